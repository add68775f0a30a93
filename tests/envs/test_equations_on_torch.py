"""The environments' equations written once over numpy and torch (the array API standard's names, margin_rl.arrays):
every reward term, every termination cause and lambda from the simulator give the same numbers on torch tensors as on
numpy arrays, and numpy's own numbers (hand-checked values for the kernel and the clipped terms), for random inputs
and for bad ones (NaN, inf)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.envs.config import TerminationConfig
from margin_rl.envs.rewards import FIELD_TRACKING_VARIANCE, REWARD_TERMS, compute_rewards, logistic_kernel
from margin_rl.envs.stability_input import heading_rotation, lambda_from_simulation, stance_width
from margin_rl.envs.terminations import CAUSE_NAMES, any_cause, termination_causes
from margin_rl.robot import quat_wxyz_to_matrix
from margin_rl.stability import LAMBDA_DIM, from_lambda

N = 16


def reward_inputs(rng: np.random.Generator, n: int = N) -> dict[str, np.ndarray]:
    """Every array a reward term reads, of the core's shapes and dtypes."""
    return {
        "command": rng.uniform(-1, 1, (n, 3)),
        "base_lin_vel": rng.normal(size=(n, 3)),
        "base_ang_vel": rng.normal(size=(n, 3)),
        "projected_gravity": rng.normal(size=(n, 3)),
        "margin": rng.normal(0, 0.1, n),
        "torques": rng.normal(0, 30, (n, 12)),
        "action": rng.uniform(-1, 1, (n, 12)),
        "last_action": rng.uniform(-1, 1, (n, 12)),
        "joint_acc": rng.normal(0, 50, (n, 12)),
        "base_lin_acc": rng.normal(0, 5, (n, 3)),
        "touchdown": rng.random((n, 4)) < 0.3,
        "air_time_at_touchdown": rng.uniform(0, 1, (n, 4)),
        "thigh_contacts": rng.random((n, 4)) < 0.2,
        "knee_heights": rng.uniform(0, 0.3, (n, 4)),
        "knee_clearance_height": np.full(n, 0.1),
        "base_height": rng.uniform(0.2, 0.6, n),
        "base_height_target": np.full(n, 0.45),
        "fell": rng.random(n) < 0.1,
    }


def on_torch(arrays: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    return {name: torch.from_numpy(np.ascontiguousarray(a)) for name, a in arrays.items()}


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), gain=st.floats(0.5, 20.0))
def test_every_reward_term_is_the_same_on_torch(seed: int, gain: float) -> None:
    inputs = reward_inputs(np.random.default_rng(seed))
    weights = {name: 1.0 for name in REWARD_TERMS}
    total, terms = compute_rewards(weights, inputs, gain)
    total_t, terms_t = compute_rewards(weights, on_torch(inputs), gain)
    assert isinstance(total, np.ndarray) and isinstance(total_t, torch.Tensor) and total_t.dtype == torch.float64
    for name in REWARD_TERMS:
        np.testing.assert_allclose(terms_t[name].numpy(), terms[name], rtol=1e-12, atol=1e-12, err_msg=name)
    np.testing.assert_allclose(total_t.numpy(), total, rtol=1e-12, atol=1e-12)


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    weights=st.lists(st.floats(-5.0, 5.0), min_size=len(REWARD_TERMS), max_size=len(REWARD_TERMS)),
)
def test_each_weighted_term_is_its_weight_times_the_term_and_the_reward_their_sum(
    seed: int, weights: list[float]
) -> None:
    """The terms are weighted in one product and summed in one reduction: each equals weight x term bit for bit, and
    the reward the terms added one after another in the weights' order (numpy's order, bit for bit; torch's reduction
    keeps several partial sums, to rounding)."""
    inputs = reward_inputs(np.random.default_rng(seed))
    weighting = dict(zip(REWARD_TERMS, weights, strict=True))
    for arrays in (inputs, on_torch(inputs)):
        total, terms = compute_rewards(weighting, arrays, 8.0)
        assert list(terms) == list(weighting)
        expected_total = 0.0
        for name, weight in weighting.items():
            expected = weight * np.asarray(REWARD_TERMS[name](arrays, 8.0), dtype=np.float64)
            np.testing.assert_array_equal(np.asarray(terms[name]), expected, err_msg=name)
            expected_total = expected_total + expected
        if isinstance(total, np.ndarray):
            np.testing.assert_array_equal(total, expected_total)
        else:
            np.testing.assert_allclose(total.numpy(), expected_total, rtol=1e-12, atol=1e-12)


