r"""The feasibility factor s of seed 004 (eq. 21-24) and which limit a wrench violates (eq. 17-20).

Robot-agnostic: polytopes and wrenches in, numbers out. :func:`feasibility_factor` solves eq. (24) on a
polytope's vertices, :func:`minkowski_feasibility_factor` on the summands of the Minkowski sum (the same s
without building the V-description), :func:`wrench_violations` names the violated limits of an
infeasible wrench, :func:`fwp_halfspaces` and :func:`halfspace_margin` give the H-description margin.
Frames, units and the derivation: :mod:`margin_rl.stability.fwp.feasibility`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.stability.fwp.polytope import FeasibleWrenchPolytope, span_basis
from margin_rl.stability.fwp.programs import gauge_lp, polar_support_lp, residual_lp
from margin_rl.stability.geometry.contact import as_array, as_rows, check_finite, positive_scalar

__all__ = [
    "FeasibilityResult",
    "feasibility_factor",
    "fwp_halfspaces",
    "halfspace_margin",
    "minkowski_feasibility_factor",
    "wrench_violations",
]

FloatArray = NDArray[np.float64]

# Relative tolerance of the membership LPs of wrench_violations (residual / wrench scale).
_MEMBER_TOL = 1e-6
# Relative tolerance on the part of a wrench outside the span of a lower-dimensional FWP.
_SPAN_TOL = 1e-9


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FeasibilityResult:
    """Result of :func:`feasibility_factor` / :func:`minkowski_feasibility_factor`.

    Attributes
    ----------
    s : float
        Feasibility factor of eq. (24), in ``(-inf, 1]``; ``-inf`` when no scaling of the FWP about
        its centre contains the wrench (empty FWP, or a lower-dimensional FWP and a wrench off its
        span); NaN on solver failure.
    status : str
        ``"ok"``, ``"infeasible"`` (empty FWP; ``s = -inf``) or ``"solver_error"``.
    solve_time : float
        Wall-clock seconds (set-up and solve).
    n_variables, n_constraints : int
        Size of the linear program (equality rows; the sign constraints not counted, as Table I).
    message : str
        Detail when ``s`` is infinite or NaN.
    """

    s: float
    status: str
    solve_time: float
    n_variables: int
    n_constraints: int
    message: str = ""


# --------------------------------------------------------------------------------------------
# Feasibility factor (eq. 21-24)
# --------------------------------------------------------------------------------------------


def _homogeniser(length_scale: float) -> FloatArray:
    return np.concatenate([np.ones(3), np.full(3, 1.0 / length_scale)])


def feasibility_factor(
    vertices: ArrayLike,
    wrench: ArrayLike,
    center: ArrayLike | None = None,
    length_scale: float = 1.0,
    dual: bool = True,
) -> FeasibilityResult:
    r"""Feasibility factor :math:`s` of ``wrench`` w.r.t. the polytope ``conv(vertices)`` (eq. 21-24).

    Eq. (24) has :math:`n_v + 1` variables and 7 equality rows (the 6 wrench rows and
    :math:`\mathbf{1}^T \lambda + s = 1`). By LP duality its value is
    :math:`s = 1 - \max\{\hat w^T u : \hat v_j^T u \le 1\ \forall j\}` (the gauge as the support
    function of the polar), a program with 6 variables and :math:`n_v` rows that Clarabel solves ~4x
    faster on thousands of vertices; both give the same ``s`` to solver accuracy.

    Parameters
    ----------
    vertices : (V, 6) array_like
        V-description [N, N m] (extra interior points do not change ``s`` for a given centre).
    wrench : (6,) array_like
        Wrench to test, e.g. :func:`gravito_inertial_wrench`, same frame and reference point.
    center : (6,) array_like, optional
        Interior point :math:`v_c`; default the centroid of ``vertices`` (the paper's choice). Pass
        ``fwp.center`` to reproduce :func:`minkowski_feasibility_factor`.
    length_scale : float
        Length [m] dividing the moment rows, only for the conditioning of the program (``s`` is
        invariant to it).
    dual : bool
        Solve the dual (default) or eq. (24) as written. ``n_variables`` and ``n_constraints`` of the
        result are those of eq. (24) either way.

    Returns
    -------
    FeasibilityResult
        ``s = -inf`` (status ok) if the vertices span less than 6 dimensions and the wrench is off
        their affine hull, or if ``center`` is not interior and the wrench is not in the cone of the
        centred vertices.
    """
    v = as_rows("vertices", vertices, 6, rows="V", min_rows=1)
    check_finite("vertices", v)
    w = as_array("wrench", wrench, (6,))
    check_finite("wrench", w)
    c = v.mean(axis=0) if center is None else as_array("center", center, (6,))
    check_finite("center", c)
    h = _homogeniser(positive_scalar("length_scale", length_scale))
    return _factor([(v - c) * h], (w - c) * h, n_equalities_paper=7, dual=dual)


def _factor(
    blocks: list[FloatArray], rhs: FloatArray, n_equalities_paper: int, dual: bool = False
) -> FeasibilityResult:
    t0 = time.perf_counter()
    centred = np.concatenate(blocks)
    scale = float(np.max(np.abs(centred), initial=0.0))
    basis = span_basis(centred, scale)
    n_var = centred.shape[0] + 1
    off_span = rhs - basis @ (basis.T @ rhs)
    if np.linalg.norm(off_span) > _SPAN_TOL * max(scale, float(np.linalg.norm(rhs))):
        msg = f"wrench is off the span of the {basis.shape[1]}-dimensional FWP: no contact forces produce it"
        return FeasibilityResult(-math.inf, "ok", time.perf_counter() - t0, n_var, n_equalities_paper, msg)
    if dual and len(blocks) == 1:
        s, msg = polar_support_lp(blocks[0], rhs, basis)
    else:
        t, msg, _ = gauge_lp(blocks, rhs, basis)
        s = 1.0 - t
    status = "solver_error" if math.isnan(s) else "ok"
    return FeasibilityResult(s, status, time.perf_counter() - t0, n_var, n_equalities_paper, msg)


def minkowski_feasibility_factor(fwp: FeasibleWrenchPolytope, wrench: ArrayLike) -> FeasibilityResult:
    r"""Feasibility factor of eq. (24) solved on the summands, without the FWP vertices.

    The program of the module docstring (:math:`\sum_i m_i + 1` variables, 6 + n equality rows); its
    value equals ``feasibility_factor(fwp.vertices, wrench, center=fwp.center)`` for a pruned
    ``fwp``, but it also works on ``prune=False`` polytopes and costs ~1 ms.

    Parameters
    ----------
    fwp : FeasibleWrenchPolytope
        From :func:`feasible_wrench_polytope` (pruned or not).
    wrench : (6,) array_like
        Wrench [N, N m], moments about the CoM, frame H.

    Returns
    -------
    FeasibilityResult
        Status ``"infeasible"`` and ``s = -inf`` for an empty FWP.
    """
    w = as_array("wrench", wrench, (6,))
    check_finite("wrench", w)
    n = len(fwp.force_vertices)
    n_var = sum(fwp.contact_vertex_counts) + 1
    if fwp.dim < 0:
        return FeasibilityResult(-math.inf, "infeasible", 0.0, n_var, 6 + n, "a bounded friction cone is empty")
    h = _homogeniser(fwp.length_scale)
    if n == 0:
        s = 1.0 if not np.any(w) else -math.inf
        return FeasibilityResult(s, "ok", 0.0, 1, 0, "no contact: the FWP is {0}")
    blocks = []
    for p, f in zip(fwp.points, fwp.force_vertices, strict=True):
        g = np.hstack([f, np.cross(p, f)]) * h
        blocks.append(g - g.mean(axis=0))
    return _factor(blocks, (w - fwp.center) * h, n_equalities_paper=6 + n)


# --------------------------------------------------------------------------------------------
# Which limit is violated (eq. 18 discussion) and the H-description margin (eq. 17-20)
# --------------------------------------------------------------------------------------------


def wrench_violations(fwp: FeasibleWrenchPolytope, wrench: ArrayLike) -> tuple[str, ...]:
    r"""Which limits a wrench violates: the CWC and AWP blocks :math:`H_c`, :math:`H_a` of eq. (18).

    Decided by membership LPs rather than by the facets: ``"contact"`` if the wrench is not a
    non-negative combination of the friction-cone edge wrenches :math:`\hat e_i^j` (outside the
    CWC, eq. 7-8: a foot would slip, pull or the robot tip over its support), ``"actuation"`` if it
    is not in :math:`\bigoplus_i \mathrm{conv}(w_{i,k})` (outside the AWP, eq. 4-6: some joint
    torque would exceed its limit whatever the contacts). A wrench inside both but outside the FWP
    (``s < 0``) gives ``("coupled",)``: every force distribution that respects friction violates a
    torque limit and vice versa. Inside the FWP: ``()``.
    Membership is decided to a relative tolerance of 1e-6, so wrenches on a boundary may go either way.

    Parameters
    ----------
    fwp : FeasibleWrenchPolytope
        Pruned or not.
    wrench : (6,) array_like
        Wrench [N, N m] about the CoM, frame H.

    Returns
    -------
    tuple of str
    """
    w = as_array("wrench", wrench, (6,))
    check_finite("wrench", w)
    h = _homogeniser(fwp.length_scale)
    wh = w * h
    tol = _MEMBER_TOL * max(1.0, float(np.sum(np.abs(wh))))

    def wrenches(sets: tuple[FloatArray, ...]) -> list[FloatArray]:
        return [np.hstack([f, np.cross(p, f)]) * h for p, f in zip(fwp.points, sets, strict=True)]

    if not fwp.force_vertices:
        return () if not np.any(w) else ("contact", "actuation")
    out = []
    if not residual_lp(wrenches(fwp.cone_edges), wh, convex=False) <= tol:
        out.append("contact")
    if not residual_lp(wrenches(fwp.actuation_vertices), wh, convex=True) <= tol:
        out.append("actuation")
    if out:
        return tuple(out)
    if fwp.dim >= 0 and minkowski_feasibility_factor(fwp, w).s >= 0.0:
        return ()
    return ("coupled",)


def fwp_halfspaces(vertices: ArrayLike, length_scale: float) -> FloatArray:
    r"""H-description of ``conv(vertices)`` (eq. 17) with qhull, in the units of :func:`halfspace_margin`.

    qhull works on the homogenised vertices :math:`(f, \tau/\ell)`; its triangulated facets are merged
    by rounding their unit equations. Expensive: ~0.2 s for 500 vertices (3 contacts), seconds to
    minutes for 4 contacts (the paper's Table II); the FWP must be full-dimensional.

    Parameters
    ----------
    vertices : (V, 6) array_like
        FWP vertices [N, N m] (``fwp.vertices``).
    length_scale : float
        :math:`\ell` [m] of :math:`Q` (e.g. ``fwp.length_scale`` or the CoM height).

    Returns
    -------
    (h, 7) ndarray
        Rows ``[a, b]`` with ``a^T w + b <= 0`` inside, ``a`` of unit :math:`Q^{-1}`-norm:
        :math:`a_f^T a_f + \ell^2 a_\tau^T a_\tau = 1`.
    """
    from scipy.spatial import ConvexHull  # local: only this function needs qhull

    v = as_rows("vertices", vertices, 6, rows="V", min_rows=7)
    check_finite("vertices", v)
    ell = positive_scalar("length_scale", length_scale)
    h = _homogeniser(ell)
    vh = v * h
    c = vh.mean(axis=0)
    eq = ConvexHull(vh - c, qhull_options="Qx Q12").equations  # unit normals in homogenised coordinates
    eq = np.column_stack([eq[:, :6], eq[:, 6] - eq[:, :6] @ c])  # undo the centring
    scale = max(1.0, float(np.max(np.abs(eq[:, 6]))))
    key = np.round(np.column_stack([eq[:, :6], eq[:, 6] / scale]) * 1e8)
    eq = eq[np.sort(np.unique(key, axis=0, return_index=True)[1])]
    # a_hom^T (h * w) + b = (h * a_hom)^T w + b.
    return np.column_stack([eq[:, :6] * h, eq[:, 6]])


def halfspace_margin(halfspaces: ArrayLike, wrench: ArrayLike, length_scale: float) -> float:
    r"""Margin :math:`m` of eq. (19)-(20) [N]: radius of the largest Q-ball around ``wrench`` in the polytope.

    With :math:`Q = \mathrm{diag}(1, 1, 1, \ell^{-2}, \ell^{-2}, \ell^{-2})` (module docstring),
    :math:`m = \min_j -(a_j^T w + b_j) / \sqrt{a_j^T Q^{-1} a_j}`.

    Parameters
    ----------
    halfspaces : (h, 7) array_like
        Rows ``[a, b]``, ``a^T w + b <= 0`` inside (e.g. :func:`fwp_halfspaces`, or scipy's
        ``ConvexHull.equations`` of physical wrenches).
    wrench : (6,) array_like
        :math:`w_{GI}` [N, N m].
    length_scale : float
        :math:`\ell` [m] (> 0).

    Returns
    -------
    float
        Positive inside (largest disturbance, in newtons of equivalent force, that keeps the wrench
        feasible), zero on the boundary, negative outside (largest facet violation, not a distance).
    """
    hs = as_rows("halfspaces", halfspaces, 7, rows="h", min_rows=1)
    check_finite("halfspaces", hs)
    w = as_array("wrench", wrench, (6,))
    check_finite("wrench", w)
    ell = positive_scalar("length_scale", length_scale)
    a = hs[:, :6]
    q_inv_norm = np.sqrt(np.sum(a[:, :3] ** 2, axis=1) + ell**2 * np.sum(a[:, 3:] ** 2, axis=1))
    if np.any(q_inv_norm <= 0.0):
        raise ValueError("halfspaces must have non-zero normals")
    return float(np.min(-(a @ w + hs[:, 6]) / q_inv_norm))
