r"""The small linear programs of the Feasible Wrench Polytope criterion (seed 004), solved with Clarabel.

Robot-agnostic, arrays in and out; used by :mod:`~margin_rl.stability.fwp.polytope` (the fallback of
the Minkowski pruning) and :mod:`~margin_rl.stability.fwp.feasibility` (the feasibility factor and the membership
tests). Variables are wrenches :math:`w = (f, \tau/\ell)` in the homogenised units of their caller
(moments divided by a length :math:`\ell` [m], frame H of :mod:`~margin_rl.stability.geometry.region`):

* :func:`depth_lp`: depth of the normal cone of a candidate Minkowski sum (eq. 13), one candidate;
* :func:`gauge_lp` and :func:`polar_support_lp`: the gauge form of eq. (24) on blocks of centred
  vertices, and its LP dual, the support function of the polar (:math:`s = 1 - \gamma`);
* :func:`residual_lp`: the :math:`\ell_1` residual of a wrench to a cone or to a Minkowski sum of
  convex hulls (CWC and AWP membership, eq. 4-8);
* :func:`_solve_lp`: the shared fast-then-robust Clarabel call.
"""

from __future__ import annotations

import math
import time
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from margin_rl.stability.geometry.contact import INFEASIBLE, solver_settings

FloatArray = NDArray[np.float64]

# Tighter than the region's programs: s is read off directly rather than as a polygon vertex.
_SETTINGS_FAST = solver_settings(robust=False, tol=1e-9, max_iter=200)
_SETTINGS_ROBUST = solver_settings(robust=True, tol=1e-9, max_iter=200)
# Interior-point infeasibility certificates are reliable: not retried (INFEASIBLE).


def depth_lp(gens: FloatArray) -> float:
    """Fallback for one candidate: ``max t`` s.t. ``g^T c + t <= 0``, ``|c|_inf <= 1``, ``t <= 1`` (Clarabel).

    Same value as the batched phase-1 simplex of :mod:`~margin_rl.stability.fwp.polytope` by LP
    duality (without the perturbation).
    """
    g = gens[np.any(gens != 0.0, axis=1)]
    k = g.shape[0]
    a = np.zeros((k + 13, 7))
    a[:k, :6] = g
    a[:k, 6] = 1.0
    a[k : k + 6, :6] = np.eye(6)
    a[k + 6 : k + 12, :6] = -np.eye(6)
    a[k + 12, 6] = 1.0
    b = np.concatenate([np.zeros(k), np.ones(13)])
    q = np.zeros(7)
    q[6] = -1.0
    solver = clarabel.DefaultSolver(
        sp.csc_matrix((7, 7)), q, sp.csc_matrix(a), b, [clarabel.NonnegativeConeT(k + 13)], _SETTINGS_ROBUST
    )
    sol = solver.solve()
    return float(sol.x[6]) if sol.status == clarabel.SolverStatus.Solved else math.nan


def _solve_lp(q: FloatArray, a: sp.csc_matrix, b: FloatArray, n_eq: int) -> tuple[Any, FloatArray]:
    """Solve ``min q^T x`` s.t. the first ``n_eq`` rows of ``a x + s = b`` are equalities, the rest
    ``s >= 0``; retried with iterative refinement if the fast solve does not reach Solved."""
    n = a.shape[1]
    cones = [clarabel.ZeroConeT(n_eq), clarabel.NonnegativeConeT(a.shape[0] - n_eq)]
    status: Any = None
    for settings in (_SETTINGS_FAST, _SETTINGS_ROBUST):
        sol = clarabel.DefaultSolver(sp.csc_matrix((n, n)), q, a, b, cones, settings).solve()
        status = sol.status
        if status == clarabel.SolverStatus.Solved:
            return status, np.asarray(sol.x)
        if status in INFEASIBLE:
            break
    return status, np.full(n, np.nan)