def test_the_terms_hold_their_hand_computed_values() -> None:
    """The kernel's peak and tails, and the clipped terms at and beyond their thresholds, on both kinds of arrays."""
    for xp_array in (np.asarray, lambda values: torch.as_tensor(np.asarray(values, dtype=np.float64))):
        x = xp_array(np.array([0.0, 1.0, -1.0, 100.0, -np.inf]))
        expected = [0.25, 1 / (np.exp(-1) + 2 + np.exp(1)), 1 / (np.exp(-1) + 2 + np.exp(1)), 0.0, 0.0]
        np.testing.assert_allclose(np.asarray(logistic_kernel(x)), expected, atol=1e-21)
        knees = {"knee_heights": xp_array(np.array([[0.05, 0.1, 0.2, 0.0]])), "knee_clearance_height": xp_array([0.1])}
        assert float(REWARD_TERMS["knee_clearance"](knees, 1.0)[0]) == pytest.approx(0.05 + 0.1)
        base = {"base_height": xp_array([0.40, 0.50]), "base_height_target": xp_array([0.45, 0.45])}
        np.testing.assert_allclose(np.asarray(REWARD_TERMS["base_height"](base, 1.0)), [0.05, 0.0], atol=1e-15)
        # the field's kernels: 1 on the command, e^-1 one sigma away (0.5 m/s or rad/s), split over x and y alike
        sigma = FIELD_TRACKING_VARIANCE**0.5
        moving = {
            "command": xp_array([[0.5, 0.0, 0.2], [0.5, 0.0, 0.2], [0.5, 0.0, 0.2]]),
            "base_lin_vel": xp_array([[0.5, 0.0, 9.0], [0.5 - sigma, 0.0, 0.0], [0.5 - 0.3, 0.4, 0.0]]),
            "base_ang_vel": xp_array([[7.0, 7.0, 0.2], [0.0, 0.0, 0.2 + sigma], [0.0, 0.0, 0.2 - 2 * sigma]]),
        }
        np.testing.assert_allclose(
            np.asarray(REWARD_TERMS["tracking_lin_vel_xy"](moving, 1.0)), [1.0, np.exp(-1), np.exp(-1)], rtol=1e-12
        )
        np.testing.assert_allclose(
            np.asarray(REWARD_TERMS["tracking_ang_vel_z"](moving, 1.0)), [1.0, np.exp(-1), np.exp(-4)], rtol=1e-12
        )
        accelerations = {"base_lin_acc": xp_array([[3.0, 4.0, 0.0], [0.0, 0.0, -2.0]])}
        np.testing.assert_allclose(np.asarray(REWARD_TERMS["base_acceleration"](accelerations, 1.0)), [25.0, 4.0])


