"""Tests of the aSLIP hop integrator: one hop is a batch of one; the stance by batched RK4 or solve_ivp."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.slip.dynamics import (
    SlipParams,
    Status,
    actuator_profile,
    return_map,
    simulate_batch,
    simulate_hop,
)

CONSERVATIVE = SlipParams(damping_ratio=0.0)


def _random_feasible(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """State-action samples that mostly reach stance (so the comparison exercises it)."""
    rng = np.random.default_rng(seed)
    states = np.column_stack([rng.uniform(0.95, 1.2, n), rng.uniform(-1.0, 1.0, n)])
    actions = np.column_stack([rng.uniform(-0.45, 0.45, n), rng.uniform(-0.05, 0.15, n)])
    return states, actions


# ---------------------------------------------------------------------------- parameters


def test_params_defaults_match_paper() -> None:
    p = SlipParams()
    assert (p.stiffness, p.damping_ratio, p.friction) == (20.0, 0.1, 0.5)
    assert p.damping == pytest.approx(2 * 0.1 * math.sqrt(20.0))


@pytest.mark.parametrize("field", ["stiffness", "extension_time", "max_stance_time"])
def test_params_reject_nonpositive(field: str) -> None:
    with pytest.raises(ValueError, match=field):
        SlipParams(**{field: 0.0})


def test_batch_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match="states"):
        simulate_batch(np.zeros((3, 3)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="differ"):
        simulate_batch(np.ones((3, 2)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="dt"):
        simulate_batch(np.ones((1, 2)), np.zeros((1, 2)), dt=-1.0)


def test_actuator_profile_is_smooth_step() -> None:
    tau = np.array([-np.inf, -0.1, 0.0, 0.05, 0.1, 0.5])
    length, rate = actuator_profile(tau, 0.1, 0.1)
    np.testing.assert_allclose(length, [0.0, 0.0, 0.0, 0.05, 0.1, 0.1], atol=1e-15)
    np.testing.assert_allclose(rate[[0, 1, 2, 4, 5]], 0.0, atol=1e-15)
    assert rate[3] == pytest.approx(0.1 * 1.5 / 0.1)


# ---------------------------------------------------------------------------- energy


@pytest.mark.parametrize("state,alpha", [([1.1, 0.6], 0.25), ([1.05, -0.3], -0.1), ([1.15, 0.0], 0.0)])
def test_undamped_unactuated_hop_conserves_energy(state: list[float], alpha: float) -> None:
    ref = simulate_hop(state, [alpha, 0.0], CONSERVATIVE)
    assert ref.status is Status.OK
    assert ref.work_actuator == pytest.approx(0.0, abs=1e-14)
    assert ref.work_damping == pytest.approx(0.0, abs=1e-14)
    assert ref.energy1 == pytest.approx(ref.energy0, abs=1e-9)
    # At liftoff F = k * delta = 0, so the spring is relaxed and nothing is lost in the leg.
    assert ref.leg_energy_loss == pytest.approx(0.0, abs=1e-12)
    batch = simulate_batch([state], [[alpha, 0.0]], CONSERVATIVE)
    assert batch.energy1[0] == pytest.approx(batch.energy0[0], abs=1e-6)


def test_energy_bookkeeping_with_damping_and_actuation() -> None:
    states, actions = _random_feasible(60, seed=3)
    batch = simulate_batch(states, actions)
    ok = batch.valid
    assert ok.sum() >= 10
    residual = batch.energy1 - (batch.energy0 + batch.work_actuator - batch.work_damping - batch.leg_energy_loss)
    assert np.max(np.abs(residual[ok])) < 1e-6
    # Damping must actually dissipate, otherwise the identity above is vacuous.
    assert np.all(batch.work_damping[ok] > 1e-4)
    i = int(np.flatnonzero(ok)[0])
    ref = simulate_hop(states[i], actions[i])
    assert abs(ref.energy_residual) < 1e-9
    assert ref.leg_energy_loss > 0.0


# ---------------------------------------------------------------------------- symmetric hops


@pytest.mark.parametrize("y0", [1.02, 1.1, 1.2])
def test_vertical_hop_returns_to_same_apex_without_damping(y0: float) -> None:
    ref = simulate_hop([y0, 0.0], [0.0, 0.0], CONSERVATIVE)
    assert ref.status is Status.OK
    np.testing.assert_allclose(ref.next_apex, [0.0, y0, 0.0], atol=1e-9)
    batch = simulate_batch([[y0, 0.0]], [[0.0, 0.0]], CONSERVATIVE)
    np.testing.assert_allclose(batch.next_apex[0], [0.0, y0, 0.0], atol=1e-6)


def test_vertical_hop_damping_loses_and_actuator_adds_height() -> None:
    heights = [simulate_hop([1.1, 0.0], [0.0, dl]).next_apex[1] for dl in (0.0, 0.05, 0.1)]
    assert heights[0] < 1.1 - 1e-3
    assert heights[0] < heights[1] < heights[2]


@settings(max_examples=25, deadline=None)
@given(
    y=st.floats(0.9, 1.2),
    xdot=st.floats(-1.0, 1.0),
    alpha=st.floats(-0.5, 0.5),
    dl=st.floats(-0.05, 0.15),
)
def test_mirror_symmetry(y: float, xdot: float, alpha: float, dl: float) -> None:
    """Reflecting x maps Phi(y, xd, a, dL) to (-dx, y1, -xd1): a check on signs and frames."""
    nxt, valid = return_map([[y, xdot], [y, -xdot]], [[alpha, dl], [-alpha, dl]])
    assert valid[0] == valid[1]
    if valid[0]:
        np.testing.assert_allclose(nxt[1], nxt[0] * [-1.0, 1.0, -1.0], atol=1e-9)


# ---------------------------------------------------------------------------- friction


def test_slip_at_touchdown_switches_exactly_at_friction_limit() -> None:
    p = SlipParams()
    limit = math.atan(p.friction)
    state = [1.15, 0.9]  # fast forward motion: the leg angle shrinks after touchdown
    above = simulate_hop(state, [limit + 1e-9, 0.05], p)
    below = simulate_hop(state, [limit - 1e-9, 0.05], p)
    assert above.status is Status.SLIP
    assert above.failure[1] == pytest.approx(math.cos(limit + 1e-9))  # failed at touchdown
    assert below.status is not Status.SLIP or below.failure[1] != pytest.approx(below.touchdown[1])
    batch = simulate_batch([state, state], [[limit + 1e-9, 0.05], [limit - 1e-9, 0.05]], p)
    assert batch.status[0] == Status.SLIP
    assert batch.status[1] == below.status


def test_stance_slip_is_located_on_the_friction_cone() -> None:
    # Foot ahead, body moving backwards: the leg leans further until |F_t| = mu F_n.
    state, action = [1.126, -0.678], [0.186, 0.083]
    ref = simulate_hop(state, action)
    assert ref.status is Status.SLIP
    assert ref.failure[1] < ref.touchdown[1]  # well inside stance, not at touchdown
    ratio = abs(ref.failure[0] - ref.foot_x) / ref.failure[1]  # |F_t| / F_n for an axial leg force
    assert ratio == pytest.approx(0.5, abs=1e-9)
    batch = simulate_batch([state], [action])
    assert batch.status[0] == Status.SLIP
    assert abs(batch.failure[0, 0] - batch.foot_x[0]) / batch.failure[0, 1] == pytest.approx(0.5, abs=1e-9)
    np.testing.assert_allclose(batch.failure[0], ref.failure, atol=1e-6)
    # A slightly higher friction coefficient postpones or removes the slip.
    grippier = simulate_hop(state, action, SlipParams(friction=0.5 + 1e-4))
    assert grippier.status is not Status.SLIP or grippier.failure[1] < ref.failure[1]


# ---------------------------------------------------------------------------- other failures


@pytest.mark.parametrize(
    "state,action,expected",
    [
        ([0.9, 0.2], [0.1, 0.05], Status.NO_TOUCHDOWN),  # apex below the touchdown height
        ([0.995, 0.934], [-0.394, 0.035], Status.FALL),  # leg lengthening at touchdown
        ([1.0, 0.0], [0.0, -0.05], Status.NO_LIFTOFF),  # settles on the spring
        ([1.042, 0.951], [-0.105, -0.034], Status.NO_APEX),  # lifts off moving down
        ([0.973, 0.54], [0.263, 0.091], Status.OK),
    ],
)
def test_failure_statuses(state: list[float], action: list[float], expected: Status) -> None:
    ref = simulate_hop(state, action)
    batch = simulate_batch([state], [action])
    assert ref.status is expected
    assert Status(int(batch.status[0])) is expected
    assert np.all(np.isnan(ref.next_apex)) == (expected is not Status.OK)


# ---------------------------------------------------------------------------- batch vs reference


def test_batch_matches_solve_ivp_reference() -> None:
    states, actions = _random_feasible(40, seed=11)
    batch = simulate_batch(states, actions)
    n_ok = 0
    for i in range(len(states)):
        ref = simulate_hop(states[i], actions[i], rtol=1e-11, atol=1e-12)
        assert int(batch.status[i]) == int(ref.status), i
        np.testing.assert_allclose(batch.touchdown[i], ref.touchdown, atol=1e-9)
        if ref.ok:
            n_ok += 1
            np.testing.assert_allclose(batch.next_apex[i], ref.next_apex, atol=1e-6)
            np.testing.assert_allclose(batch.liftoff[i], ref.liftoff, atol=1e-6)
            assert batch.t_max_compression[i] == pytest.approx(ref.t_max_compression, abs=1e-6)
    assert n_ok >= 8  # the comparison must cover successful hops


def test_a_hop_is_a_batch_of_one() -> None:
    """simulate_hop is row i of simulate_batch with the same stance method, to the last bit."""
    states, actions = _random_feasible(12, seed=5)
    states[0], actions[0] = [0.9, 0.2], [0.1, 0.05]  # no touchdown
    for method in ("rk4", "DOP853"):
        batch = simulate_batch(states, actions, method=method)
        for i in range(len(states)):
            hop = simulate_hop(states[i], actions[i], method=method)
            assert int(hop.status) == int(batch.status[i])
            for name in ("next_apex", "touchdown", "liftoff", "failure"):
                np.testing.assert_array_equal(getattr(hop, name), getattr(batch, name)[i])
            for name in ("t_max_compression", "t_liftoff", "t_apex", "energy1", "work_damping", "leg_energy_loss"):
                np.testing.assert_array_equal(getattr(hop, name), getattr(batch, name)[i])
            assert isinstance(hop.t_apex, float) and isinstance(hop.status, Status)
    assert simulate_batch(states, actions, method="rk4").n_steps > 0


@pytest.mark.parametrize("method", ["DOP853", "rk4"])
def test_recorded_path_runs_from_apex_to_apex(method: str) -> None:
    hop = simulate_hop([1.1, 0.3], [0.1, 0.03], method=method, record_path=True)
    assert hop.ok and hop.path is not None
    t, x, y = hop.path.T
    np.testing.assert_array_equal(hop.path[0], [0.0, 0.0, 1.1])
    np.testing.assert_allclose(hop.path[-1], [hop.t_apex, *hop.next_apex[:2]], atol=1e-12)
    assert np.all(np.diff(t) >= 0) and np.max(np.diff(t)) <= 0.01 + 1e-12
    flight = t <= hop.t_touchdown
    np.testing.assert_allclose(y[flight], 1.1 - 0.5 * t[flight] ** 2, atol=1e-12)  # ballistic, closed form
    np.testing.assert_allclose(x[flight], 0.3 * t[flight], atol=1e-12)
    stance = (t > hop.t_touchdown) & (t < hop.t_liftoff)
    assert stance.sum() > 10 and np.all(y[stance] < 1.0)
    failed = simulate_hop([0.995, 0.934], [-0.394, 0.035], method=method, record_path=True)
    assert failed.status is Status.FALL and failed.path[-1, 0] == pytest.approx(failed.t_touchdown)


def test_unknown_method_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown method"):
        simulate_hop([0.9, 0.2], [0.1, 0.05], method="euler")  # refused even when no stance is integrated


def test_return_map_marks_failures_nan() -> None:
    nxt, valid = return_map([[0.85, 0.0], [1.1, 0.3]], [[0.0, 0.05], [0.1, 0.05]])
    assert valid.tolist() == [False, True]
    assert np.all(np.isnan(nxt[0])) and np.all(np.isfinite(nxt[1]))
