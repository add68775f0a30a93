"""Learned margin inference: numpy vs torch vs ONNX, exact gradients, OOD mask, safe loading."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES
from margin_rl.stability.learned.margin_mlp import MarginMLP
from margin_rl.stability.learned.model import (
    ARCHITECTURE,
    LearnedMargin,
    MarginWeights,
    WeightsError,
    bundled_robots,
    save_weights,
)


def random_weights(seed: int = 0) -> MarginWeights:
    rng = np.random.default_rng(seed)
    widths = ARCHITECTURE
    return MarginWeights(
        weights=tuple(rng.normal(0, 1 / np.sqrt(widths[i]), (widths[i + 1], widths[i])) for i in range(4)),
        biases=tuple(rng.normal(0, 0.1, widths[i + 1]) for i in range(4)),
        input_mean=rng.normal(size=47),
        input_std=rng.uniform(0.5, 2.0, 47),
        output_mean=-0.1,
        output_std=0.15,
        lam_low=-np.full(47, 3.0),
        lam_high=np.full(47, 3.0),
    )


@pytest.fixture(scope="module")
def saved(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("weights") / "toy"
    save_weights(random_weights(), path, {"robot": "toy"})
    return path.with_suffix(".npz")


@pytest.fixture(scope="module")
def model(saved: Path) -> LearnedMargin:
    return LearnedMargin.load(saved)


def test_single_batch_and_torch_agree(model: LearnedMargin) -> None:
    lam = np.random.default_rng(1).normal(size=(64, 47))
    batch = model(lam)
    single = np.array([model(x) for x in lam])
    np.testing.assert_allclose(batch, single, rtol=1e-5, atol=1e-6)  # float32 batch path
    module = model.torch_module(torch.float64)
    with torch.no_grad():
        torch_out = module(torch.as_tensor(lam)).numpy()
    np.testing.assert_allclose(single, torch_out, atol=1e-10)
    assert isinstance(single[0], float)


def test_gradient_is_exact(model: LearnedMargin) -> None:
    lam = np.random.default_rng(2).normal(size=(5, 47))
    value, grad = model.value_and_grad(lam)
    module = model.torch_module(torch.float64)
    x = torch.tensor(lam, requires_grad=True)
    module(x).sum().backward()
    np.testing.assert_allclose(grad, x.grad.numpy(), atol=1e-10)
    np.testing.assert_allclose(value, model(lam), atol=1e-5)
    # Independent check: central differences of the numpy forward pass.
    h = 1e-6
    for j in (0, 20, 46):
        e = np.zeros(47)
        e[j] = h
        fd = (model(lam[0] + e) - model(lam[0] - e)) / (2 * h)
        assert fd == pytest.approx(grad[0, j], abs=1e-6)
    v1, g1 = model.value_and_grad(lam[3])
    assert v1 == pytest.approx(value[3]) and g1.shape == (47,)
    np.testing.assert_allclose(model.grad(lam[3]), grad[3])


def test_out_of_distribution_mask(model: LearnedMargin) -> None:
    lam = np.zeros((3, 47))
    lam[1, 5] = 10.0  # outside [-3, 3]
    lam[2, LAMBDA_SLICES["contacts"].start] = 10.0  # contact flags are never out of range
    assert model.out_of_distribution(lam).tolist() == [False, True, False]
    assert model.out_of_distribution(lam[1]) is True


@pytest.mark.parametrize("robot", ["anymal_b", "anymal_c"])
def test_standing_on_flat_ground_is_in_distribution(robot: str) -> None:
    """The standing state has flat-ground normals (0, 0, 1), exactly the top of the sampled range of their z."""
    from margin_rl import load_robot
    from margin_rl.stability.analytic.sampling import standing_state

    lam = standing_state(load_robot(robot))
    assert lam[LAMBDA_SLICES["normals"]][2::3].tolist() == [1.0] * 4
    model = LearnedMargin.load(robot)
    assert not model.out_of_distribution(lam)
    lam_far = lam.copy()
    index = LAMBDA_SLICES["base_ang_acc"].start
    lam_far[index] = model.params.lam_high[index] + 1.0  # 1 rad/s^2 beyond the training data's largest
    assert model.out_of_distribution(lam_far)
    assert np.flatnonzero(model.outside_ranges(lam_far)).tolist() == [LAMBDA_SLICES["base_ang_acc"].start]


def test_save_load_round_trip_and_card(saved: Path, model: LearnedMargin) -> None:
    card = json.loads(saved.with_suffix(".json").read_text())
    assert card["architecture"] == list(ARCHITECTURE) and card["activation"] == "softsign"
    assert len(card["lambda_names"]) == 47 and card["robot"] == "toy"
    w = model.params
    torch.manual_seed(0)
    module = MarginMLP(w.input_mean, w.input_std, w.output_mean, w.output_std, w.lam_low, w.lam_high)
    path = save_weights(module.to_weights(), saved.parent / "trained", {"robot": "toy"})["file"]
    again = LearnedMargin.load(saved.parent / path)
    lam = np.random.default_rng(3).normal(size=47)
    with torch.no_grad():
        expected = float(module(torch.as_tensor(lam, dtype=torch.float32)))
    assert again(lam) == pytest.approx(expected, abs=1e-5)  # the float32 module vs float64 numpy


def test_bad_inputs(model: LearnedMargin) -> None:
    with pytest.raises(ValueError, match="shape"):
        model(np.zeros(46))
    lam = np.zeros(47)
    lam[LAMBDA_SLICES["mu"]] = np.nan
    with pytest.raises(ValueError, match="mu"):
        model(lam)
    with pytest.raises(ValueError, match="shape"):
        model(np.zeros((2, 3, 47)))


def test_unknown_robot_lists_bundled() -> None:
    with pytest.raises(WeightsError, match="no learned margin for robot 'anymal_x'"):
        LearnedMargin.load("anymal_x")


def test_corrupted_and_mismatched_files_are_refused(saved: Path, tmp_path: Path) -> None:
    npz, card = tmp_path / "w.npz", tmp_path / "w.json"
    data = bytearray(saved.read_bytes())
    data[len(data) // 2] ^= 0xFF
    npz.write_bytes(bytes(data))
    card.write_text(saved.with_suffix(".json").read_text())
    with pytest.raises(WeightsError, match="checksum mismatch"):
        LearnedMargin.load(npz)
    npz.write_bytes(saved.read_bytes())
    meta = json.loads(card.read_text())
    meta["lambda_layout"] = "0123456789abcdef"
    card.write_text(json.dumps(meta))
    with pytest.raises(WeightsError, match="another lambda layout"):
        LearnedMargin.load(npz)
    card.unlink()
    with pytest.raises(WeightsError, match="model card not found"):
        LearnedMargin.load(npz)
    with pytest.raises(WeightsError, match="not found"):
        LearnedMargin.load(tmp_path / "missing.npz")


def test_wrong_architecture_is_refused() -> None:
    w = random_weights()
    bad = MarginWeights(**{**w.__dict__, "weights": (w.weights[0][:100], *w.weights[1:])})
    with pytest.raises(WeightsError, match=r"layer widths|bias"):
        bad.validate()


def test_onnx_export_matches(model: LearnedMargin, tmp_path: Path) -> None:
    ort = pytest.importorskip("onnxruntime")
    path = model.export_onnx(tmp_path / "margin.onnx")
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    lam = np.random.default_rng(4).normal(size=(7, 47)).astype(np.float32)
    (out,) = session.run(None, {"lam": lam})
    np.testing.assert_allclose(out, model(lam.astype(np.float64)), atol=1e-5)


@pytest.mark.parametrize("robot", bundled_robots())
def test_bundled_weights_load_and_track_the_analytic_margin(robot: str) -> None:
    from margin_rl import load_robot
    from margin_rl.stability.analytic.margin import analytic_margin
    from margin_rl.stability.analytic.sampling import sample_states

    model = LearnedMargin.load(robot)
    assert model.card["robot"] == robot
    robot_model = load_robot(robot)
    lams = sample_states(robot_model, 60, seed=123)
    analytic = np.array([analytic_margin(robot_model, lam).margin for lam in lams])
    ok = np.isfinite(analytic)
    err = np.asarray(model(lams))[ok] - analytic[ok]
    # Loose bound: the card's test RMSE is the real figure; this guards against wrong weights.
    assert np.sqrt(np.mean(err**2)) < 3 * model.card["test_metrics"]["rmse_cm"] / 100 + 0.01


@pytest.mark.parametrize("name", ["anymal_b", "anymal_c", "anymal_c_table_i"])
def test_bundled_torch_form_matches_numpy_and_finite_differences(name: str) -> None:
    """One set of folded weights: the torch form (float64) gives the numpy value and gradient to 1e-12, and its
    autograd gradient is the derivative of its own forward pass (central differences)."""
    from margin_rl import load_robot
    from margin_rl.stability.analytic.sampling import sample_states

    model = LearnedMargin.load(name)
    lams = sample_states(load_robot(name.removesuffix("_table_i")), 16, seed=7)
    value, grad = model.value_and_grad(lams)
    module = model.torch_module(torch.float64)
    x = torch.tensor(lams, requires_grad=True)
    out = module(x)
    out.sum().backward()
    np.testing.assert_allclose(out.detach().numpy(), value, rtol=0, atol=1e-12)
    np.testing.assert_allclose(x.grad.numpy(), grad, rtol=0, atol=1e-12)
    h = 1e-6
    with torch.no_grad():
        for j in range(0, 47, 3):
            e = torch.zeros(47, dtype=torch.float64)
            e[j] = h
            fd = (module(x + e) - module(x - e)) / (2 * h)
            np.testing.assert_allclose(fd.numpy(), x.grad[:, j].numpy(), rtol=0, atol=1e-7)


def test_training_end_to_end_writes_a_complete_card(tmp_path: Path) -> None:
    from margin_rl.stability.analytic.margin import AnalyticSettings
    from margin_rl.stability.learned.dataset import DatasetSpec, generate
    from margin_rl.stability.learned.training import TrainConfig, train

    data = tmp_path / "data"
    generate(DatasetSpec("anymal_b", 120, 60, 0, AnalyticSettings()), data, workers=1, progress=False)
    config = TrainConfig(epochs=2, grad_check_states=2, protocol_states=40, protocol_sweeps=1)
    card = train(data, tmp_path / "w", config, logdir=tmp_path / "tb", progress=False)
    for key in (
        "dataset",
        "analytic_settings",
        "package_commit",
        "training",
        "test_metrics",
        "gradient_check",
        "paper_protocol",
        "sha256",
    ):
        assert key in card, key
    command = card["dataset"]["generation_command"]
    assert "margin_rl.stability.learned.dataset generate --robot anymal_b --n 120" in command
    assert set(card["test_metrics"]) >= {"rmse_cm", "sign_agreement", "rmse_cm_by_acc_xy_band"}
    assert card["paper_protocol"]["reliability"]["states_drawn"] == 40
    assert card["paper_protocol"]["analytic_settings"] == card["analytic_settings"]
    assert list((tmp_path / "tb").iterdir()), "no TensorBoard events"
    model = LearnedMargin.load(tmp_path / "w.npz")
    assert np.isfinite(model(np.zeros(47)))


@pytest.mark.parametrize("schedule", ["plateau", "cosine"])
def test_fit_learns_a_smooth_function_and_anneals_the_rate(schedule: str) -> None:
    """A smooth target the MLP can represent: both schedules cut the validation error well below the
    target's spread; the cosine schedule ends exactly at min_lr."""
    from margin_rl.stability.learned.training import TrainConfig, build_model, fit

    rng = np.random.default_rng(0)
    lam = rng.normal(size=(3000, 47))
    margin = 0.1 * np.tanh(lam[:, 0] - 0.5 * lam[:, 6]) + 0.02 * lam[:, 30]
    config = TrainConfig(epochs=8, batch_size=128, lr=3e-3, schedule=schedule, min_lr=1e-4, grad_check_states=0)
    model = build_model(lam[:2500], margin[:2500])
    summary = fit(model, lam[:2500], margin[:2500], lam[2500:], margin[2500:], config, progress=False)
    assert summary["best_val_rmse_cm"] < 0.25 * 100 * margin.std()
    assert 0 < summary["last_train_rmse_cm"] < 0.25 * 100 * margin.std()
    if schedule == "cosine":
        assert summary["final_lr"] == pytest.approx(1e-4, rel=1e-6)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [("schedule", "linear", "schedule must be one of"), ("batch_size", 0, "batch_size must be >= 1"),
     ("min_lr", 1.0, "min_lr <= lr"), ("mirror", "both", "mirror must be one of"),
     ("protocol_states", -1, "protocol_states must be >= 0")],
)  # fmt: skip
def test_bad_training_config_is_refused_naming_the_field(field: str, value: object, message: str) -> None:
    from margin_rl.stability.learned.training import TrainConfig, check_config

    with pytest.raises(ValueError, match=message):
        check_config(TrainConfig(**{field: value}))


