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

For IPOPT's exact Hessian (``PlannerConfig(hessian="exact")``) the custom Jacobian has a custom Jacobian of
its own: the block-diagonal second derivatives, one 47 x 47 Hessian per column, computed in numpy by
:meth:`margin_rl.network.DenseNetwork.hessian` (exact second-order backpropagation, ~5 ms for 16 columns)
through a CasADi callback. CasADi's generic second derivatives of the network cost ~250 ms per IPOPT
iteration (measured); the callback is only called when second derivatives are asked for.

The planner's IPOPT does not take its Hessian through this callback by default: it is given the Lagrangian's
Hessian assembled by the chain rule (:mod:`margin_rl.planning.lagrangian`), the same matrix at about 1.5x less time
per iteration. The callback serves any CasADi expression built on this function (``ca.hessian`` of it) and the
benchmark's contrast (``TrajectoryProblem(..., chain_rule_hessian=False)``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from margin_rl.network import DenseNetwork
from margin_rl.stability import LAMBDA_DIM, LearnedMargin


def planning_weights(robot_name: str) -> str:
    """The bundled learned-margin weights the planner uses for ``robot_name``: the robot's default network.

    One network per robot serves the environments, the planner and users. The default (learned margin v6) is
    trained on Table I and on the neighbourhoods of walking policies' states, flat and rough. Along the planner's
    courses the analytic margin stays above the bound at every sampled instant and every course reaches its goal
    (docs/planning.md, "Results"); the Table I network the planner used before stays loadable as
    ``<robot>_table_i`` (``--weights``).
    """
    return robot_name


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
    blocks = ca.diagcat(*[grads[:, k].T for k in range(int(n_columns))])
    second = _block_hessian_callback(model.network, int(n_columns), blocks.sparsity())
    jacobian = ca.Function(
        "jac_learned_margin", [lam_j, out_j], [blocks], {"custom_jacobian": second, "jac_penalty": 0}
    )
    function = ca.Function(
        "learned_margin", [lam], [plain(lam)], ["lam"], ["margin"], {"custom_jacobian": jacobian, "jac_penalty": 0}
    )
    # CasADi keeps a Python callback only while its Python object lives: it goes with the returned Function,
    # whose holder (the planner's problem) must keep that Function for as long as its solver.
    function.keepalive = second
    return function


def _block_hessian_callback(network: DenseNetwork, n_columns: int, jacobian_sparsity: Any) -> Any:
    """The Jacobian of the margin's block-diagonal Jacobian (n, 47 n): CasADi's ``jac_jac_learned_margin``.

    CasADi's layout: the Jacobian of the (n, 47 n) Jacobian, vectorised column-major, w.r.t. lambda (47, n)
    vectorised column-major, and w.r.t. the margin (zero). Its non-zeros: for column k, d J[k, 47 k + i] /
    d lam[j, k] = H_k[i, j], the network's Hessian at column k; everything else is zero.
    """
    import casadi as ca

    d = LAMBDA_DIM
    rows = [(d * k + i) * n_columns + k for k in range(n_columns) for j in range(d) for i in range(d)]
    cols = [d * k + j for k in range(n_columns) for j in range(d) for _ in range(d)]
    blocks = ca.Sparsity.triplet(n_columns * d * n_columns, d * n_columns, rows, cols)

    class BlockHessian(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.construct("jac_jac_learned_margin", {})

        def get_n_in(self) -> int:
            return 3  # lambda, the margin (nominal output), the Jacobian (nominal output)

        def get_n_out(self) -> int:
            return 2

        def get_sparsity_in(self, i: int) -> Any:
            return [ca.Sparsity.dense(d, n_columns), ca.Sparsity.dense(1, n_columns), jacobian_sparsity][i]

        def get_sparsity_out(self, i: int) -> Any:
            return [blocks, ca.Sparsity(n_columns * d * n_columns, n_columns)][i]

        def eval(self, arg: list[Any]) -> list[Any]:
            hessians = network.hessian(np.asarray(arg[0]).T)  # (n, 47, 47)
            # CCS order: column (k, j), then rows i ascending: H_k[i, j] with i fastest
            nonzeros = np.swapaxes(hessians, 1, 2).reshape(-1)
            return [ca.DM(blocks, nonzeros), ca.DM(ca.Sparsity(n_columns * d * n_columns, n_columns))]

    return BlockHessian()
