"""Physics features of lambda: hand-solved values, exact Jacobians, numpy vs torch, mirror, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES, StabilityState, mirror_lambda
from margin_rl.stability.learned.features import (
    FEATURE_SLICES,
    INPUT_MIRROR_SIGN,
    INPUT_MIRROR_SOURCE,
    N_FEATURES,
    PhysicsConstants,
    feature_names,
    mirror_features,
    mirror_inputs,
    physics_features,
    physics_features_and_jacobian,
    physics_features_torch,
    physics_inputs,
    support_distance,
)

G = 9.81
H = 0.04 * G  # CoM height with sqrt(h / g) = 0.2 s
CONSTANTS = PhysicsConstants(mass=50.0, gravity=G, foot_radius=0.0)
SQUARE = np.array([[0.3, 0.2], [0.3, -0.2], [-0.3, 0.2], [-0.3, -0.2]])  # LF RF LH RH


def state(com_vel=(0.0, 0.0, 0.0), com_acc=(0.0, 0.0, 0.0), contacts=(1, 1, 1, 1), **kw) -> np.ndarray:
    """A level state on the square stance 0.6 m x 0.4 m, feet H below the CoM, flat normals."""
    values = dict(
        gravity_axis=np.array([0.0, 0.0, 1.0]),
        com_vel=np.asarray(com_vel, float),
        com_acc=np.asarray(com_acc, float),
        base_ang_acc=np.zeros(3),
        ext_force=np.zeros(3),
        ext_torque=np.zeros(3),
        feet=np.column_stack([SQUARE, np.full(4, -H)]),
        mu=np.array(0.5),
        contacts=np.asarray(contacts, float),
        normals=np.tile([0.0, 0.0, 1.0], (4, 1)),
    )
    values.update({k: np.asarray(v, float) for k, v in kw.items()})
    return StabilityState(**values).to_lambda()


def feature(f: np.ndarray, name: str) -> np.ndarray:
    out = f[..., FEATURE_SLICES[name]]
    return out[..., 0] if out.shape[-1] == 1 else out


def random_states(n: int, seed: int) -> np.ndarray:
    """Table I-like states around the square stance (all contact counts 1-4), unit normals."""
    rng = np.random.default_rng(seed)
    tilt_a, tilt_b = rng.normal(0, 0.3, (2, n, 4))
    normals = np.stack([np.cos(tilt_a) * np.sin(tilt_b), -np.sin(tilt_a), np.cos(tilt_a) * np.cos(tilt_b)], -1)
    roll, pitch = rng.uniform(-0.2, 0.2, (2, n))
    contacts = (rng.uniform(size=(n, 4)) < 0.75).astype(float)
    contacts[contacts.sum(1) == 0, 0] = 1.0
    return StabilityState(
        gravity_axis=np.stack([-np.sin(pitch), np.cos(pitch) * np.sin(roll), np.cos(pitch) * np.cos(roll)], -1),
        com_vel=rng.uniform(-1.25, 1.25, (n, 3)),
        com_acc=rng.uniform(-2.5, 2.5, (n, 3)),
        base_ang_acc=rng.uniform(-1, 1, (n, 3)),
        ext_force=rng.normal(0, 50, (n, 3)),
        ext_torque=rng.normal(0, 25, (n, 3)),
        feet=np.column_stack([SQUARE, np.full(4, -0.45)])[None] + rng.uniform(-0.15, 0.15, (n, 4, 3)),
        mu=rng.uniform(0.2, 0.9, n),
        contacts=contacts,
        normals=normals,
    ).to_lambda()


# ----------------------------------------------------------------------------- hand-solved values
def test_square_stance_capture_point_and_support_margin() -> None:
    f = physics_features(state(com_vel=(1.0, 0.25, 0.0)), CONSTANTS)
    assert feature(f, "com_height") == pytest.approx(H, abs=1e-4)  # smooth floor: +6e-5 m at 0.39 m
    np.testing.assert_allclose(feature(f, "capture_point"), [0.2, 0.05], atol=2e-5)
    np.testing.assert_allclose(feature(f, "load_shift"), [0.0, 0.0], atol=1e-12)
    # the ICP (0.2, 0.05) is 0.1 m from the front edge x = 0.3 and 0.15 m from the side edge y = 0.2
    assert feature(f, "support_margin") == pytest.approx(0.1, abs=2e-5)
    assert feature(f, "icp_support_distance") == pytest.approx(0.1, abs=2e-5)
    np.testing.assert_allclose(feature(f, "capture_point_from_feet")[:2], [-0.1, -0.15], atol=2e-5)  # from LF
    # beyond the front-left corner (0.3, 0.2): minus the Euclidean distance
    f = physics_features(state(com_vel=(2.0, 1.5, 0.0)), CONSTANTS)
    assert feature(f, "support_margin") == pytest.approx(-math.hypot(0.1, 0.1), abs=5e-5)


def test_forward_acceleration_shifts_the_region_forward() -> None:
    """c_ddot_x = 1 m/s^2: F = (m, 0, m g), s_x = h / g = 0.04 m; the ICP at rest sits 0.04 m behind the
    shifted square's centre, so the margin is 0.2 m to the side edges and 0.26 m to the back one."""
    f = physics_features(state(com_acc=(1.0, 0.0, 0.0)), CONSTANTS)
    np.testing.assert_allclose(feature(f, "load_shift"), [0.04, 0.0], rtol=2e-4)
    np.testing.assert_allclose(feature(f, "shifted_capture_point"), [-0.04, 0.0], rtol=2e-4)
    assert feature(f, "support_margin") == pytest.approx(0.2, abs=1e-9)
    assert feature(f, "friction_usage") == pytest.approx(1.0 / G / 0.5, rel=2e-4)  # |F_xy| / (mu F_z)
    # flat normals: the force's direction (1, 0, g) is inside a mu = 0.5 cone: (0.5 g - 1) / |(1, 0, g)|
    np.testing.assert_allclose(feature(f, "cone_slack"), (0.5 * G - 1.0) / math.hypot(1.0, G), rtol=1e-4)