def test_mirror_tied_network_is_exactly_invariant_in_torch_numpy_and_gradients() -> None:
    """The tied parameterisation: m(mirror(lam)) = m(lam) for random parameters, in the torch module and in
    the dense numpy weights it exports; the gradient transforms like lambda (dm/dlam(M lam) = M dm/dlam(lam))."""
    from margin_rl.stability.analytic.lambda_state import MIRROR_SIGN, MIRROR_SOURCE, mirror_lambda
    from margin_rl.stability.learned.training import build_model

    rng = np.random.default_rng(5)
    lam = rng.normal(size=(400, 47))
    torch.manual_seed(1)
    module = build_model(lam, rng.normal(size=400), mirror="tied")
    x = torch.as_tensor(lam[:50], dtype=torch.float64)
    module = module.double()
    out, out_mirrored = module(x), module(torch.as_tensor(mirror_lambda(lam[:50])))
    assert float(out.std()) > 0
    torch.testing.assert_close(out, out_mirrored, rtol=0, atol=1e-12)
    dense = LearnedMargin(module.to_weights())  # float32 weights, as saved: invariant to float32 rounding
    np.testing.assert_allclose(dense(lam[:50]), dense(mirror_lambda(lam[:50])), rtol=0, atol=1e-6)
    np.testing.assert_allclose(dense(lam[:50]), out.detach().numpy(), rtol=0, atol=1e-6)
    grad, grad_mirrored = dense.grad(lam[:50]), dense.grad(mirror_lambda(lam[:50]))
    scale = np.abs(grad).max()
    np.testing.assert_allclose(grad_mirrored, grad[:, MIRROR_SOURCE] * MIRROR_SIGN, rtol=0, atol=1e-5 * scale)
    # the dense weights keep the paper's architecture
    assert [w.shape[0] for w in dense.params.weights] == list(ARCHITECTURE[1:])


