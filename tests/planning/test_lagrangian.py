"""The planner's Lagrangian Hessian assembled by the chain rule (margin_rl.planning.lagrangian) against CasADi's own
second derivatives of the same problem, against finite differences of the Lagrangian's gradient, and in IPOPT."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from margin_rl.planning import WALK, BaseState, PlannerConfig, TrajectoryProblem, flat_map
from tests.planning.conftest import initial_footholds, random_decision


def _symmetric(upper: ca.DM) -> np.ndarray:
    triu = np.array(ca.densify(upper))
    return triu + np.triu(triu, 1).T


@pytest.fixture(scope="module")
def both_hessians(model_c, bumpy_map, margin_c):
    """The walk problem on the bumpy map (the lambda map curves with the terrain), built both ways."""
    chain = TrajectoryProblem(model_c, bumpy_map, WALK, 0.6, PlannerConfig(), margin_c)
    casadi = TrajectoryProblem(model_c, bumpy_map, WALK, 0.6, PlannerConfig(), margin_c, chain_rule_hessian=False)
    return chain, casadi


@pytest.mark.parametrize("seed", [0, 1])
def test_chain_rule_hessian_is_casadis_hessian(both_hessians, seed):
    chain, casadi = both_hessians
    rng = np.random.default_rng(seed)
    z = random_decision(chain, seed=seed)
    par = chain.parameters(initial_footholds(chain), np.array([0.15, 0.0]))
    lam_f, lam_g = 0.7, rng.normal(size=chain.n_constraints)
    ours = _symmetric(chain.solver.get_function("nlp_hess_l")(z, par, lam_f, lam_g))
    reference = _symmetric(casadi.solver.get_function("nlp_hess_l")(z, par, lam_f, lam_g))
    scale = np.abs(reference).max()
    assert scale > 1.0
    np.testing.assert_allclose(ours, reference, rtol=0, atol=1e-9 * scale)
    # the margin rows carry curvature of their own: with their multipliers zeroed the matrix changes
    lam_g_without = lam_g.copy()
    lam_g_without[: chain.schedule.n_nodes] = 0.0
    without = _symmetric(chain.solver.get_function("nlp_hess_l")(z, par, lam_f, lam_g_without))
    assert np.abs(ours - without).max() > 1e-3 * scale


def test_chain_rule_hessian_is_the_derivative_of_the_lagrangians_gradient(both_hessians):
    """H v against central differences of grad L = lam_f grad f + J_g^T lam_g (CasADi's first derivatives), along
    directions of the base nodes (moving a foothold crosses the height map's interpolation cells, whose second
    derivatives are not those of the differences)."""
    chain, _ = both_hessians
    rng = np.random.default_rng(7)
    z = random_decision(chain, seed=3)
    par = chain.parameters(initial_footholds(chain), np.array([0.15, 0.0]))
    lam_f, lam_g = 0.7, rng.normal(size=chain.n_constraints)
    x = ca.MX.sym("x", chain.n_decision)
    lagrangian = lam_f * chain.cost_function(x, par) + ca.dot(ca.DM(lam_g), chain.constraint_function(x, par))
    gradient = ca.Function("grad_lagrangian", [x], [ca.gradient(lagrangian, x)])
    H = _symmetric(chain.solver.get_function("nlp_hess_l")(z, par, lam_f, lam_g))
    for _ in range(3):
        v = np.zeros(chain.n_decision)
        v[: chain.n_base] = rng.normal(size=chain.n_base)
        # Softsign's second derivative jumps where a hidden unit's input crosses zero: a difference whose step
        # straddles such a crossing averages the two sides. The smallest step that stays on one side agrees;
        # a wrong Hessian agrees at none.
        errors = []
        for step in (1e-5, 1e-6, 1e-7):
            fd = (np.array(gradient(z + step * v)) - np.array(gradient(z - step * v))).ravel() / (2 * step)
            errors.append(np.abs(H @ v - fd).max() / np.abs(fd).max())
        assert min(errors) < 1e-5, errors


def test_ipopt_takes_the_same_steps_with_either_hessian(model_c, margin_c):
    h = model_c.nominal_com_height
    initial = BaseState([0.0, 0.0, h], np.zeros(3), np.zeros(3), np.zeros(3))
    target = BaseState([0.45, 0.0, h], np.zeros(3), [WALK.speed, 0.0, 0.0], np.zeros(3))
    terrain = flat_map((-1.0, 2.5), (-1.0, 1.0))
    footholds = np.column_stack([model_c.nominal_feet_com[:, :2], np.zeros(4)])
    plans = [
        TrajectoryProblem(model_c, terrain, WALK, 0.0, PlannerConfig(), margin_c, chain_rule_hessian=chain).solve(
            initial, target, footholds
        )
        for chain in (True, False)
    ]
    assert plans[0].status == plans[1].status == "Solve_Succeeded"
    assert plans[0].iterations == plans[1].iterations
    np.testing.assert_allclose(plans[0].decision, plans[1].decision, rtol=0, atol=1e-6)
