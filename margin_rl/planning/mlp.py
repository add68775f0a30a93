"""The learned stability margin as a CasADi expression, built from the bundled weights.

    m_l(lam) = s_y * (W_4 softsign(W_3 softsign(W_2 softsign(W_1 (lam - mu_x) / s_x + b_1) + b_2) + b_3) + b_4) + mu_y

with softsign(z) = z / (1 + |z|) (seed 000 §IV-A), exactly the network of
:class:`margin_rl.stability.LearnedMargin` (same weights and normalisation, read from its ``params``).
The function is written with MX matrix products on constant weight matrices, so a batch of nodes is one
dense product per layer and its derivatives are exact reverse-mode AD (backpropagation). softsign is
C1 (its second derivative jumps at 0), which is enough for IPOPT with a quasi-Newton Hessian.

Why a custom Jacobian: each column's margin depends on that column's lambda only, so the Jacobian of
the batch is block diagonal and *one* reverse sweep with a seed of ones returns every column's
gradient (the gradient of the sum). CasADi's generic Jacobian of the planner's constraints does not
see this through the shared foothold variables and spent ~40 directional sweeps of the network per
evaluation (46 ms of a 60 ms IPOPT iteration, measured); the block-diagonal Jacobian is supplied here.
"""

from __future__ import annotations

import numpy as np

from margin_rl.stability import LAMBDA_DIM, LearnedMargin


def planning_weights(robot_name: str) -> str:
    """The bundled learned-margin weights the planner uses for ``robot_name``: the Table I network.

    The planner's trajectories are slow, statically stable walks: states of the kind Table I samples. The
    default network (learned margin v2) is trained for the states RL policies visit and is about half as
    accurate on Table I states (8.1-8.5 vs 3.7-4.1 cm RMSE, the two cards' ``paper_protocol``), so the
    planner keeps the network it was developed and measured with.
    """
    return f"{robot_name}_table_i"


def margin_function(model: LearnedMargin, n_columns: int = 1):  # -> casadi.Function
    """``m(lam) -> margin``: lam (47, n_columns) -> (1, n_columns) [m], one column per state.

    Raises:
        ValueError: n_columns < 1.
    """
    import casadi as ca

    if int(n_columns) != n_columns or n_columns < 1:
        raise ValueError(f"n_columns must be a positive integer, got {n_columns!r}")
    p = model.params
    lam = ca.MX.sym("lam", LAMBDA_DIM, int(n_columns))
    # Fold the input normalisation into the first layer and the output scaling into the last, as
    # LearnedMargin does, so the expression is a plain chain of affine maps and softsigns.
    W = [np.asarray(w, dtype=float) for w in p.weights]
    b = [np.asarray(x, dtype=float) for x in p.biases]
    W0 = W[0] / p.input_std[None, :]
    b0 = b[0] - W0 @ p.input_mean
    W_last = W[-1] * p.output_std
    b_last = b[-1] * p.output_std + p.output_mean
    layers = [(W0, b0), *zip(W[1:-1], b[1:-1], strict=True)]
    h = lam
    for Wk, bk in layers:
        z = ca.mtimes(ca.DM(Wk), h) + ca.repmat(ca.DM(bk), 1, int(n_columns))
        h = z / (1 + ca.fabs(z))
    out = ca.mtimes(ca.DM(W_last), h) + ca.repmat(ca.DM(b_last), 1, int(n_columns))
    plain = ca.Function("learned_margin_plain", [lam], [out], ["lam"], ["margin"])
    # Block-diagonal Jacobian (n, 47 n) of vec(margin) w.r.t. vec(lam), from one reverse sweep.
    lam_j, out_j = ca.MX.sym("lam", LAMBDA_DIM, int(n_columns)), ca.MX.sym("margin", 1, int(n_columns))
    grads = ca.gradient(ca.sum2(plain(lam_j)), lam_j)  # (47, n): column k is dm_k / dlam_k
    jacobian = ca.Function(
        "jac_learned_margin", [lam_j, out_j], [ca.diagcat(*[grads[:, k].T for k in range(int(n_columns))])]
    )
    return ca.Function(
        "learned_margin", [lam], [plain(lam)], ["lam"], ["margin"], {"custom_jacobian": jacobian, "jac_penalty": 0}
    )