def test_mirror_tied_network_refuses_an_asymmetric_normalisation() -> None:
    rng = np.random.default_rng(0)
    lam = rng.normal(size=(200, 47)) + 0.3  # mean not mirror-symmetric
    with pytest.raises(ValueError, match="mirror-symmetric input normalisation"):
        MarginMLP(lam.mean(0), lam.std(0), 0.0, 1.0, lam.min(0), lam.max(0), mirror_tied=True)


@pytest.mark.parametrize("mirror", ["augment", "tied"])
def test_mirror_training_learns_a_symmetric_target(mirror: str) -> None:
    """A mirror-invariant target: both modes fit it, and the tied one is invariant by construction."""
    from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES, mirror_lambda
    from margin_rl.stability.learned.training import TrainConfig, build_model, fit, training_split

    rng = np.random.default_rng(0)
    lam = rng.normal(size=(3000, 47))
    feet = lam[:, LAMBDA_SLICES["feet"]].reshape(-1, 4, 3)
    margin = 0.1 * np.tanh(feet[:, 0, 1] - feet[:, 1, 1]) ** 2 + 0.02 * lam[:, LAMBDA_SLICES["com_vel"]][:, 0]
    np.testing.assert_allclose(  # the target is invariant
        0.1 * np.tanh(mirror_lambda(lam)[:, LAMBDA_SLICES["feet"]].reshape(-1, 4, 3)[:, 0, 1]
                      - mirror_lambda(lam)[:, LAMBDA_SLICES["feet"]].reshape(-1, 4, 3)[:, 1, 1]) ** 2
        + 0.02 * lam[:, LAMBDA_SLICES["com_vel"]][:, 0],
        margin,
    )  # fmt: skip
    config = TrainConfig(epochs=6, batch_size=128, lr=3e-3, grad_check_states=0, mirror=mirror)
    torch.manual_seed(0)  # initial weights
    model = build_model(lam[:2500], margin[:2500], mirror)
    lam_fit, margin_fit = training_split(lam[:2500], margin[:2500], config)
    assert len(lam_fit) == (5000 if mirror == "augment" else 2500)
    summary = fit(model, lam_fit, margin_fit, lam[2500:], margin[2500:], config, progress=False)
    assert summary["best_val_rmse_cm"] < 0.5 * 100 * margin.std()
    learned = LearnedMargin(model.to_weights())
    asymmetry = learned(lam[2500:]) - learned(mirror_lambda(lam[2500:]))
    if mirror == "tied":
        assert np.abs(asymmetry).max() < 1e-6
    else:  # approximately invariant: more so than the same network trained without the mirrored copies
        plain_config = TrainConfig(epochs=6, batch_size=128, lr=3e-3, grad_check_states=0)
        torch.manual_seed(0)
        plain = build_model(lam[:2500], margin[:2500])
        fit(plain, lam[:2500], margin[:2500], lam[2500:], margin[2500:], plain_config, progress=False)
        plain_learned = LearnedMargin(plain.to_weights())
        plain_asymmetry = plain_learned(lam[2500:]) - plain_learned(mirror_lambda(lam[2500:]))
        ratio = np.sqrt(np.mean(asymmetry**2)) / np.sqrt(np.mean(plain_asymmetry**2))
        assert ratio < 0.8


