"""Analytic margin of a robot state: statuses, physics sanity, ICP, batch evaluation, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from margin_rl import load_robot
from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES, from_lambda
from margin_rl.stability.analytic.margin import STATUSES, AnalyticSettings, analytic_margin, analytic_margin_batch
from margin_rl.stability.analytic.sampling import nominal_feet, sample_states, standing_state
from margin_rl.stability.geometry.icp import stability_margin


@pytest.fixture(scope="module", params=["anymal_b", "anymal_c"])
def robot(request):
    return load_robot(request.param)


def contact_polygon_distance(points_xy: np.ndarray, p: np.ndarray) -> float:
    """Signed distance of p to the convex polygon of four rectangle-like points (positive inside)."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(points_xy)
    # hull.equations rows: n.x + d <= 0 inside with outward unit n.
    return float(np.min(-(hull.equations[:, :2] @ p + hull.equations[:, 2])))


def test_standing_robot_is_stable_and_region_inside_support_polygon(robot) -> None:
    result = analytic_margin(robot, standing_state(robot), AnalyticSettings(focus_tol=None))
    assert result.status == "ok", result.message
    assert result.margin > 0.1
    contact_xy = (nominal_feet(robot) - [0, 0, robot.foot_radius])[:, :2]
    # Torque limits can only shrink the region below the support polygon.
    for v in result.region.vertices:
        assert contact_polygon_distance(contact_xy, v) > -2e-3
    assert result.margin <= contact_polygon_distance(contact_xy, np.zeros(2)) + 1e-3
    assert set(result.timings) >= {"kinematics_dynamics", "region", "total"}
    assert result.n_lps >= 4


def test_capture_point_and_margin_follow_eq5_and_eq7(robot) -> None:
    v = np.array([0.6, -0.2, 0.0])
    result = analytic_margin(robot, standing_state(robot, com_vel=v))
    omega = np.sqrt(robot.gravity / result.com_height)
    np.testing.assert_allclose(result.capture_point, v[:2] / omega, atol=1e-12)
    assert result.margin == pytest.approx(stability_margin(result.region, result.capture_point))
    still = analytic_margin(robot, standing_state(robot))
    assert result.margin < still.margin
    # CoM height: above the stance contact points (sphere centre minus radius along the normal).
    expected = -np.mean(nominal_feet(robot)[:, 2] - robot.foot_radius)
    assert result.com_height == pytest.approx(expected)


def test_forward_acceleration_moves_the_region_forward(robot) -> None:
    """c_ddot_x = a tilts the gravito-inertial force m (a, 0, g): the ZMP x - h a / g must stay in the
    support polygon, so the region's front and back edges both shift forward by h a / g."""
    a = 1.5
    full = AnalyticSettings(focus_tol=None)  # the whole region, refined uniformly
    still = analytic_margin(robot, standing_state(robot), full)
    accel = analytic_margin(robot, standing_state(robot, com_acc=np.array([a, 0.0, 0.0])), full)
    expected = still.com_height * a / robot.gravity
    for extreme in (np.min, np.max):
        shift = extreme(accel.region.vertices[:, 0]) - extreme(still.region.vertices[:, 0])
        assert shift == pytest.approx(expected, rel=0.05)


def test_trot_stance_has_no_positive_margin(robot) -> None:
    result = analytic_margin(
        robot, standing_state(robot, contacts=np.array([1.0, 0.0, 0.0, 1.0])), AnalyticSettings(focus_tol=None)
    )
    assert result.status == "ok", result.message
    assert result.margin <= 5e-3
    diagonal = nominal_feet(robot)[0, :2] - nominal_feet(robot)[3, :2]  # LF - RH
    across = np.array([diagonal[1], -diagonal[0]]) / np.linalg.norm(diagonal)
    width = np.ptp(result.region.vertices @ across)
    assert width < 0.01  # a thin segment along the diagonal (contact torques w_M give it a width)


def test_statuses(robot) -> None:
    far = nominal_feet(robot).copy()
    far[0] += [0.5, 0.0, -0.3]
    assert analytic_margin(robot, standing_state(robot, feet=far)).status == "unreachable"
    none = analytic_margin(robot, standing_state(robot, contacts=np.zeros(4)))
    assert none.status == "no_contact" and np.isnan(none.margin)
    # Pushing down with 20 body weights exceeds every torque limit: no equilibrium anywhere.
    crush = analytic_margin(robot, standing_state(robot, ext_force=np.array([0.0, 0.0, -20 * 9.81 * robot.total_mass])))
    assert crush.status == "infeasible" and np.isnan(crush.margin)


