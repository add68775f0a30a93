"""Eq. (9) solved: constraints hold, a hand-solvable case, the analytic+FD variant, bad configurations."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.planning import WALK, BaseState, PlannerConfig, TrajectoryProblem, flat_map, range_of_motion_reachable
from margin_rl.planning.analytic_fd import analytic_margin_function, varying_entries
from margin_rl.stability import analytic_margin
from tests.planning.conftest import initial_footholds


def _standing(model, x=0.0, speed=0.0):
    return BaseState([x, 0.0, model.nominal_com_height], np.zeros(3), [speed, 0.0, 0.0], np.zeros(3))


def test_walk_plan_satisfies_its_constraints(model_c, margin_c):
    hm = flat_map((-1.0, 2.5), (-1.0, 1.0))
    problem = TrajectoryProblem(model_c, hm, WALK, 0.0, PlannerConfig(), margin_c)
    assert 180 <= problem.n_decision <= 260 and 350 <= problem.n_constraints <= 550  # the paper's ~200 / ~500
    plan = problem.solve(_standing(model_c), _standing(model_c, 0.45, WALK.speed), initial_footholds(problem))
    assert plan.success, plan.status
    assert np.all(plan.learned_margins >= plan.margin_bound - 1e-4)
    # Footholds on the terrain, initial state met exactly, progress towards the target.
    np.testing.assert_allclose(plan.footholds[:, 2], hm.height(plan.footholds[:, :2]), atol=1e-6)
    np.testing.assert_allclose(plan.base[0], _standing(model_c).as_vector(), atol=1e-9)
    assert plan.base[-1, 0] == pytest.approx(0.45, abs=1e-6)
    # The margin constraint is what shapes the walk: it is active at some three-foot node.
    three_feet = problem.schedule.contacts.sum(axis=1) == 3
    assert np.min(plan.learned_margins[three_feet] - plan.margin_bound) < 2e-3


def test_standing_still_without_margin_keeps_the_base_still(model_c):
    # Hand-solvable: flat ground, start = target at rest, no margin constraint. The smoothness cost is
    # zero for a motionless base and every constraint holds there, so the optimum is the base at rest. The
    # optimum is shallow in height (a 2.6 mm rise costs ~1e-6), hence the tight tolerance.
    hm = flat_map((-1.0, 1.5), (-1.0, 1.0))
    problem = TrajectoryProblem(model_c, hm, WALK, 0.0, PlannerConfig(margin="none", tol=1e-8, max_iter=400), None)
    still = _standing(model_c)
    plan = problem.solve(still, still, initial_footholds(problem))
    assert plan.success, plan.status
    np.testing.assert_allclose(plan.base[:, 0:3], np.tile(still.position, (problem.schedule.n_nodes, 1)), atol=2e-3)
    np.testing.assert_allclose(plan.base[:, 3:12], 0.0, atol=5e-3)  # IPOPT tolerance, not the model


def test_range_of_motion_boxes_are_reachable_for_both_robots(model_c):
    from margin_rl.planning import planning_robot
    from margin_rl.robot import load_robot

    assert range_of_motion_reachable(model_c).all()
    assert range_of_motion_reachable(planning_robot(load_robot("anymal_b"))).all()


def test_analytic_fd_margin_is_the_analytic_margin_with_forward_differences(robot_c, model_c):
    import casadi as ca

    from margin_rl.stability import StabilityState

    lam0 = StabilityState(
        gravity_axis=np.array([0.0, 0.0, 1.0]),
        com_vel=np.array([0.1, 0.0, 0.0]),
        com_acc=np.zeros(3),
        base_ang_acc=np.zeros(3),
        ext_force=np.zeros(3),
        ext_torque=np.zeros(3),
        feet=model_c.nominal_feet_com + np.array([0.0, 0.05, 0.0]),
        mu=np.array(0.7),
        contacts=np.array([1.0, 1.0, 1.0, 0.0]),
        normals=np.tile([0.0, 0.0, 1.0], (4, 1)),
    ).to_lambda()
    assert analytic_margin(robot_c, lam0).status == "ok"
    f = analytic_margin_function(robot_c, 2e-3)
    assert float(f(lam0)) == pytest.approx(analytic_margin(robot_c, lam0).margin, abs=1e-12)
    lam = ca.MX.sym("lam", 47)
    grad = np.array(ca.Function("g", [lam], [ca.jacobian(f(lam), lam)])(lam0)).ravel()
    i = varying_entries()[20]  # a foot coordinate
    shifted = lam0.copy()
    shifted[i] += 2e-3
    expected = (analytic_margin(robot_c, shifted).margin - analytic_margin(robot_c, lam0).margin) / 2e-3
    assert grad[i] == pytest.approx(expected, abs=1e-9)
    assert np.all(grad[np.setdiff1d(np.arange(47), varying_entries())] == 0.0)


def test_learned_margin_needs_a_network(model_c):
    with pytest.raises(ValueError, match="margin_model"):
        TrajectoryProblem(model_c, flat_map((0, 1), (0, 1)), WALK, 0.0, PlannerConfig(), None)


@settings(max_examples=25, deadline=None)
@given(
    field=st.sampled_from(["horizon", "node_dt", "mu", "max_com_acc_xy", "weight_slope", "margin_backoff", "max_iter"]),
    value=st.floats(-10.0, 0.0, exclude_max=True) | st.just(float("nan")),
)
def test_bad_configurations_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        PlannerConfig(**{field: value})


def test_bad_state_and_margin_kind_are_refused():
    with pytest.raises(ValueError, match="margin must be one of"):
        PlannerConfig(margin="network")
    with pytest.raises(ValueError, match="position"):
        BaseState([0.0, 0.0], np.zeros(3), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="target_tolerance"):
        PlannerConfig(target_tolerance=(0.1,) * 11)