# ----------------------------------------------------------------------------- physics-informed architecture
def random_physics_weights(seed: int = 0, proxy_weight: float = 1.0) -> MarginWeights:
    from margin_rl.stability.learned.features import PHYSICS_INPUT_DIM
    from margin_rl.stability.learned.mlp_weights import architecture_widths

    rng = np.random.default_rng(seed)
    widths = architecture_widths("physics")
    assert widths == (PHYSICS_INPUT_DIM, *ARCHITECTURE[1:])
    return MarginWeights(
        weights=tuple(rng.normal(0, 1 / np.sqrt(widths[i]), (widths[i + 1], widths[i])) for i in range(4)),
        biases=tuple(rng.normal(0, 0.1, widths[i + 1]) for i in range(4)),
        input_mean=rng.normal(0, 0.1, PHYSICS_INPUT_DIM),
        input_std=rng.uniform(0.5, 2.0, PHYSICS_INPUT_DIM),
        output_mean=-0.1,
        output_std=0.15,
        lam_low=-np.full(47, 3.0),
        lam_high=np.full(47, 3.0),
        architecture="physics",
        physics=np.array([50.0, 9.81, 0.03]),
        proxy_weight=proxy_weight,
    )


def physics_states(n: int, seed: int) -> np.ndarray:
    from tests.stability.learned.test_features import random_states

    return random_states(n, seed)


