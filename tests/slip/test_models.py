"""Tests of the bundled P/M networks, their numpy/torch/casadi forms and the trainer."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from margin_rl.network import DenseNetwork, read_arrays
from margin_rl.slip.dataset import DatasetConfig, generate_dataset, load_dataset
from margin_rl.slip.margin import PREDICTION_WEIGHTS, label_samples, sample_box
from margin_rl.slip.models import BUNDLE_DIR, box_normalisation, load_bundle, network_arrays, network_from_arrays
from margin_rl.slip.train import TorchMLP, TrainConfig, fit, threshold_curve, train_bundle


@pytest.fixture(scope="module")
def bundle():  # type: ignore[no-untyped-def]
    return load_bundle()


def test_bundle_card_records_checksums_and_metrics(bundle) -> None:  # type: ignore[no-untyped-def]
    card = bundle.card
    assert card["dataset"]["n_samples"] >= 100_000
    assert set(card["files"]) == {"return_map", "margin"}
    assert card["metrics_test"]["margin"]["sign_accuracy"] > 0.9
    assert bundle.return_map.in_dim == 4 and bundle.return_map.out_dim == 3
    assert bundle.margin.out_dim == 1
    assert [w.shape for w in bundle.margin.weights] == [(64, 4), (64, 64), (1, 64)]


def test_tampered_weights_are_refused(tmp_path: Path) -> None:
    shutil.copytree(BUNDLE_DIR, tmp_path / "w")
    path = tmp_path / "w" / "margin.npz"
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["b2"] = arrays["b2"] + 1.0
    np.savez(path, **arrays)
    with pytest.raises(ValueError, match="checksum"):
        load_bundle(tmp_path / "w")


def test_bundled_networks_match_the_simulator(bundle) -> None:  # type: ignore[no-untyped-def]
    z = sample_box(3000, np.random.default_rng(123))
    res = label_samples(z)
    ok = res.valid
    err = bundle.return_map(z[ok]) - res.next_apex[ok]
    assert np.mean(np.sum(PREDICTION_WEIGHTS * err * err, axis=1)) < 1e-3
    m = bundle.margin(z)[:, 0]
    assert np.mean((m > 0) == ok) > 0.97
    # The paper's operating point: points with M > 0.05 should be valid almost always.
    assert np.mean(ok[m > 0.05]) > 0.95


def test_numpy_torch_and_casadi_agree(bundle) -> None:  # type: ignore[no-untyped-def]
    """The three forms of the folded network: values and Jacobians to 1e-12 (float64)."""
    import casadi as ca

    net: DenseNetwork = bundle.return_map
    z = sample_box(50, np.random.default_rng(7))
    module = net.torch_module(torch.float64)
    with torch.no_grad():
        np.testing.assert_allclose(module(torch.as_tensor(z)).numpy(), net(z), rtol=0, atol=1e-12)
    zs = ca.SX.sym("z", 4)
    expr = net.casadi(zs)
    f = ca.Function("f", [zs], [expr, ca.jacobian(expr, zs)])
    for row in z[:10]:
        torch_jac = torch.autograd.functional.jacobian(module, torch.as_tensor(row)).numpy()
        np.testing.assert_allclose(torch_jac, net.jacobian(row), rtol=0, atol=1e-12)
        val, jac = f(row)
        np.testing.assert_allclose(np.array(val).ravel(), net(row), rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.array(jac), net.jacobian(row), rtol=0, atol=1e-12)


def test_trained_twin_exports_the_network_it_evaluates() -> None:
    """TorchMLP (normalised units, trainable) and the folded network of its exported file content agree."""
    torch.manual_seed(0)
    off, scale = box_normalisation()
    twin = TorchMLP(off, scale, np.array([0.1, 1.0, 0.2]), np.array([0.3, 0.05, 0.4]))
    arrays = twin.export()
    assert sorted(arrays) == sorted(network_arrays((0, 0, 0), (0, 0, 0), 0, 0, 0, 0))
    assert all(a.dtype == np.float32 for a in arrays.values())
    z = sample_box(40, np.random.default_rng(1))
    with torch.no_grad():
        expected = twin(torch.as_tensor(z, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(network_from_arrays(arrays)(z), expected, rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="lack"):
        network_from_arrays({k: v for k, v in arrays.items() if k != "in_scale"})


def test_jacobian_matches_finite_differences(bundle) -> None:  # type: ignore[no-untyped-def]
    net: DenseNetwork = bundle.margin
    z0 = np.array([1.05, 0.3, 0.15, 0.05])
    h = 1e-7
    fd = np.column_stack([(net(z0 + h * e) - net(z0 - h * e)) / (2 * h) for e in np.eye(4)])
    np.testing.assert_allclose(net.jacobian(z0), fd, rtol=1e-5, atol=1e-6)


def test_fit_learns_a_smooth_function() -> None:
    rng = np.random.default_rng(0)
    z = sample_box(4000, rng)
    target = np.column_stack([np.sin(3 * z[:, 1]) + z[:, 0], z[:, 2] * z[:, 3]])
    arrays, hist = fit(z, target, np.ones(2), TrainConfig(iters=1500, batch_size=256))
    net = network_from_arrays(arrays)
    assert hist[-1] < 0.1 * hist[0]
    err = net(z) - target
    assert np.mean(err**2) < 0.01 * np.var(target, axis=0).sum()


def test_fit_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match="weights"):
        fit(np.zeros((5, 4)), np.zeros((5, 2)), np.ones(3), TrainConfig(iters=1))
    with pytest.raises(ValueError, match="iters"):
        TrainConfig(iters=0)


def test_threshold_curve_by_hand() -> None:
    pred = np.array([0.2, 0.1, 0.06, 0.01, -0.1])
    valid = np.array([True, True, False, True, False])
    prec, rec = threshold_curve(pred, valid, np.array([0.0, 0.05, 0.15]))
    np.testing.assert_allclose(prec, [3 / 4, 2 / 3, 1.0])
    np.testing.assert_allclose(rec, [1.0, 2 / 3, 1 / 3])


def test_train_bundle_end_to_end(tmp_path: Path) -> None:
    generate_dataset(tmp_path / "data", DatasetConfig(n=3000, shard_size=1500, seed=9))
    card = train_bundle(
        load_dataset(tmp_path / "data"), tmp_path / "w", TrainConfig(iters=200), figure=tmp_path / "fig.png"
    )
    assert (tmp_path / "fig.png").stat().st_size > 1000
    loaded = load_bundle(tmp_path / "w")
    assert json.loads((tmp_path / "w" / "card.json").read_text()) == loaded.card
    assert card["dataset"]["n_samples"] == 3000
    off, scale = box_normalisation()
    stored = read_arrays(tmp_path / "w" / "margin.npz")
    np.testing.assert_allclose(stored["in_offset"], off, rtol=1e-6)
    np.testing.assert_allclose(stored["in_scale"], scale, rtol=1e-6)
    np.testing.assert_array_equal(loaded.margin(off), network_from_arrays(stored)(off))
