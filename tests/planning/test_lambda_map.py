"""lambda(trajectory): the CasADi expression vs an independent numpy route, derivatives vs finite differences."""

from __future__ import annotations

import casadi as ca
import numpy as np

from margin_rl.planning import plan_lambda
from margin_rl.planning.checks import rotation_kinematics
from margin_rl.stability import LAMBDA_SLICES
from tests.planning.conftest import initial_footholds, random_decision


def _plan(problem, z):
    par = problem.parameters(initial_footholds(problem), np.zeros(2))
    return problem._plan(z, par, "test", 0, 0.0), par


def test_casadi_lambda_matches_the_numpy_route(walk_problem, robot_c):
    plan, _ = _plan(walk_problem, random_decision(walk_problem))
    lams = walk_problem.plan_lambdas(plan)
    for k, t in enumerate(walk_problem.schedule.node_times):
        reference = plan_lambda(plan, walk_problem.height_map, robot_c, walk_problem.config.mu, float(t))
        np.testing.assert_allclose(lams[k], reference, atol=1e-9, err_msg=f"node {k}")


def test_lambda_jacobian_matches_finite_differences(walk_problem):
    z0 = random_decision(walk_problem, seed=2)
    par = walk_problem.parameters(initial_footholds(walk_problem), np.zeros(2))
    z = ca.MX.sym("z", walk_problem.n_decision)
    lam = ca.vec(walk_problem.lambda_function(z, par))
    J = np.array(ca.Function("J", [z], [ca.jacobian(lam, z)])(z0))
    eps = 1e-6
    rng = np.random.default_rng(0)
    for i in rng.choice(walk_problem.n_decision, 25, replace=False):
        dz = np.zeros_like(z0)
        dz[i] = eps
        plus = np.array(walk_problem.lambda_function(z0 + dz, par)).ravel(order="F")
        minus = np.array(walk_problem.lambda_function(z0 - dz, par)).ravel(order="F")
        np.testing.assert_allclose(J[:, i], (plus - minus) / (2 * eps), atol=1e-6, err_msg=f"variable {i}")


def test_eq10_margin_gradient_wrt_com_is_minus_the_sum_over_feet(walk_problem, margin_c):
    # Seed 000 eq. (10): at yaw 0 a CoM translation moves every foot of lambda by the opposite amount.
    # The node's CoM position also enters its acceleration through the cubic segment,
    # d c_ddot_k / d c_k = -6 / dT^2 (both ends of a Hermite segment), which adds the c_ddot channel.
    z0 = random_decision(walk_problem, seed=3)
    z0[5 : walk_problem.n_base : 12] = 0.0  # yaw of every node
    z0[11 : walk_problem.n_base : 12] = 0.0  # yaw rate
    par = walk_problem.parameters(initial_footholds(walk_problem), np.zeros(2))
    from margin_rl.planning.mlp import margin_function

    z = ca.MX.sym("z", walk_problem.n_decision)
    n = walk_problem.schedule.n_nodes
    margins = margin_function(margin_c, n)(walk_problem.lambda_function(z, par))
    J = np.array(ca.Function("J", [z], [ca.jacobian(margins, z)])(z0))
    lams = np.array(walk_problem.lambda_function(z0, par)).T
    feet, acc = LAMBDA_SLICES["feet"], LAMBDA_SLICES["com_acc"]
    dt = walk_problem.config.node_dt
    for k in (0, 4, 9, n - 1):
        grad = margin_c.grad(lams[k])
        eq10 = -grad[feet].reshape(4, 3).sum(axis=0)
        np.testing.assert_allclose(J[k, 12 * k : 12 * k + 3], eq10 - 6.0 / dt**2 * grad[acc], atol=1e-9)


def test_rotation_kinematics_match_the_euler_rate_formula():
    # Hand-checkable case: pure yaw motion, omega = (0, 0, psi_dot), omega_dot = (0, 0, psi_ddot).
    R, omega, omega_dot = rotation_kinematics(
        np.array([0.0, 0.0, 0.4]), np.array([0.0, 0.0, 0.7]), np.array([0, 0, 0.2])
    )
    np.testing.assert_allclose(omega, [0.0, 0.0, 0.7], atol=1e-12)
    np.testing.assert_allclose(omega_dot, [0.0, 0.0, 0.2], atol=1e-12)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