@pytest.fixture(scope="module")
def physics_model(tmp_path_factory: pytest.TempPathFactory) -> LearnedMargin:
    path = tmp_path_factory.mktemp("physics") / "toy_physics"
    card = save_weights(random_physics_weights(), path, {"robot": "toy"})
    assert card["model"] == "physics" and card["architecture"][0] == 47 + len(card["features"])
    assert card["physics_constants"] == {"mass_kg": 50.0, "gravity": 9.81, "foot_radius_m": 0.03}
    return LearnedMargin.load(path.with_suffix(".npz"))


def test_paper_weights_files_keep_their_keys(saved: Path) -> None:
    with np.load(saved) as data:
        assert "architecture" not in data.files and "physics_constants" not in data.files
    assert LearnedMargin.load(saved).architecture == "paper"


def test_physics_model_numpy_torch_and_gradient_agree(physics_model: LearnedMargin) -> None:
    assert physics_model.architecture == "physics" and physics_model.params.proxy_weight == 1.0
    lam = physics_states(24, seed=4)
    batch = physics_model(lam)
    single = np.array([physics_model(x) for x in lam])
    assert isinstance(single[0], float)
    np.testing.assert_allclose(batch, single, rtol=1e-5, atol=1e-5)  # float32 batch path
    module = physics_model.torch_module(torch.float64)
    x = torch.tensor(lam, requires_grad=True)
    out = module(x)
    out.sum().backward()
    np.testing.assert_allclose(out.detach().numpy(), single, atol=1e-10)
    value, grad = physics_model.value_and_grad(lam)
    np.testing.assert_allclose(value, single, atol=1e-10)
    np.testing.assert_allclose(grad, x.grad.numpy(), atol=1e-9)
    v1, g1 = physics_model.value_and_grad(lam[5])
    assert v1 == pytest.approx(single[5], abs=1e-12) and g1.shape == (47,)
    # independent check: central differences of the numpy forward pass (not across the binary flags)
    h = 1e-6
    for j in (3, 9, 20, 30, 45):
        e = np.zeros(47)
        e[j] = h
        fd = (physics_model(lam[0] + e) - physics_model(lam[0] - e)) / (2 * h)
        assert fd == pytest.approx(grad[0, j], abs=1e-5)