def test_no_reward_term_on_an_empty_weighting_gives_zeros_of_the_inputs_kind() -> None:
    inputs = reward_inputs(np.random.default_rng(0))
    total, terms = compute_rewards({}, on_torch(inputs), 8.0)
    assert terms == {} and isinstance(total, torch.Tensor) and total.dtype == torch.float64 and not total.any()


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_every_termination_cause_is_the_same_on_torch(seed: int) -> None:
    rng = np.random.default_rng(seed)
    inputs = {
        "base_contact": rng.random(N) < 0.2,
        "thigh_contacts": rng.random((N, 4)) < 0.1,
        "base_height": rng.uniform(0.1, 0.6, N),
        "tilt_cos": rng.uniform(-1, 1, N),
        "diverged": rng.random(N) < 0.2,
    }
    inputs["base_height"][0] = np.nan  # a diverged world's bookkeeping can hold anything: only `diverged` counts
    inputs["diverged"][0] = True
    bounds = TerminationConfig()
    causes, causes_t = termination_causes(inputs, bounds), termination_causes(on_torch(inputs), bounds)
    for name in CAUSE_NAMES:
        assert causes_t[name].dtype == torch.bool
        np.testing.assert_array_equal(causes_t[name].numpy(), causes[name], err_msg=name)
    np.testing.assert_array_equal(any_cause(causes_t).numpy(), any_cause(causes))
    assert [causes[name][0] for name in CAUSE_NAMES] == [name == "diverged" for name in CAUSE_NAMES]


