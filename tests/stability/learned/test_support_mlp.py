"""Support-function margin model: the exact geometry (hand-solved stance, against the features' independent support
distance), concavity in the capture point, the velocity only through xi, mirror-closed directions, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, LAMBDA_SLICES, StabilityState
from margin_rl.stability.learned.features import support_distance
from margin_rl.stability.learned.support_mlp import (
    N_PAIR_DIRECTIONS,
    SupportMarginMLP,
    build_support_model,
    fixed_directions,
)

G = 9.81
HEIGHT = 0.04 * G  # sqrt(h / g) = 0.2 s: xi = 0.2 s x c_dot
SQUARE = np.array([[0.3, 0.2], [0.3, -0.2], [-0.3, 0.2], [-0.3, -0.2]])  # LF RF LH RH


def state(com_vel=(0.0, 0.0), contacts=(1, 1, 1, 1), feet_xy=SQUARE, com_acc=(0.0, 0.0, 0.0)) -> np.ndarray:
    return StabilityState(
        gravity_axis=np.array([0.0, 0.0, 1.0]),
        com_vel=np.array([*com_vel, 0.0], float),
        com_acc=np.asarray(com_acc, float),
        base_ang_acc=np.zeros(3),
        ext_force=np.zeros(3),
        ext_torque=np.zeros(3),
        feet=np.column_stack([feet_xy, np.full(4, -HEIGHT)]),
        mu=np.array(0.5),
        contacts=np.asarray(contacts, float),
        normals=np.tile([0.0, 0.0, 1.0], (4, 1)),
    ).to_lambda()


def model(directions: int = 32, zero_network: bool = True, seed: int = 0) -> SupportMarginMLP:
    torch.manual_seed(seed)
    net = SupportMarginMLP(
        input_mean=np.zeros(LAMBDA_DIM),
        input_std=np.ones(LAMBDA_DIM),
        output_mean=0.0,
        output_std=0.1,
        foot_radius=0.0,
        gravity=G,
        directions=directions,
    ).double()
    if zero_network:
        with torch.no_grad():
            for p in net.trunk.parameters():
                p.zero_()
    return net.eval()


def margin(net: SupportMarginMLP, lam: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return net(torch.as_tensor(lam, dtype=torch.float64)).numpy()


def test_prior_alone_is_the_distance_to_the_stance_rectangle() -> None:
    """With the network at zero the model is the signed distance of xi to the stance polygon: on the 0.6 x 0.4 m
    rectangle, xi = 0.2 s x c_dot, inside 0.2 - |xi_y| or 0.3 - |xi_x| (whichever is smaller), outside minus the
    Euclidean distance."""
    net = model()
    cases = {
        (0.0, 0.0): 0.2,
        (0.5, 0.0): 0.2,  # xi = (0.1, 0): nearest edge y = +-0.2
        (1.0, 0.5): 0.1,  # xi = (0.2, 0.1): 0.1 to both
        (2.0, 0.0): -0.1,  # xi = (0.4, 0): 0.1 beyond x = 0.3
        (2.0, 1.5): -np.hypot(0.1, 0.1),  # beyond the corner (0.3, 0.2): fixed directions, 0.5 % of the distance
    }
    lam = np.stack([state(v) for v in cases])
    expected = np.array(list(cases.values()))
    np.testing.assert_allclose(margin(net, lam), expected, atol=1e-9 + 0.005 * 0.15)
    # A two-foot diagonal stance: the pair normals make the sliver exact, the fixed directions alone could not.
    diagonal = state((0.25, -0.15), contacts=(1, 0, 0, 1))  # LF (0.3, 0.2) and RH (-0.3, -0.2); xi (0.05, -0.03)
    line = SQUARE[3] - SQUARE[0]
    normal = np.array([line[1], -line[0]]) / np.linalg.norm(line)
    assert margin(net, diagonal) == pytest.approx(-abs(normal @ np.array([0.05, -0.03])), abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-0.25, 0.25), min_size=8, max_size=8),
    st.lists(st.floats(-3.0, 3.0), min_size=2, max_size=2),
    st.sampled_from([(1, 1, 1, 1), (1, 1, 1, 0), (0, 1, 1, 1), (1, 0, 0, 1), (0, 1, 1, 0)]),
)
def test_prior_matches_the_features_support_distance(jitter, velocity, contacts) -> None:
    """Independent implementation: the physics features' exact support distance (candidate directions, no hull).
    Inside the stance polygon and beyond an edge both are exact; beyond a vertex the nearest of the fixed
    directions misses by at most 1 - cos(pi / K) of the distance."""
    feet = SQUARE + 0.4 * np.asarray(jitter).reshape(4, 2)
    lam = state(velocity, contacts=contacts, feet_xy=feet)
    xi = 0.2 * np.asarray(velocity)
    exact = support_distance(feet, np.asarray(contacts, float), xi)
    got = float(margin(model(), lam))
    assert exact - 1e-9 <= got <= exact + (1 - np.cos(np.pi / 32)) * max(-exact, 0.0) + 1e-9


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(-2.0, 2.0), min_size=4, max_size=4),
    st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
    st.integers(0, 5),
)
def test_margin_is_concave_in_the_velocity_and_the_region_ignores_it(velocities, acceleration, seed) -> None:
    """With a random network: the support values do not depend on c_dot, and m is a minimum of functions affine in
    xi = c_dot sqrt(z / g), hence concave along any line of velocities."""
    net = model(zero_network=False, seed=seed)
    a = state(velocities[:2], com_acc=acceleration)
    b = state(velocities[2:], com_acc=acceleration)
    with torch.no_grad():
        _, h_a, _ = net.support(torch.as_tensor(a))
        _, h_b, _ = net.support(torch.as_tensor(b))
    torch.testing.assert_close(h_a, h_b, rtol=0, atol=0)
    m_a, m_b, m_mid = margin(net, np.stack([a, b, 0.5 * (a + b)]))
    assert m_mid >= 0.5 * (m_a + m_b) - 1e-12


def test_directions_are_closed_under_the_mirror_and_gradients_reach_lambda() -> None:
    fixed = fixed_directions(32)
    mirrored = fixed * np.array([1.0, -1.0])
    distances = np.linalg.norm(mirrored[:, None, :] - fixed[None, :, :], axis=-1)
    assert distances.min(axis=1).max() < 1e-12
    net = model(zero_network=False)
    lam = torch.tensor(state((0.3, 0.1)), requires_grad=True)
    directions, h, _ = net.support(lam)
    assert directions.shape == (32 + N_PAIR_DIRECTIONS, 2) and h.shape == (32 + N_PAIR_DIRECTIONS,)
    net(lam).backward()
    grad = lam.grad.numpy()
    step = 1e-6
    for index in (LAMBDA_SLICES["com_vel"].start, LAMBDA_SLICES["com_acc"].start, LAMBDA_SLICES["feet"].start):
        e = np.zeros(LAMBDA_DIM)
        e[index] = step
        base = state((0.3, 0.1))
        fd = (margin(net, base + e) - margin(net, base - e)) / (2 * step)
        assert grad[index] == pytest.approx(fd, rel=1e-5, abs=1e-8)


def test_bad_input_is_refused_with_the_reason() -> None:
    with pytest.raises(ValueError, match="at least 3 fixed directions"):
        fixed_directions(2)
    with pytest.raises(ValueError, match="foot_radius >= 0"):
        SupportMarginMLP(np.zeros(LAMBDA_DIM), np.ones(LAMBDA_DIM), 0.0, 1.0, foot_radius=-0.1, gravity=G)
    with pytest.raises(ValueError, match="lam_train"):
        build_support_model(np.zeros((5, 46)), np.zeros(5), 0.0, G)
    with pytest.raises(ValueError, match="lam_train"):
        build_support_model(np.zeros((5, LAMBDA_DIM)), np.zeros(4), 0.0, G)


def test_shifted_prior_moves_the_rectangle_by_the_static_load_shift() -> None:
    """c_ddot_x = 1 m/s^2 on flat ground: the centre of pressure is z c_ddot_x / g = 0.04 m behind the CoM, so the
    feasible CoM region is the rectangle moved 0.04 m forward, x in [-0.26, 0.34]: xi = +-0.3 m is 0.04 m inside
    its front edge and 0.04 m behind its rear edge."""
    torch.manual_seed(0)
    net = SupportMarginMLP(
        np.zeros(LAMBDA_DIM), np.ones(LAMBDA_DIM), 0.0, 0.1, foot_radius=0.0, gravity=G, prior="shifted", mass=40.0
    ).double()
    with torch.no_grad():
        for p in net.trunk.parameters():
            p.zero_()
    lam = np.stack([state((1.5, 0.0), com_acc=(1.0, 0.0, 0.0)), state((-1.5, 0.0), com_acc=(1.0, 0.0, 0.0))])
    np.testing.assert_allclose(margin(net, lam), [0.34 - 0.3, -(0.3 - 0.26)], atol=1e-12)
    with pytest.raises(ValueError, match="prior must be one of"):
        SupportMarginMLP(np.zeros(LAMBDA_DIM), np.ones(LAMBDA_DIM), 0.0, 1.0, foot_radius=0.0, gravity=G, prior="x")