def test_physics_model_onnx_export_matches(physics_model: LearnedMargin, tmp_path: Path) -> None:
    ort = pytest.importorskip("onnxruntime")
    path = physics_model.export_onnx(tmp_path / "physics.onnx")
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    lam = physics_states(9, seed=5).astype(np.float32)
    (out,) = session.run(None, {"lam": lam})
    np.testing.assert_allclose(out, physics_model(lam.astype(np.float64)), atol=2e-5)


def test_physics_model_ranges_and_bad_inputs(physics_model: LearnedMargin) -> None:
    lam = np.zeros((2, 47))
    lam[:, LAMBDA_SLICES["normals"].start + 2 :: 3] = 1.0
    lam[1, 5] = 10.0
    assert physics_model.out_of_distribution(lam).tolist() == [False, True]
    with pytest.raises(ValueError, match="shape"):
        physics_model(np.zeros(46))
    bad = lam[0].copy()
    bad[LAMBDA_SLICES["mu"]] = np.nan
    with pytest.raises(ValueError, match="mu"):
        physics_model.value_and_grad(bad)


def test_physics_weights_validation() -> None:
    w = random_physics_weights()
    with pytest.raises(WeightsError, match="layer widths"):
        MarginWeights(**{**w.__dict__, "architecture": "paper"}).validate()
    with pytest.raises(WeightsError, match="mass, gravity, foot_radius"):
        MarginWeights(**{**w.__dict__, "physics": None}).validate()
    with pytest.raises(WeightsError, match="mass"):
        MarginWeights(**{**w.__dict__, "physics": np.array([-1.0, 9.81, 0.03])}).validate()
    arrays = w.to_arrays()
    arrays["architecture"] = np.array("transformer")
    with pytest.raises(WeightsError, match="unknown architecture"):
        MarginWeights.from_arrays(arrays)
    arrays = w.to_arrays()
    del arrays["proxy_weight"]
    with pytest.raises(WeightsError, match="missing arrays"):
        MarginWeights.from_arrays(arrays)


def test_tied_physics_model_is_exactly_mirror_invariant() -> None:
    """Tied weights on [lambda, features]: m(mirror(lam)) = m(lam) in the torch module of the saved dense
    weights (float64, through the features), in numpy, and the gradient transforms like lambda."""
    from margin_rl.stability.analytic.lambda_state import MIRROR_SIGN, MIRROR_SOURCE, mirror_lambda
    from margin_rl.stability.learned.features import PhysicsConstants
    from margin_rl.stability.learned.training import TrainConfig, build_model, model_inputs, to_margin_weights

    constants = PhysicsConstants(50.0, 9.81, 0.03)
    config = TrainConfig(architecture="physics", mirror="tied")
    lam = physics_states(300, seed=6)
    inputs = model_inputs(lam, config, constants)
    torch.manual_seed(2)
    core = build_model(
        inputs.inputs, np.random.default_rng(0).normal(size=300), "tied", (inputs.inputs.shape[1], 256, 128, 128, 1)
    )
    weights = to_margin_weights(core, config, constants)
    dense = LearnedMargin(weights)
    module = dense.torch_module(torch.float64)  # the features in torch, then the folded layers
    x, xm = torch.as_tensor(lam[:40]), torch.as_tensor(mirror_lambda(lam[:40]))
    out = module(x)
    assert float(out.std()) > 0
    torch.testing.assert_close(out, module(xm), rtol=0, atol=1e-12)
    np.testing.assert_allclose(dense(lam[:40]), dense(mirror_lambda(lam[:40])), rtol=0, atol=2e-6)
    np.testing.assert_allclose(dense(lam[:40]), out.detach().numpy(), rtol=0, atol=2e-6)
    grad, grad_mirrored = dense.grad(lam[:40]), dense.grad(mirror_lambda(lam[:40]))
    scale = np.abs(grad).max()
    np.testing.assert_allclose(grad_mirrored, grad[:, MIRROR_SOURCE] * MIRROR_SIGN, rtol=0, atol=1e-5 * scale)
    assert weights.lam_low.shape == (47,)