def simulation_inputs(rng: np.random.Generator) -> list[np.ndarray]:
    """The world-frame arguments of lambda_from_simulation for N random states (unit quaternions, feet, contacts)."""
    quaternion = rng.normal(size=(N, 4))
    quaternion /= np.linalg.norm(quaternion, axis=1, keepdims=True)
    rotation = np.stack([quat_wxyz_to_matrix(q) for q in quaternion])
    return [
        rotation,
        rng.normal(size=(N, 3)),  # com
        rng.normal(size=(N, 3)),  # com_vel
        rng.normal(0, 5, (N, 3)),  # com_acc
        rng.normal(0, 5, (N, 3)),  # base_ang_acc
        rng.normal(0, 50, (N, 3)),  # ext_force
        np.zeros((N, 3)),  # ext_torque
        rng.normal(size=(N, 4, 3)),  # feet
        rng.uniform(0.3, 1.0, N),  # mu
        rng.random((N, 4)) < 0.7,  # contacts
        rng.normal(size=(N, 4, 3)),  # normals
    ]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_lambda_from_the_simulation_is_the_same_on_torch(seed: int) -> None:
    """lambda (seed 000 eq. 4) from world-frame quantities, its heading frame and the stance width: the same numbers
    from torch tensors as from numpy arrays, and lambda's layout round-trips through from_lambda."""
    arguments = simulation_inputs(np.random.default_rng(seed))
    rotation = arguments[0]
    lam = lambda_from_simulation(*arguments)
    lam_t = lambda_from_simulation(*(torch.from_numpy(a) for a in arguments))
    assert isinstance(lam, np.ndarray) and lam.shape == (N, LAMBDA_DIM) and lam_t.dtype == torch.float64
    np.testing.assert_allclose(lam_t.numpy(), lam, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(from_lambda(lam).to_lambda(), lam)
    heading = heading_rotation(rotation)
    np.testing.assert_allclose(heading_rotation(torch.from_numpy(rotation)).numpy(), heading, atol=1e-15)
    np.testing.assert_allclose(heading[:, 2], np.tile([0.0, 0.0, 1.0], (N, 1)))  # H keeps the world's z axis
    feet_h = from_lambda(lam).feet
    np.testing.assert_allclose(stance_width(torch.from_numpy(feet_h)).numpy(), stance_width(feet_h), atol=1e-15)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_base_rotation_from_the_quaternion_is_the_same_on_torch(seed: int) -> None:
    """quat_wxyz_to_matrix on tensors equals numpy's to rounding, and both are rotations (R^T R = I, det 1)."""
    quaternion = np.random.default_rng(seed).normal(size=(N, 4))
    rotation = quat_wxyz_to_matrix(quaternion)
    rotation_t = quat_wxyz_to_matrix(torch.from_numpy(quaternion))
    np.testing.assert_allclose(rotation_t.numpy(), rotation, atol=1e-14)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", rotation, rotation), np.broadcast_to(np.eye(3), (N, 3, 3)),
                               atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(np.linalg.det(rotation), 1.0, atol=1e-12)


@pytest.mark.parametrize("terrain", ["flat", "rough"])
def test_terrain_heights_and_normals_are_the_same_on_torch(terrain: str) -> None:
    """Bilinear heights and central-difference normals of the heightfield (and of flat ground) on tensors equal
    numpy's; the grid goes to the tensors' device once and is left out of pickles."""
    import pickle

    from margin_rl.envs.terrain import TerrainConfig, flat_terrain, rough_terrain

    ground = flat_terrain() if terrain == "flat" else rough_terrain(TerrainConfig(size=8.0, border=2.0), seed=4)
    points = np.random.default_rng(0).uniform(-6, 6, size=(N, 4, 2))
    heights, normals = ground.height(points), ground.normal(points)
    points_t = torch.from_numpy(points)
    np.testing.assert_allclose(ground.height(points_t).numpy(), heights, atol=1e-12)
    np.testing.assert_allclose(ground.normal(points_t).numpy(), normals, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0)
    np.testing.assert_array_equal(ground.spawn_points_like(points_t).numpy(), ground.spawn_points)
    assert pickle.loads(pickle.dumps(ground))._on_device == {}
    if terrain == "rough":
        assert np.ptp(heights) > 0.05 and np.any(normals[..., 2] < 0.999)  # the points met slopes and steps


def test_observations_are_assembled_the_same_on_torch() -> None:
    """The observation layout on tensors (with the tensors' generator drawing the noise) equals numpy's without
    noise, and stays within each term's noise band with it."""
    from margin_rl.arrays import TorchRandom
    from margin_rl.envs.observations import POLICY_OBSERVATIONS, assemble

    rng = np.random.default_rng(1)
    values = {t.name: rng.normal(size=(N, t.size)) for t in POLICY_OBSERVATIONS}
    clean = assemble(values, POLICY_OBSERVATIONS, 0.0, rng)
    values_t = {name: torch.from_numpy(v) for name, v in values.items()}
    clean_t = assemble(values_t, POLICY_OBSERVATIONS, 0.0, TorchRandom(0, "cpu"))
    assert clean_t.dtype == torch.float32
    np.testing.assert_array_equal(clean_t.numpy(), clean)
    noisy_t = assemble(values_t, POLICY_OBSERVATIONS, 1.0, TorchRandom(0, "cpu")).numpy()
    band = np.concatenate([np.full(t.size, t.noise * t.scale) for t in POLICY_OBSERVATIONS])
    assert np.all(np.abs(noisy_t - clean) <= band + 1e-6) and np.any(noisy_t != clean)


@pytest.mark.parametrize("robot", ["anymal_b", "anymal_c"])
def test_the_learned_margin_of_the_environments_is_the_same_network_on_torch(robot: str) -> None:
    """The env's learned margin function answers tensors with the torch form of the one network (float32 layers, as
    numpy's batch path): equal to numpy's to float32 rounding; 'none' gives zeros of the input's kind."""
    from margin_rl.envs.margin_kinds import make_margin_function
    from margin_rl.robot import load_robot

    states = lambda_from_simulation(*simulation_inputs(np.random.default_rng(2)))
    margin = make_margin_function("learned", load_robot(robot), None, -0.5)
    values, values_t = margin(states), margin(torch.from_numpy(states))
    assert isinstance(values_t, torch.Tensor) and values_t.dtype == torch.float64
    np.testing.assert_allclose(values_t.numpy(), values, atol=2e-6)
    assert np.ptp(values) > 1e-3  # different states, different margins
    zero = make_margin_function("none", load_robot(robot), None, -0.5)(torch.from_numpy(states))
    assert isinstance(zero, torch.Tensor) and not zero.any()