def test_support_distance_segment_point_and_no_contact() -> None:
    diagonal = (1, 0, 0, 1)  # LF and RH: the segment (0.3, 0.2) - (-0.3, -0.2)
    assert support_distance(SQUARE, diagonal, [0.0, 0.0]) == pytest.approx(0.0, abs=1e-12)
    assert support_distance(SQUARE, diagonal, [0.0, 0.1]) == pytest.approx(-0.06 / math.hypot(0.6, 0.4))
    assert support_distance(SQUARE, diagonal, [0.6, 0.6]) == pytest.approx(-0.5)  # beyond LF: (0.3, 0.4)
    assert support_distance(SQUARE, (0, 0, 1, 0), [0.0, 0.2]) == pytest.approx(-0.3)  # one foot: a point
    none = support_distance(SQUARE, (0, 0, 0, 0), [0.0, 0.0])
    assert np.isfinite(none) and none < -9.0
    f = physics_features(state(contacts=(0, 0, 0, 0)), CONSTANTS)  # defined with no contact
    assert np.all(np.isfinite(f)) and feature(f, "support_margin") < -9.0
    batch = support_distance(SQUARE[None].repeat(3, 0), np.ones((3, 4)), np.zeros((3, 2)))
    np.testing.assert_allclose(batch, 0.2)


def reference_support_distance(points: np.ndarray, p: np.ndarray) -> float:
    """Brute force: outside, minus the distance to the nearest segment between two points (or a point);
    inside (p on the inner side of every hull edge), the distance to the nearest hull edge line."""

    def segment_distance(a: np.ndarray, b: np.ndarray) -> float:
        d = b - a
        t = 0.0 if d @ d == 0 else float(np.clip((p - a) @ d / (d @ d), 0.0, 1.0))
        return float(np.linalg.norm(p - a - t * d))

    n = len(points)
    outside = min(segment_distance(points[i], points[j]) for i in range(n) for j in range(n))
    edges = []
    for i in range(n):
        for j in range(n):
            d = points[j] - points[i]
            if i == j or d @ d == 0:
                continue
            normal = np.array([-d[1], d[0]]) / np.linalg.norm(d)  # left normal
            if all(normal @ (points[k] - points[i]) >= -1e-12 for k in range(n)):
                edges.append(normal @ (p - points[i]))
    if n >= 3 and edges and min(edges) > 0:
        return float(min(edges))
    return -outside


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)), min_size=4, max_size=4),
    st.tuples(st.floats(-0.8, 0.8), st.floats(-0.8, 0.8)),
    st.lists(st.booleans(), min_size=4, max_size=4).filter(any),
)
def test_support_distance_matches_brute_force(feet: list, point: tuple, stance: list) -> None:
    feet_xy, p = np.array(feet), np.array(point)
    stance_points = feet_xy[np.array(stance)]
    expected = reference_support_distance(stance_points, p)
    assert support_distance(feet_xy, np.array(stance, float), p) == pytest.approx(expected, abs=1e-7)