def test_physics_training_end_to_end(tmp_path: Path) -> None:
    """The training entry point with --architecture physics: the card records the model and the weights load."""
    from margin_rl.stability.analytic.margin import AnalyticSettings
    from margin_rl.stability.learned.dataset import DatasetSpec, generate
    from margin_rl.stability.learned.training import main

    data = tmp_path / "data"
    generate(DatasetSpec("anymal_c", 60, 60, 0, AnalyticSettings()), data, workers=1, progress=False)
    out = tmp_path / "w"
    args = ["--data", str(data), "--out", str(out), "--epochs", "2", "--grad-check-states", "0"]
    assert main([*args, "--protocol-states", "0", "--architecture", "physics", "--mirror", "tied", "--quiet"]) == 0
    model = LearnedMargin.load(out.with_suffix(".npz"))
    card = json.loads(out.with_suffix(".json").read_text())
    assert model.architecture == "physics" and card["model"] == "physics"
    assert card["training"]["architecture"] == "physics" and card["training"]["proxy_weight"] == 1.0
    assert card["physics_constants"]["mass_kg"] == pytest.approx(52.13485)
    assert np.isfinite(model(_flat_normals()))  # mu = 0 too: the features stay finite


def _flat_normals() -> np.ndarray:
    lam = np.zeros(47)
    lam[LAMBDA_SLICES["normals"].start + 2 :: 3] = 1.0
    return lam


def test_extended_target_trains_on_every_state_and_mixes_datasets(tmp_path: Path) -> None:
    """Two datasets of one robot are concatenated; the card names both and judges the net on m_a too."""
    from margin_rl.stability.analytic.margin import AnalyticSettings
    from margin_rl.stability.learned.dataset import DatasetError, DatasetSpec, generate
    from margin_rl.stability.learned.training import TrainConfig, train

    first, second, other = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    generate(DatasetSpec("anymal_b", 80, 40, 0, AnalyticSettings()), first, workers=1, progress=False)
    generate(DatasetSpec("anymal_b", 40, 40, 1, AnalyticSettings()), second, workers=1, progress=False)
    config = TrainConfig(epochs=2, grad_check_states=0, protocol_states=0, target="extended", max_seconds=60.0)
    card = train([first, second], tmp_path / "w", config, progress=False)
    assert card["dataset"]["target"] == "extended" and card["dataset"]["samples_used"] == 120
    assert [p["path"] for p in card["dataset"]["parts"]] == [str(first), str(second)]
    assert card["test_metrics"]["on_analytic"]["n"] <= card["test_metrics"]["n"]
    generate(DatasetSpec("anymal_c", 40, 40, 0, AnalyticSettings()), other, workers=1, progress=False)
    with pytest.raises(DatasetError, match="one robot"):
        train([first, other], tmp_path / "x", config, progress=False)
    kappa = tmp_path / "kappa"  # m_x with another load penalty is another quantity
    generate(DatasetSpec("anymal_b", 40, 40, 2, AnalyticSettings(), load_penalty=0.3), kappa, workers=1, progress=False)
    with pytest.raises(DatasetError, match="extended_margin"):
        train([first, kappa], tmp_path / "y", config, progress=False)


def test_time_budget_stops_the_fit() -> None:
    from margin_rl.stability.learned.training import TrainConfig, build_model, fit

    rng = np.random.default_rng(0)
    lam, margin = rng.normal(size=(600, 47)), rng.normal(size=600)
    config = TrainConfig(epochs=50, batch_size=64, patience=100, max_seconds=1e-6, grad_check_states=0)
    model = build_model(lam[:500], margin[:500])
    summary = fit(model, lam[:500], margin[:500], lam[500:], margin[500:], config, progress=False)
    assert summary["epochs_run"] == 1 and summary["stopped_by_time_budget"]


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [("target", "relaxed", "target must be one of"), ("max_seconds", 0.0, "max_seconds must be > 0")],
)
def test_bad_target_and_budget_are_refused(field: str, value: object, message: str) -> None:
    from margin_rl.stability.learned.training import TrainConfig, check_config

    with pytest.raises(ValueError, match=message):
        check_config(TrainConfig(**{field: value}))


