"""The extended margin m_x: equal to m_a where it exists, the relaxed load and the support fallback elsewhere."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl import load_robot
from margin_rl.stability.analytic.extended import (
    DEFAULT_LOAD_PENALTY,
    DYNAMIC_LOAD_FIELDS,
    SOURCES,
    extended_margin,
    extended_margin_batch,
    scale_dynamic_load,
    support_hull_distance,
)
from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES, from_lambda
from margin_rl.stability.analytic.margin import STATUSES, AnalyticSettings, analytic_margin, analytic_margin_batch
from margin_rl.stability.analytic.sampling import sample_states, standing_state

VELOCITY = np.array([0.3, 0.1, 0.0])
# Next to the friction limit the batched labelling path's re-used solver can cut the region wrongly (BENCHMARKS,
# "Extended margin"): the checks at the edge of feasibility use the per-state reference path.
REFERENCE = AnalyticSettings(labelling="per_state")


@pytest.fixture(scope="module")
def robot():
    return load_robot("anymal_c")


def pushed(robot, forward_acc: float) -> np.ndarray:
    """Standing ANYmal C (mu 0.8) walking forward and accelerating: friction-infeasible above ~7.85 m/s^2."""
    return standing_state(robot, com_acc=np.array([forward_acc, 0.0, 0.0]), com_vel=VELOCITY)


def test_scale_dynamic_load_scales_only_the_load_fields(robot) -> None:
    lam = sample_states(robot, 5, seed=1)
    alpha = np.array([0.0, 0.25, 0.5, 1.0, 2.0])
    scaled = scale_dynamic_load(lam, alpha)
    load = np.zeros(lam.shape[1], dtype=bool)
    for name in DYNAMIC_LOAD_FIELDS:
        load[LAMBDA_SLICES[name]] = True
    np.testing.assert_array_equal(scaled[:, ~load], lam[:, ~load])
    np.testing.assert_allclose(scaled[:, load], alpha[:, None] * lam[:, load])
    np.testing.assert_array_equal(scale_dynamic_load(lam, 1.0), lam)


def test_equals_the_analytic_margin_where_it_exists(robot) -> None:
    lam = sample_states(robot, 60, seed=3)
    analytic = analytic_margin_batch(robot.name, lam, workers=1)
    result = extended_margin_batch(robot, lam)
    ok = analytic.status == STATUSES.index("ok")
    assert ok.any() and (~ok).any()
    np.testing.assert_array_equal(result.margin[ok], analytic.margin[ok])
    assert (result.source[ok] == SOURCES.index("analytic")).all()
    assert (result.load_fraction[ok] == 1.0).all()
    # Every state of a sampled stance has a value: relaxed or the support fallback.
    assert np.isfinite(result.margin).all()
    assert result.counts()["none"] == 0


def test_relaxed_load_is_the_edge_of_feasibility(robot) -> None:
    lam = pushed(robot, 9.0)
    assert analytic_margin(robot, lam).status == "infeasible"
    steps = 8
    result = extended_margin_batch(robot, lam[None], REFERENCE, bisection_steps=steps)
    alpha = float(result.load_fraction[0])
    assert result.source[0] == SOURCES.index("relaxed")
    assert 0.0 < alpha < 1.0
    # Two independent checks of the bisection: the load fraction it returns is feasible, one step more is not.
    at_alpha = analytic_margin(robot, scale_dynamic_load(lam, alpha))
    assert at_alpha.status == "ok"
    assert analytic_margin(robot, scale_dynamic_load(lam, alpha + 2.0**-steps)).status == "infeasible"
    # Friction bound: the supportable forward acceleration is at most mu g (all normal force used).
    assert alpha * 9.0 <= 0.8 * robot.gravity + 1e-6
    assert result.margin[0] == pytest.approx(at_alpha.margin - DEFAULT_LOAD_PENALTY * (1.0 - alpha))


def test_no_jump_where_the_status_changes(robot) -> None:
    """The floor would jump by more than 0.5 m at the edge of feasibility; m_x moves by ~1 cm there."""
    accelerations = np.arange(7.7, 8.05, 0.05)
    lams = np.stack([pushed(robot, a) for a in accelerations])
    result = extended_margin_batch(robot, lams, REFERENCE, bisection_steps=10)
    source = result.source
    edge = int(np.flatnonzero(source == SOURCES.index("relaxed"))[0])
    assert edge > 0 and source[edge - 1] == SOURCES.index("analytic")
    assert abs(result.margin[edge] - result.margin[edge - 1]) < 0.02
    assert abs(result.margin[edge - 1] - (-0.5)) > 0.5


def test_more_penalty_lowers_relaxed_states_only(robot) -> None:
    lams = np.stack([pushed(robot, 4.0), pushed(robot, 12.0)])
    low = extended_margin_batch(robot, lams, penalty=0.0)
    high = extended_margin_batch(robot, lams, penalty=1.0)
    assert high.margin[0] == low.margin[0]
    expected = low.margin[1] - (1.0 - low.load_fraction[1])
    assert high.margin[1] == pytest.approx(expected)


def test_no_contact_uses_the_hull_of_all_feet(robot) -> None:
    still = standing_state(robot, contacts=np.zeros(4))
    assert extended_margin(robot, still) == pytest.approx(-DEFAULT_LOAD_PENALTY)
    # Running fast forward in flight: the ICP v sqrt(z / g) is ahead of the front feet by a computable amount.
    fast = standing_state(robot, contacts=np.zeros(4), com_vel=np.array([4.0, 0.0, 0.0]))
    st_ = from_lambda(fast)
    points = st_.feet - robot.foot_radius * st_.normals
    icp_x = 4.0 * math.sqrt(-points[:, 2].mean() / robot.gravity)
    front = points[:, 0].max()
    assert icp_x > front  # the hand computation below assumes the ICP is beyond the front edge
    expected = -DEFAULT_LOAD_PENALTY - (icp_x - front)
    assert extended_margin(robot, fast) == pytest.approx(expected, abs=1e-9)
    result = extended_margin_batch(robot, fast[None])
    assert result.status[0] == STATUSES.index("no_contact") and result.source[0] == SOURCES.index("support")


def test_support_hull_distance_hand_cases() -> None:
    square = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    assert support_hull_distance(square, np.array([0.2, -0.3])) == 0.0
    assert support_hull_distance(square, np.array([3.0, 0.0])) == pytest.approx(2.0)
    assert support_hull_distance(square, np.array([4.0, 5.0])) == pytest.approx(5.0)  # to the corner (1, 1)
    assert support_hull_distance(square[:1], np.array([4.0, 5.0])) == pytest.approx(5.0)
    segment = square[[0, 2]]  # the diagonal of a trot's stance
    assert support_hull_distance(segment, np.array([1.0, -1.0])) == pytest.approx(math.sqrt(2.0))
    assert support_hull_distance(segment, np.array([0.5, 0.5])) == pytest.approx(0.0, abs=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    points=st.lists(st.tuples(st.floats(-1, 1), st.floats(-1, 1)), min_size=1, max_size=6, unique=True),
    p=st.tuples(st.floats(-3, 3), st.floats(-3, 3)),
)
def test_support_hull_distance_matches_a_dense_boundary(points, p) -> None:
    """Against the minimum distance over points sampled densely on every segment between the points."""
    pts, q = np.array(points), np.array(p)
    d = support_hull_distance(pts, q)
    assert d >= 0.0
    t = np.linspace(0.0, 1.0, 401)[:, None]
    samples = np.concatenate([a + t * (b - a) for a in pts for b in pts]) if len(pts) > 1 else pts
    # The hull contains every sampled point, so its distance is at most theirs (up to the sampling step).
    assert d <= np.linalg.norm(samples - q, axis=1).min() + 1e-9


def test_bad_input_is_refused_with_the_name(robot) -> None:
    lam = standing_state(robot)
    with pytest.raises(ValueError, match="penalty"):
        extended_margin_batch(robot, lam[None], penalty=-0.1)
    with pytest.raises(ValueError, match="penalty"):
        extended_margin_batch(robot, lam[None], penalty=float("nan"))
    with pytest.raises(ValueError, match="bisection_steps"):
        extended_margin_batch(robot, lam[None], bisection_steps=0)
    with pytest.raises(ValueError, match="shape"):
        extended_margin_batch(robot, lam)
    with pytest.raises(ValueError, match="shape"):
        extended_margin(robot, lam[None])
    bad = lam.copy()
    bad[LAMBDA_SLICES["com_vel"]][0] = np.nan
    with pytest.raises(ValueError, match="com_vel"):
        extended_margin(robot, bad)
