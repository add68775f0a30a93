"""The CasADi network vs LearnedMargin (numpy): values and backpropagated gradients, both robots."""

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
    np.testing.assert_allclose(np.array(f(lams.T)).ravel(), [model(x) for x in lams], atol=1e-9)
    lam = ca.MX.sym("lam", 47, 5)
    jacobian = ca.Function("jacobian", [lam], [ca.jacobian(f(lam), lam)])  # uses the custom block-diagonal Jacobian
    J = np.array(jacobian(lams.T))
    for k in range(5):
        np.testing.assert_allclose(J[k, 47 * k : 47 * k + 47], model.grad(lams[k]), atol=1e-9)
        assert np.all(np.delete(J[k], np.s_[47 * k : 47 * k + 47]) == 0.0)


def test_bad_column_count_is_refused(margin_c):
    with pytest.raises(ValueError, match="n_columns"):
        margin_function(margin_c, 0)