# ----------------------------------------------------------------------------- continuing a fit from saved weights
@pytest.mark.parametrize("mirror", ["none", "tied"])
def test_saved_weights_become_the_same_trainable_network(mirror: str) -> None:
    """from_weights inverts to_weights: the same dense matrices, the same outputs, and the tied structure kept
    (a tied network read back is still exactly mirror-invariant after a gradient step)."""
    from margin_rl.stability.analytic.lambda_state import mirror_lambda
    from margin_rl.stability.learned.training import build_model

    rng = np.random.default_rng(3)
    lam = rng.normal(size=(300, 47))
    torch.manual_seed(2)
    original = build_model(lam, rng.normal(size=300), mirror=mirror)
    saved = original.to_weights()
    restored = MarginMLP.from_weights(saved, mirror_tied=mirror == "tied")
    for a, b in zip(restored.to_weights().weights, saved.weights, strict=True):
        np.testing.assert_array_equal(a, b)
    x = torch.as_tensor(lam[:20], dtype=torch.float32)
    torch.testing.assert_close(restored(x), original(x), rtol=0, atol=0)
    loss = restored(x).square().sum()
    loss.backward()
    with torch.no_grad():
        for p in restored.parameters():
            p -= 0.1 * p.grad
    moved = LearnedMargin(restored.to_weights())
    assert np.abs(moved(lam[:20]) - LearnedMargin(saved)(lam[:20])).max() > 1e-4
    if mirror == "tied":
        np.testing.assert_allclose(moved(lam[:20]), moved(mirror_lambda(lam[:20])), rtol=0, atol=1e-6)


def test_untied_or_physics_weights_are_refused_as_tied() -> None:
    plain = random_weights(0)
    plain = MarginWeights(**{**plain.__dict__, "input_mean": np.zeros(47), "input_std": np.ones(47)})
    with pytest.raises(ValueError, match="not mirror-tied"):
        MarginMLP.from_weights(plain, mirror_tied=True)
    with pytest.raises(ValueError, match="paper network"):
        MarginMLP.from_weights(random_physics_weights(), mirror_tied=False)


def test_training_continues_saved_weights(tmp_path: Path) -> None:
    """--init: the continued network starts from the saved one (one small-rate step moves it a little, it is not
    refitted), keeps the saved normalisation, widens the input ranges to the new data, records what it
    continued, and refuses weights of another robot or another architecture."""
    from margin_rl.stability.analytic.margin import AnalyticSettings
    from margin_rl.stability.learned.dataset import DatasetSpec, generate
    from margin_rl.stability.learned.training import TrainConfig, train

    first, more = tmp_path / "a", tmp_path / "b"
    generate(DatasetSpec("anymal_b", 120, 60, 0, AnalyticSettings()), first, workers=1, progress=False)
    generate(DatasetSpec("anymal_b", 120, 60, 5, AnalyticSettings()), more, workers=1, progress=False)
    config = TrainConfig(epochs=2, grad_check_states=0, protocol_states=0, mirror="tied")
    first_card = train(first, tmp_path / "w0", config, progress=False)
    saved = LearnedMargin.load(tmp_path / "w0.npz")
    continued = dataclasses.replace(config, init=str(tmp_path / "w0.npz"), lr=1e-4, epochs=1)
    card = train([first, more], tmp_path / "w1", continued, progress=False)
    assert card["continued_from"] == {"source": str(tmp_path / "w0.npz"), "sha256": first_card["sha256"]}
    result = LearnedMargin.load(tmp_path / "w1.npz")
    np.testing.assert_array_equal(result.params.input_mean, saved.params.input_mean)
    assert result.params.output_std == saved.params.output_std
    assert np.all(result.params.lam_low <= saved.params.lam_low)
    assert np.all(result.params.lam_high >= saved.params.lam_high)
    lam = np.random.default_rng(0).normal(size=(50, 47)) * saved.params.input_std + saved.params.input_mean
    assert 0 < np.abs(result(lam) - saved(lam)).max() < 0.05  # moved by a small-rate epoch, not refitted
    with pytest.raises(ValueError, match="holds weights of 'anymal_c'"):
        train(first, tmp_path / "w2", dataclasses.replace(continued, init="anymal_c"), progress=False)
    with pytest.raises(ValueError, match="paper network only"):
        train(first, tmp_path / "w3", dataclasses.replace(continued, architecture="physics"), progress=False)