def test_bad_lambda(robot) -> None:
    lam = standing_state(robot)
    bad = lam.copy()
    bad[LAMBDA_SLICES["mu"]] = np.nan
    with pytest.raises(ValueError, match="mu"):
        analytic_margin(robot, bad)
    bad = lam.copy()
    bad[LAMBDA_SLICES["contacts"].start] = 0.5
    with pytest.raises(ValueError, match="contacts"):
        analytic_margin(robot, bad)
    bad = lam.copy()
    bad[LAMBDA_SLICES["mu"]] = -0.1
    with pytest.raises(ValueError, match="mu must be positive"):
        analytic_margin(robot, bad)
    with pytest.raises(ValueError, match="shape"):
        analytic_margin(robot, np.stack([lam, lam]))


def test_batch_over_processes_matches_sequential() -> None:
    robot = load_robot("anymal_b")
    lams = sample_states(robot, 24, seed=5)
    seq = analytic_margin_batch("anymal_b", lams, workers=1)
    par = analytic_margin_batch("anymal_b", lams, workers=2, chunk_size=5)
    np.testing.assert_array_equal(seq.status, par.status)
    np.testing.assert_allclose(seq.margin, par.margin, equal_nan=True)
    assert sum(seq.counts().values()) == 24
    # The per-state path is analytic_margin on each state; the batched one (default) agrees with it to
    # within focus_tol (tests/stability/test_labelling.py).
    per_state = analytic_margin_batch("anymal_b", lams[:3], AnalyticSettings(labelling="per_state"), workers=1)
    for i in range(3):
        single = analytic_margin(robot, lams[i])
        assert STATUSES[seq.status[i]] == STATUSES[per_state.status[i]] == single.status
        np.testing.assert_array_equal(per_state.margin[i], single.margin)
        np.testing.assert_allclose(seq.margin[i], single.margin, atol=AnalyticSettings().focus_tol, equal_nan=True)


def test_settings_change_the_friction_model() -> None:
    robot = load_robot("anymal_c")
    lam = standing_state(robot, mu=np.array(0.3), com_acc=np.array([2.0, 1.0, 0.0]))
    cone = analytic_margin(robot, lam, AnalyticSettings(friction="cone"))
    pyramid = analytic_margin(robot, lam, AnalyticSettings(friction=("pyramid", 4)))
    assert cone.status == pyramid.status == "ok"
    # The inscribed pyramid is smaller than the cone, so is its region; the margin cannot grow.
    assert pyramid.margin <= cone.margin + 1e-4
    st = from_lambda(lam)
    assert st.mu == pytest.approx(0.3)


def test_settings_round_trip_through_their_recorded_form() -> None:
    for settings in (AnalyticSettings(), AnalyticSettings(friction=("pyramid", 8), focus_tol=1e-5, max_lps=30)):
        assert AnalyticSettings.from_dict(settings.as_dict()) == settings
    with pytest.raises(ValueError, match=r"unknown analytic settings \['focus'\]"):
        AnalyticSettings.from_dict({"focus": 1e-3})


def test_focused_margin_matches_a_fully_refined_region() -> None:
    """The focused projection's bracket holds: |m_focus - m_reference| <= focus_tol on Table I states.

    Up to the conic solver's optimality noise: a support point can fall short of the optimum along
    its direction by a few 1e-5 m (measured up to 3.4e-5 m), which shifts both bounds that much.
    """
    noise = 1e-4
    robot = load_robot("anymal_c")
    lams = sample_states(robot, 60, seed=21)
    reference = AnalyticSettings(focus_tol=None, tol=1e-7, max_lps=300)
    focused = AnalyticSettings()
    n_ok = 0
    for lam in lams:
        ref = analytic_margin(robot, lam, reference)
        res = analytic_margin(robot, lam, focused)
        assert res.status == ref.status
        if ref.status != "ok":
            continue
        n_ok += 1
        lo, hi = res.region.margin_bounds
        assert lo <= ref.margin + noise and ref.margin <= hi + noise
        assert abs(res.margin - ref.margin) <= focused.focus_tol + noise
        assert res.n_lps <= ref.n_lps
    assert n_ok >= 20


def test_margin_is_invariant_under_the_sagittal_mirror(robot) -> None:
    """Left-right symmetry, checked two independent ways: the margin of the mirrored state (legs swapped,
    y flipped) through the whole pipeline (IK, Pinocchio dynamics, LPs) equals the margin of the state.
    ANYmal B's published base CoM is 1.4 mm off the sagittal plane (C's 0.2 mm), so B is symmetric only
    to about a millimetre; the default 0.5 mm focus bracket adds up to 1 mm."""
    from margin_rl.stability.analytic.lambda_state import mirror_lambda

    lams = sample_states(robot, 40, seed=99)
    direct = analytic_margin_batch(robot.name, lams, workers=1)
    mirrored = analytic_margin_batch(robot.name, mirror_lambda(lams), workers=1)
    assert np.mean(direct.status == mirrored.status) >= 0.95
    ok = (direct.status == 0) & (mirrored.status == 0)
    assert ok.sum() >= 15
    difference = np.abs(direct.margin[ok] - mirrored.margin[ok])
    assert np.median(difference) < 2e-4
    assert np.percentile(difference, 90) < 1.5e-3