def gauge_lp(blocks: list[FloatArray], rhs: FloatArray, basis: FloatArray) -> tuple[float, str, float]:
    r"""``min t`` s.t. ``sum_i sum_k mu_ik g_ik = rhs`` (in span(basis)), ``sum_k mu_ik = t`` for every
    block, ``mu >= 0``. One block of n_v columns is eq. (24) with t = 1 - s. Returns (t, status, time)."""
    t0 = time.perf_counter()
    sizes = [blk.shape[0] for blk in blocks]
    n_mu = sum(sizes)
    r = basis.shape[1]
    g = np.concatenate(blocks) @ basis  # (n_mu, r)
    scale = max(1e-12, float(np.max(np.abs(g), initial=0.0)))
    n_blocks = len(blocks)
    # Rows: r projected wrench equalities, one weight-sum row per block, then mu >= 0.
    top = np.zeros((r + n_blocks, n_mu + 1))
    top[:r, :n_mu] = g.T / scale
    col = 0
    for i, size in enumerate(sizes):
        top[r + i, col : col + size] = 1.0
        top[r + i, n_mu] = -1.0
        col += size
    a = sp.vstack([sp.csc_matrix(top), sp.hstack([-sp.identity(n_mu, format="csc"), sp.csc_matrix((n_mu, 1))])])
    b = np.concatenate([basis.T @ rhs / scale, np.zeros(n_blocks + n_mu)])
    q = np.zeros(n_mu + 1)
    q[n_mu] = 1.0
    status, x = _solve_lp(q, a.tocsc(), b, r + n_blocks)
    if status in INFEASIBLE:
        return math.inf, "wrench outside the cone of the centred vertices (is the centre interior?)", 0.0
    if status != clarabel.SolverStatus.Solved:
        return math.nan, f"solver status {status}", time.perf_counter() - t0
    return float(x[n_mu]), "", time.perf_counter() - t0


def polar_support_lp(vertices: FloatArray, rhs: FloatArray, basis: FloatArray) -> tuple[float, str]:
    """Dual of eq. (24): ``max rhs^T u`` s.t. ``v_j^T u <= 1`` in span(basis); returns (1 - max, message).

    An unbounded program (Clarabel: dual infeasible) means the primal is infeasible: ``s = -inf``.
    """
    g = vertices @ basis
    scale = max(1e-12, float(np.max(np.abs(g), initial=0.0)))  # the value is invariant to this scale
    a = sp.csc_matrix(g / scale)
    q = -(basis.T @ rhs) / scale
    status: Any = None
    for settings in (_SETTINGS_FAST, _SETTINGS_ROBUST):
        n = basis.shape[1]
        cones = [clarabel.NonnegativeConeT(g.shape[0])]
        sol = clarabel.DefaultSolver(sp.csc_matrix((n, n)), q, a, np.ones(g.shape[0]), cones, settings).solve()
        status = sol.status
        if status == clarabel.SolverStatus.Solved:
            return 1.0 + float(q @ np.asarray(sol.x)), ""
        if status in (clarabel.SolverStatus.DualInfeasible, clarabel.SolverStatus.AlmostDualInfeasible):
            return -math.inf, "wrench outside the cone of the centred vertices (is the centre interior?)"
    return math.nan, f"solver status {status}"


def residual_lp(blocks: list[FloatArray], w: FloatArray, convex: bool) -> float:
    """Smallest ``||w - sum alpha g||_1`` with alpha >= 0 (and sum_k alpha_ik = 1 per block if convex).

    NaN if the solver fails, which :func:`~margin_rl.stability.fwp.feasibility.wrench_violations` reads as "not a
    member".
    """
    sizes = [blk.shape[0] for blk in blocks]
    n_a = sum(sizes)
    n_b = len(blocks) if convex else 0
    g = np.concatenate(blocks)
    scale = max(1.0, float(np.max(np.abs(g), initial=0.0)), float(np.max(np.abs(w))))
    n_var = n_a + 12  # alpha, u, v with g^T alpha + u - v = w
    top = np.zeros((6 + n_b, n_var))
    top[:6, :n_a] = g.T / scale
    top[:6, n_a : n_a + 6] = np.eye(6)
    top[:6, n_a + 6 :] = -np.eye(6)
    col = 0
    if convex:
        for i, size in enumerate(sizes):
            top[6 + i, col : col + size] = 1.0
            col += size
    a = sp.vstack([sp.csc_matrix(top), -sp.identity(n_var, format="csc")]).tocsc()
    b = np.concatenate([w / scale, np.ones(n_b), np.zeros(n_var)])
    q = np.concatenate([np.zeros(n_a), np.ones(12)])
    status, x = _solve_lp(q, a, b, 6 + n_b)
    if status in INFEASIBLE:  # only possible for an empty block (no vertex to take a convex weight)
        return math.inf
    if status != clarabel.SolverStatus.Solved:
        return math.nan
    return float(q @ x) * scale  # back to the (homogenised) wrench units of w