# ----------------------------------------------------------------------------- derivatives, backends
def test_jacobian_matches_central_differences() -> None:
    lam = random_states(12, seed=1)
    f, jac = physics_features_and_jacobian(lam, CONSTANTS)
    np.testing.assert_array_equal(f, physics_features(lam, CONSTANTS))
    assert jac.shape == (12, N_FEATURES, 47)
    step = 1e-6
    contacts = set(range(LAMBDA_SLICES["contacts"].start, LAMBDA_SLICES["contacts"].stop))
    for j in (k for k in range(47) if k not in contacts):
        e = np.zeros(47)
        e[j] = step
        fd = (physics_features(lam + e, CONSTANTS) - physics_features(lam - e, CONSTANTS)) / (2 * step)
        # piecewise-smooth distances: a step may cross a kink, so compare where both sides agree
        np.testing.assert_allclose(jac[:, :, j], fd, atol=2e-5 * (1 + np.abs(fd).max()), err_msg=f"lambda[{j}]")
    single_f, single_jac = physics_features_and_jacobian(lam[3], CONSTANTS)
    np.testing.assert_array_equal(single_f, f[3])
    np.testing.assert_array_equal(single_jac, jac[3])


def test_numpy_and_torch_agree_in_values_and_jacobians() -> None:
    lam = random_states(16, seed=2)
    f, jac = physics_features_and_jacobian(lam, CONSTANTS)
    x = torch.tensor(lam, requires_grad=True)
    out = physics_features_torch(x, CONSTANTS)
    np.testing.assert_allclose(out.detach().numpy(), f, rtol=0, atol=1e-12)
    for k in range(N_FEATURES):
        (grad,) = torch.autograd.grad(out[:, k].sum(), x, retain_graph=True)
        np.testing.assert_allclose(grad.numpy(), jac[:, k], rtol=0, atol=1e-10, err_msg=feature_names()[k])
    assert physics_features_torch(x[0], CONSTANTS).shape == (N_FEATURES,)


def test_the_torch_features_stay_on_lambdas_device() -> None:
    """Every tensor the features combine is made on lambda's device: on torch's "meta" device (shapes only, no data:
    any tensor left on the CPU would refuse to combine with it, as it would beside a GPU)."""
    lam = torch.as_tensor(random_states(4, seed=5)).to("meta")
    out = physics_features_torch(lam, CONSTANTS)
    assert out.device.type == "meta" and tuple(out.shape) == (4, N_FEATURES)


def test_features_are_mirror_equivariant_to_the_last_bit() -> None:
    lam = random_states(500, seed=3)
    f = physics_features(lam, CONSTANTS)
    np.testing.assert_array_equal(physics_features(mirror_lambda(lam), CONSTANTS), mirror_features(f))
    x = physics_inputs(lam, CONSTANTS)
    np.testing.assert_array_equal(physics_inputs(mirror_lambda(lam), CONSTANTS), mirror_inputs(x))
    # the input mirror is an involution with equal signs on swapped entries (what the tied network needs)
    np.testing.assert_array_equal(INPUT_MIRROR_SOURCE[INPUT_MIRROR_SOURCE], np.arange(len(INPUT_MIRROR_SOURCE)))
    np.testing.assert_array_equal(INPUT_MIRROR_SIGN[INPUT_MIRROR_SOURCE], INPUT_MIRROR_SIGN)


# ----------------------------------------------------------------------------- bad input
def test_bad_inputs_are_refused_with_clear_errors() -> None:
    with pytest.raises(ValueError, match="shape"):
        physics_features(np.zeros(46), CONSTANTS)
    with pytest.raises(ValueError, match="shape"):
        physics_features_and_jacobian(np.zeros((2, 3, 47)), CONSTANTS)
    lam = state()
    lam[LAMBDA_SLICES["com_vel"].start] = np.nan
    with pytest.raises(ValueError, match=r"com_vel\.x"):
        physics_features(lam, CONSTANTS)
    with pytest.raises(ValueError, match="last dimension"):
        physics_features_torch(torch.zeros(3, 46), CONSTANTS)
    with pytest.raises(ValueError, match="mass"):
        PhysicsConstants(mass=0.0, gravity=G, foot_radius=0.03)
    with pytest.raises(ValueError, match="foot_radius"):
        PhysicsConstants(mass=50.0, gravity=G, foot_radius=float("nan"))
    with pytest.raises(ValueError, match="feet"):
        support_distance(np.zeros((3, 2)), np.ones(4), np.zeros(2))
    with pytest.raises(ValueError, match="last dimension"):
        mirror_features(np.zeros(5))
    assert len(feature_names()) == N_FEATURES == len(set(feature_names()))
