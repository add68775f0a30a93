"""The CasADi network vs LearnedMargin (numpy): values and backpropagated gradients to 1e-12, both robots; the
Jacobian against central differences."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from margin_rl.planning.mlp import margin_function
from margin_rl.robot import load_robot
from margin_rl.stability import LearnedMargin, sample_states


@pytest.mark.parametrize("robot", ["anymal_c", "anymal_b"])
def test_casadi_network_matches_learned_margin(robot):
    model = LearnedMargin.load(robot)
    lams = sample_states(load_robot(robot), 5, seed=4)
    f = margin_function(model, 5)
    np.testing.assert_allclose(np.array(f(lams.T)).ravel(), [model(x) for x in lams], rtol=0, atol=1e-12)
    lam = ca.MX.sym("lam", 47, 5)
    jacobian = ca.Function("jacobian", [lam], [ca.jacobian(f(lam), lam)])  # uses the custom block-diagonal Jacobian
    J = np.array(jacobian(lams.T))
    for k in range(5):
        np.testing.assert_allclose(J[k, 47 * k : 47 * k + 47], model.grad(lams[k]), rtol=0, atol=1e-12)
        assert np.all(np.delete(J[k], np.s_[47 * k : 47 * k + 47]) == 0.0)
    # the Jacobian is the derivative of the CasADi function itself (central differences)
    h = 1e-6
    for j in range(0, 47, 4):
        step = np.zeros((47, 5))
        step[j] = h
        fd = (np.array(f(lams.T + step)) - np.array(f(lams.T - step))).ravel() / (2 * h)
        np.testing.assert_allclose(fd, [J[k, 47 * k + j] for k in range(5)], rtol=0, atol=1e-7)


def test_bad_column_count_and_physics_weights_are_refused(margin_c):
    with pytest.raises(ValueError, match="n_columns"):
        margin_function(margin_c, 0)
    from tests.stability.learned.test_model import random_physics_weights

    with pytest.raises(ValueError, match="paper weights"):
        margin_function(LearnedMargin(random_physics_weights()), 1)


def test_second_derivatives_of_the_casadi_margin_are_the_networks_block_hessians(margin_c):
    """The custom Jacobian of the custom Jacobian (numpy's block Hessians through a callback) against CasADi's own
    second derivatives of the plain network (two independent computations of the same 47 x 47 blocks)."""
    n = 3
    lams = sample_states(load_robot("anymal_c"), n, seed=5).T  # (47, n)
    lam = ca.MX.sym("lam", 47, n)
    custom = margin_function(margin_c, n)
    first = ca.jacobian(custom(lam), lam)  # through the block-diagonal custom Jacobian
    second = ca.Function("second", [lam], [ca.jacobian(ca.vec(first), lam)])(lams)  # through the callback
    reference = ca.jacobian(ca.vec(ca.jacobian(margin_c.network.casadi(lam), lam)), lam)
    expected = ca.Function("reference", [lam], [reference])(lams)
    np.testing.assert_allclose(np.array(ca.densify(second)), np.array(ca.densify(expected)), rtol=1e-9, atol=1e-9)
    blocks = margin_c.network.hessian(lams.T)
    dense = np.array(ca.densify(second)).reshape(n, 47 * n, 47 * n, order="F")  # rows: vec(J), J is (n, 47 n)
    for k in range(n):
        block = dense[k, 47 * k : 47 * k + 47, 47 * k : 47 * k + 47]
        np.testing.assert_allclose(block, blocks[k], rtol=1e-9, atol=1e-9)


def test_exact_hessian_planner_converges_in_few_iterations(model_c, margin_c):
    """IPOPT with the exact Hessian solves the walk problem in a handful of iterations (quasi-Newton: ~80) to the
    same kind of plan: converged, every node above the margin bound."""
    from margin_rl.planning import WALK, BaseState, PlannerConfig, TrajectoryProblem, flat_map

    h = model_c.nominal_com_height
    initial = BaseState([0.0, 0.0, h], np.zeros(3), np.zeros(3), np.zeros(3))
    target = BaseState([0.45, 0.0, h], np.zeros(3), [WALK.speed, 0.0, 0.0], np.zeros(3))
    xy = model_c.nominal_feet_com[:, :2]
    footholds = np.column_stack([xy, np.zeros(4)])
    problem = TrajectoryProblem(
        model_c, flat_map((-1.0, 2.5), (-1.0, 1.0)), WALK, 0.0, PlannerConfig(hessian="exact"), margin_c
    )
    plan = problem.solve(initial, target, footholds)
    assert plan.status == "Solve_Succeeded" and plan.iterations <= 30
    assert np.min(margin_c(problem.plan_lambdas(plan))) >= problem.margin_bound - 1e-3
    with pytest.raises(ValueError, match="hessian"):
        PlannerConfig(hessian="newton")
    assert PlannerConfig().hessian == "exact"
    with pytest.raises(ValueError, match="first derivatives only"):
        PlannerConfig(margin="analytic_fd")
    assert PlannerConfig(margin="analytic_fd", hessian="quasi-newton").hessian == "quasi-newton"
