"""The learned stability margin as a CasADi expression, built from the bundled weights.

    m_l(lam) = W_4 softsign(W_3 softsign(W_2 softsign(W_1 lam + b_1) + b_2) + b_3) + b_4

with softsign(z) = z / (1 + |z|) (seed 000 §IV-A) and the input normalisation and output scaling folded into
W_1, b_1 and W_4, b_4: the CasADi form of :attr:`margin_rl.stability.LearnedMargin.network`
(:meth:`margin_rl.network.DenseNetwork.casadi`), the same folded weights as the numpy value and gradient.
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
        ValueError: n_columns < 1, or weights of the physics architecture (its features have no CasADi form).
    """
    import casadi as ca

    if int(n_columns) != n_columns or n_columns < 1:
        raise ValueError(f"n_columns must be a positive integer, got {n_columns!r}")
    if model.architecture != "paper":
        raise ValueError(f"the planner's CasADi margin takes paper weights, got {model.architecture!r}")
    lam = ca.MX.sym("lam", LAMBDA_DIM, int(n_columns))
    out = model.network.casadi(lam)
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
