"""The Hessian of the planner's Lagrangian with the learned-margin constraints, assembled by the chain rule.

With the margin rows m_k(lambda_k(z)) >= bound (one per node k of the horizon) and their multipliers mu_k, their
part of the Hessian of the Lagrangian in the decision vector z is

    sum_k mu_k d^2 m_k / dz^2 = sum_k mu_k J_k^T H_k J_k  +  d^2/dz^2 [ sum_k sum_i w_ki lambda_ki(z) ],

    J_k = d lambda_k / dz (47 x n_z, sparse), H_k = the network's 47 x 47 Hessian at lambda_k,
    w_ki = mu_k dm/dlambda_i at lambda_k, held constant in the second term (the curvature of the lambda map).

CasADi's own Hessian of the same Lagrangian (forward-over-reverse through the network's callbacks) multiplies the
block Hessians with every colour direction of z inside its expression graph: most of an IPOPT iteration (65 ms per
iteration against 12 ms without the margin rows; BENCHMARKS "Trajectory optimisation speed").
Here the first term is a few small dense products per node in numpy (each node's lambda depends on a few dozen
decision variables: its own and the next base node, the footholds in use), and the second term and the rest of
the Lagrangian (cost and every other constraint) stay CasADi's symbolic second derivatives. The result is the same
matrix (checked against CasADi's to 1e-9 in the tests); IPOPT takes it through ``nlpsol``'s ``hess_lag`` option.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from margin_rl.network import DenseNetwork
from margin_rl.stability import LAMBDA_DIM


def margin_lagrangian_hessian(
    z: Any, par: Any, cost: Any, other_constraints: Any, lambdas: Any, network: DenseNetwork
):  # -> casadi.Function
    """IPOPT's ``hess_lag``: (x, p, lam_f, lam_g) -> upper triangle of the Lagrangian's Hessian in x.

    The problem's constraints are the N margin rows m(lambda_k) >= bound first (one per column of ``lambdas``, in
    column order), then ``other_constraints``.

    Args:
        z, par: the problem's decision and parameter symbols (MX).
        cost: the problem's cost (scalar MX in z and par).
        other_constraints: every constraint row after the margin rows (column MX in z and par). Given apart
            from the margin rows: the second derivatives of a graph that holds the network's callbacks cost
            several times more, even with zero multipliers on those rows.
        lambdas: lambda at the nodes, (47, N) MX in z and par (the expression the margin rows were built on).
        network: the learned margin's network (folded weights, one output).
    """
    import casadi as ca

    n_nodes = int(lambdas.shape[1])
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", n_nodes + other_constraints.shape[0])
    mu = lam_g[:n_nodes]
    jacobian = ca.jacobian(ca.vec(lambdas), z)  # (47 N, n_z), row 47 k + i: d lambda_ki / dz
    chain = _chain_rule_callback(network, jacobian.sparsity(), n_nodes)
    outer, weights = chain(lambdas, mu, jacobian)
    # Everything but J^T H J in one symbolic Hessian: the cost, the other rows, and the lambda map's curvature
    # weighted by w (constant there: a symbol in this function, the callback's output below).
    w, lam_rest = ca.MX.sym("w", LAMBDA_DIM, n_nodes), ca.MX.sym("lam_rest", other_constraints.shape[0])
    symbolic = lam_f * cost + ca.dot(lam_rest, other_constraints) + ca.dot(ca.vec(w), ca.vec(lambdas))
    second_derivatives = ca.Function(
        "lagrangian_without_network_curvature", [z, par, lam_f, lam_rest, w], [ca.triu(ca.hessian(symbolic, z)[0])]
    )
    hessian = second_derivatives(z, par, lam_f, lam_g[n_nodes:], weights) + outer
    function = ca.Function(
        "nlp_hess_l", [z, par, lam_f, lam_g], [hessian], ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]
    )
    function.keepalive = chain  # CasADi calls a Python callback only while its Python object lives
    return function


def _chain_rule_callback(network: DenseNetwork, jacobian_sparsity: Any, n_nodes: int) -> Any:
    """Callback (lambda (47, N), mu (N,), J (47 N, n_z)) -> (triu sum_k mu_k J_k^T H_k J_k, w = mu_k dm/dlambda_k).

    Each node's lambda depends on a fixed set of decision variables (the columns of J's rows 47 k .. 47 k + 46);
    the products are dense on those columns only, and the output's sparsity is the union of the nodes' squares,
    upper triangle.
    """
    import casadi as ca

    d = LAMBDA_DIM
    n_z = jacobian_sparsity.size2()
    pattern = np.zeros((d * n_nodes, n_z), dtype=bool)
    rows, cols = jacobian_sparsity.get_triplet()
    pattern[rows, cols] = True
    node_columns = [np.flatnonzero(pattern[d * k : d * (k + 1)].any(axis=0)) for k in range(n_nodes)]
    union = np.zeros((n_z, n_z), dtype=bool)
    for columns in node_columns:
        union[np.ix_(columns, columns)] = True
    union_rows, union_cols = np.nonzero(np.triu(union))
    out_sparsity = ca.Sparsity.triplet(n_z, n_z, union_rows.tolist(), union_cols.tolist())
    ccs_rows, ccs_cols = out_sparsity.get_triplet()  # the non-zeros in CasADi's (column-major) order
    ccs_rows, ccs_cols = np.asarray(ccs_rows), np.asarray(ccs_cols)
    jac_rows, jac_cols = np.asarray(rows), np.asarray(cols)

    class ChainRule(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.construct("margin_chain_rule", {"enable_fd": False})

        def get_n_in(self) -> int:
            return 3

        def get_n_out(self) -> int:
            return 2

        def get_sparsity_in(self, i: int) -> Any:
            return [ca.Sparsity.dense(d, n_nodes), ca.Sparsity.dense(n_nodes, 1), jacobian_sparsity][i]

        def get_sparsity_out(self, i: int) -> Any:
            return [out_sparsity, ca.Sparsity.dense(d, n_nodes)][i]

        def eval(self, arg: list[Any]) -> list[Any]:
            lams = np.asarray(arg[0]).T  # (N, 47)
            mu = np.asarray(arg[1]).ravel()
            J = np.zeros((d * n_nodes, n_z))
            J[jac_rows, jac_cols] = np.asarray(arg[2].nonzeros())
            _, gradients = network.value_and_grad(lams)  # (N, 1, 47)
            hessians = network.hessian(lams)  # (N, 47, 47)
            total = np.zeros((n_z, n_z))
            for k, columns in enumerate(node_columns):
                if mu[k] == 0.0:
                    continue
                block = J[d * k : d * (k + 1)][:, columns]  # (47, c_k)
                total[np.ix_(columns, columns)] += mu[k] * (block.T @ hessians[k] @ block)
            weights = (gradients[:, 0, :] * mu[:, None]).T  # (47, N)
            return [ca.DM(out_sparsity, total[ccs_rows, ccs_cols]), ca.DM(weights)]

    return ChainRule()
