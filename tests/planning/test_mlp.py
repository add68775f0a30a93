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
