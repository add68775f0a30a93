r"""Construction of the Feasible Wrench Polytope (FWP, seed 004, eq. 3, 8, 10-13) in frame H.

Robot-agnostic, arrays in and out. Frame H of :mod:`~margin_rl.stability.geometry.region` (origin at the CoM,
:math:`z` against gravity); contact points :math:`p_i` [m], forces [N], wrenches :math:`(f, p \times f)`
[N, N m] with moments about the CoM. Per stance contact: the edges of the linearised friction cone
(:func:`friction_cone_edges`, eq. 8), the force polytope :math:`\mathcal{F}_i` of the joint-torque limits
(:func:`force_polytope`, eq. 3), the bounded friction cone :math:`\mathcal{B}_i = \mathcal{C}_i \cap
\mathcal{F}_i` (:func:`bounded_friction_cone`, eq. 10) and its wrenches (:func:`contact_wrench_vertices`,
eq. 11); then the Minkowski sum :math:`\bigoplus_i \mathcal{G}_i` pruned to its vertices by a batched
phase-1 simplex on the tangent cones (:func:`feasible_wrench_polytope`, eq. 13), in wrench coordinates
homogenised by a length [m]. The derivation, the sign conventions and the feasibility factor that
uses the polytope are in :mod:`~margin_rl.stability.fwp.feasibility`.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.stability.fwp.programs import depth_lp
from margin_rl.stability.geometry.contact import (
    as_array,
    as_rows,
    check_finite,
    frozen_array,
    positive_scalar,
    tangent_bases,
    validate_contact_arrays,
)

__all__ = [
    "DEFAULT_N_FACES",
    "FeasibleWrenchPolytope",
    "bounded_friction_cone",
    "contact_wrench_vertices",
    "feasible_wrench_polytope",
    "force_polytope",
    "friction_cone_edges",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Default number of faces of the linearised friction cone (as the k of ``("pyramid", k)``).
DEFAULT_N_FACES: int = 4


# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FeasibleWrenchPolytope:
    """V-description of the FWP (eq. 13) and its ingredients; arrays are read-only.

    Attributes
    ----------
    vertices : (V, 6) ndarray
        Vertices ``(f, tau)`` [N, N m] of the FWP, moments about the origin of frame H (the CoM);
        ``(0, 6)`` when built with ``prune=False`` or when the FWP is empty.
    vertex_tuples : (V, n) ndarray of int
        Row ``j`` gives, per stance contact, the index into ``force_vertices[i]`` of the vertices
        whose wrenches sum to ``vertices[j]``.
    center : (6,) ndarray
        :math:`v_c = \\sum_i \\bar b_i`, the sum of the centroids of the contact-wrench vertex sets
        (NaN if empty); interior to the FWP relative to its span.
    points : (n, 3) ndarray
        Stance contact points [m], frame H; ``n`` stance contacts, in input order.
    stance_index : (n,) ndarray of int
        Index of each stance contact in the input arrays.
    force_vertices : tuple of (m_i, 3) ndarray
        Vertices :math:`b_i^k` [N] of the bounded friction cones :math:`\\mathcal{B}_i` (eq. 10).
    actuation_vertices : tuple of (q_i, 3) ndarray
        Vertices [N] of the force polytopes :math:`\\mathcal{F}_i` (eq. 3), for the AWP.
    cone_edges : tuple of (k, 3) ndarray
        Unit edges :math:`e_i^j` of the linearised friction cones (eq. 8), for the CWC.
    dim : int
        Dimension of the FWP: 6 for three or more non-collinear contacts, 5 for two, 3 for one, 0
        with no contact (the FWP is then {0}), -1 if empty (some :math:`\\mathcal{B}_i` is empty).
    length_scale : float
        Length [m] used to homogenise moments (largest contact distance from the CoM, >= 0.1 m).
    pruned : bool
        Whether ``vertices`` holds the pruned V-description.
    n_candidates : int
        Number of sums tested by the pruning (0 if not pruned); the unpruned V-description has
        :math:`\\prod_i m_i` points.
    timings : dict
        Wall-clock seconds: ``cones`` (eq. 3, 10, 11), ``minkowski`` (eq. 13 pruning), ``total``.
    """

    vertices: FloatArray
    vertex_tuples: IntArray
    center: FloatArray
    points: FloatArray
    stance_index: IntArray
    force_vertices: tuple[FloatArray, ...]
    actuation_vertices: tuple[FloatArray, ...]
    cone_edges: tuple[FloatArray, ...]
    dim: int
    length_scale: float
    pruned: bool
    n_candidates: int
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def n_vertices(self) -> int:
        """Number of FWP vertices (0 unless pruned)."""
        return int(self.vertices.shape[0])

    @property
    def contact_vertex_counts(self) -> tuple[int, ...]:
        """Number of vertices of each :math:`\\mathcal{B}_i` (the paper's :math:`\\mu`)."""
        return tuple(int(b.shape[0]) for b in self.force_vertices)

    @property
    def n_unpruned(self) -> int:
        """Size :math:`\\prod_i m_i` of the unpruned V-description of eq. (13)."""
        return math.prod(self.contact_vertex_counts) if self.force_vertices else 1


# Relative tolerances (times the force scale of a contact) of the 3-D vertex enumeration: a plane
# triple whose solution violates another plane by more than _FEAS_TOL is not a vertex; vertices closer
# than _MERGE_TOL are one; planes within _ACTIVE_TOL of a vertex are active there. _ACTIVE_TOL is
# generous on purpose: a spurious active plane can only add a superfluous (still valid) generator of
# the tangent cone, while a missed one would drop an edge and make a non-vertex look like a vertex.
_FEAS_TOL = 1e-9
_MERGE_TOL = 1e-7
_ACTIVE_TOL = 1e-7
# Three unit plane normals with |det| below this are treated as dependent (no unique vertex).
_DET_TOL = 1e-10
# A candidate Minkowski sum is a vertex iff the depth of its normal cone (phase-1 value, in the
# homogenised wrench coordinates, dimensionless) exceeds this. Non-vertices give ~1e-10 (the
# right-hand-side perturbation), the shallowest true vertices we met ~1e-6.
_POINTED_TOL = 1e-9
_SIMPLEX_PERTURBATION = 1e-11
_SIMPLEX_MAX_PIVOTS = 100
_SIMPLEX_CHUNK = 4096


# --------------------------------------------------------------------------------------------
# Per contact: friction pyramid, force polytope, bounded friction cone (eq. 3, 8, 10)
# --------------------------------------------------------------------------------------------


def check_n_faces(n_faces: Any) -> int:
    if isinstance(n_faces, bool) or not isinstance(n_faces, (int, np.integer)) or n_faces < 3:
        raise ValueError(f"n_faces must be an integer >= 3, got {n_faces!r}")
    return int(n_faces)


def _unit_normal(normal: ArrayLike, name: str = "normal") -> FloatArray:
    n = as_array(name, normal, (3,))
    check_finite(name, n)
    length = float(np.linalg.norm(n))
    if length < 1e-9:
        raise ValueError(f"{name} must be non-zero")
    return n / length


def _pyramid_faces(normal: FloatArray, mu: float, n_faces: int) -> FloatArray:
    """Rows ``a_j`` of the inscribed pyramid ``a_j^T f <= 0``, a_j = d_j - mu cos(pi/k) n (unit)."""
    t1, t2 = tangent_bases(normal[None, :])
    th = 2.0 * np.pi * np.arange(n_faces) / n_faces
    d = np.cos(th)[:, None] * t1 + np.sin(th)[:, None] * t2
    faces = d - mu * math.cos(math.pi / n_faces) * normal
    return faces / np.linalg.norm(faces, axis=1, keepdims=True)


def friction_cone_edges(normal: ArrayLike, mu: float, n_faces: int = DEFAULT_N_FACES) -> FloatArray:
    r"""Unit edges :math:`e^j` (eq. 8) of the linearised friction cone, ``("pyramid", k)`` convention.

    Parameters
    ----------
    normal : (3,) array_like
        Contact normal (out of the ground), frame H; normalised here.
    mu : float
        Friction coefficient (> 0).
    n_faces : int
        Number of faces k (>= 3).

    Returns
    -------
    (k, 3) ndarray
        :math:`e^j \propto n + \mu(\cos\theta_j t_1 + \sin\theta_j t_2)`, :math:`\theta_j = (2j+1)\pi/k`:
        the pyramid's edges, which lie on the Coulomb cone (the pyramid is inscribed).
    """
    n = _unit_normal(normal)
    mu_v = positive_scalar("mu", mu)
    k = check_n_faces(n_faces)
    t1, t2 = tangent_bases(n[None, :])
    th = (2.0 * np.arange(k) + 1.0) * np.pi / k
    e = n + mu_v * (np.cos(th)[:, None] * t1 + np.sin(th)[:, None] * t2)
    return e / np.linalg.norm(e, axis=1, keepdims=True)


@functools.lru_cache(maxsize=16)
def _plane_triples(m: int) -> IntArray:
    return np.array(list(itertools.combinations(range(m), 3)), dtype=np.intp).reshape(-1, 3)


def _polytope_vertices(a: FloatArray, b: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Vertices of the bounded polytope ``{x in R^3 : a x <= b}`` (unit rows) and the active planes.

    Every vertex lies on three planes with independent normals, so solving all plane triples and
    keeping the feasible, distinct solutions gives exactly the vertices (degenerate vertices, such as
    the pyramid apex on k planes, appear once after merging). Returns ``(vertices (m, 3), active
    (m, rows))``; ``(0, 3)`` if the polytope is empty.
    """
    scale = max(1.0, float(np.max(np.abs(b))))
    tri = _plane_triples(a.shape[0])
    M = a[tri]
    ok = np.abs(np.linalg.det(M)) > _DET_TOL
    x = np.linalg.solve(M[ok], b[tri][ok][..., None])[..., 0]
    x = x[np.min(b[None, :] - x @ a.T, axis=1) >= -_FEAS_TOL * scale]
    keep: list[FloatArray] = []
    for p in x:  # greedy merge; at most C(rows, 3) points
        if all(np.max(np.abs(p - q)) > _MERGE_TOL * scale for q in keep):
            keep.append(p)
    v = np.array(keep, dtype=np.float64).reshape(-1, 3)
    active = (b[None, :] - v @ a.T) <= _ACTIVE_TOL * scale
    return v, active


def _adjacency(a: FloatArray, active: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Vertex adjacency of a 3-D polytope: two vertices span an edge iff they share two active planes
    with independent normals (the segment then lies in a face of dimension <= 1, i.e. an edge)."""
    independent = (np.linalg.norm(np.cross(a[:, None, :], a[None, :, :]), axis=2) > 1e-9).astype(np.float64)
    common = (active[:, None, :] & active[None, :, :]).astype(np.float64)
    adj = np.einsum("uvk,kl,uvl->uv", common, independent, common) > 0.5
    np.fill_diagonal(adj, False)
    return adj


def _check_jacobian(jac: FloatArray, name: str) -> None:
    check_finite(name, jac)
    sv = np.linalg.svd(jac, compute_uv=False)
    if sv.size < 3 or sv[2] <= 1e-9 * max(sv[0], 1e-300):
        raise ValueError(f"{name} must have rank 3 (a singular leg makes the force polytope unbounded)")


def _leg_arrays(
    jacobian: ArrayLike, torque_lo: ArrayLike, torque_hi: ArrayLike, leg_bias: ArrayLike | None
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    try:
        jac = np.asarray(jacobian, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError("jacobian must be a numeric (3, k) array") from exc
    if jac.ndim != 2 or jac.shape[0] != 3 or jac.shape[1] < 3:
        raise ValueError(f"jacobian must have shape (3, k) with k >= 3, got {jac.shape}")
    k = jac.shape[1]
    _check_jacobian(jac, "jacobian")
    lo = as_array("torque_lo", torque_lo, (k,))
    hi = as_array("torque_hi", torque_hi, (k,))
    check_finite("torque_lo", lo)
    check_finite("torque_hi", hi)
    if np.any(lo > hi):
        raise ValueError("torque_lo must be <= torque_hi for every joint")
    bias = np.zeros(k) if leg_bias is None else as_array("leg_bias", leg_bias, (k,))
    check_finite("leg_bias", bias)
    return jac, lo, hi, bias


def _torque_rows(jac: FloatArray, lo: FloatArray, hi: FloatArray, bias: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Unit rows of lo <= delta - J^T f <= hi: J^T f <= delta - lo and -J^T f <= hi - delta."""
    a = np.vstack([jac.T, -jac.T])
    b = np.concatenate([bias - lo, hi - bias])
    norm = np.linalg.norm(a, axis=1)
    return a / norm[:, None], b / norm


def force_polytope(
    jacobian: ArrayLike, torque_lo: ArrayLike, torque_hi: ArrayLike, leg_bias: ArrayLike | None = None
) -> FloatArray:
    r"""Vertices of the force polytope :math:`\mathcal{F}_i` of one leg (eq. 3).

    Parameters
    ----------
    jacobian : (3, k) array_like
        Translational foot Jacobian w.r.t. the leg's k >= 3 joints, frame H [m/rad]; rank 3.
    torque_lo, torque_hi : (k,) array_like
        Finite joint-torque bounds [N m].
    leg_bias : (k,) array_like, optional
        Bias torques :math:`\delta_i` [N m] (default zeros); the joint torques under a contact force
        ``f`` are :math:`\delta_i - J^T f`.

    Returns
    -------
    (q, 3) ndarray
        Vertices [N] of :math:`\{f : \underline\tau \le \delta - J^T f \le \bar\tau\}`; for k = 3 the
        :math:`2^3` points :math:`J^{-T}(\delta - \tau^{lim})` of eq. (3).

    Raises
    ------
    ValueError
        Malformed, non-finite or singular inputs (the message names the argument).
    """
    jac, lo, hi, bias = _leg_arrays(jacobian, torque_lo, torque_hi, leg_bias)
    a, b = _torque_rows(jac, lo, hi, bias)
    return _polytope_vertices(a, b)[0]


@dataclass(frozen=True)
class _Contact:
    """One stance contact: B_i vertices, their homogenised wrenches and tangent-cone generators."""

    forces: FloatArray  # (m, 3) vertices of B_i [N]
    wrenches: FloatArray  # (m, 6) homogenised wrenches (f, p x f / ell)
    generators: FloatArray  # (m, d, 6) unit edge directions of G_i at each vertex (zero-padded)


def _bounded_cone(
    normal: FloatArray, mu: float, jac: FloatArray, lo: FloatArray, hi: FloatArray, bias: FloatArray, n_faces: int
) -> tuple[FloatArray, NDArray[np.bool_], FloatArray]:
    ta, tb = _torque_rows(jac, lo, hi, bias)
    a = np.vstack([_pyramid_faces(normal, mu, n_faces), ta])
    b = np.concatenate([np.zeros(n_faces), tb])
    v, active = _polytope_vertices(a, b)
    return v, active, a


def bounded_friction_cone(
    normal: ArrayLike,
    mu: float,
    jacobian: ArrayLike,
    torque_lo: ArrayLike,
    torque_hi: ArrayLike,
    leg_bias: ArrayLike | None = None,
    n_faces: int = DEFAULT_N_FACES,
) -> FloatArray:
    r"""Vertices :math:`b^k` of the bounded friction cone :math:`\mathcal{B} = \mathcal{C} \cap \mathcal{F}` (eq. 10).

    The intersection of the k-face friction pyramid (inscribed in the Coulomb cone) with the force
    polytope of eq. (3), computed in 3-D from the :math:`k + 2n_a` half-spaces.

    Parameters
    ----------
    normal : (3,) array_like
        Contact normal (out of the ground), frame H; normalised here.
    mu : float
        Friction coefficient (> 0).
    jacobian : (3, k) array_like
        Translational foot Jacobian, frame H [m/rad]; rank 3.
    torque_lo, torque_hi : (k,) array_like
        Finite joint-torque bounds [N m].
    leg_bias : (k,) array_like, optional
        Bias torques [N m] (default zeros).
    n_faces : int
        Faces of the friction pyramid (>= 3).

    Returns
    -------
    (m, 3) ndarray
        Vertices [N], frame H; ``(0, 3)`` if no force respects both limits. The origin is a vertex
        whenever the unloaded leg is within its torque limits.

    Raises
    ------
    ValueError
        Malformed inputs (the message names the argument).
    """
    n = _unit_normal(normal)
    mu_v = positive_scalar("mu", mu)
    k = check_n_faces(n_faces)
    jac, lo, hi, bias = _leg_arrays(jacobian, torque_lo, torque_hi, leg_bias)
    return _bounded_cone(n, mu_v, jac, lo, hi, bias, k)[0]


def contact_wrench_vertices(point: ArrayLike, force_vertices: ArrayLike) -> FloatArray:
    r"""Wrenches :math:`\hat b^k = (b^k,\ p \times b^k)` of forces applied at ``point`` (eq. 11).

    Parameters
    ----------
    point : (3,) array_like
        Contact point [m] relative to the moment reference (the CoM in frame H).
    force_vertices : (m, 3) array_like
        Forces [N], e.g. from :func:`bounded_friction_cone`.

    Returns
    -------
    (m, 6) ndarray
        ``(f, tau)`` [N, N m].
    """
    p = as_array("point", point, (3,))
    check_finite("point", p)
    f = as_rows("force_vertices", force_vertices, 3, rows="m")
    check_finite("force_vertices", f)
    return np.hstack([f, np.cross(p, f)])


def _contact(point: FloatArray, v: FloatArray, active: NDArray[np.bool_], a: FloatArray, ell: float) -> _Contact:
    """Homogenised wrenches (moments / ell) and unit tangent-cone generators of G_i at each vertex."""
    w = np.hstack([v, np.cross(point, v) / ell])
    adj = _adjacency(a, active)
    degree = adj.sum(axis=1)
    gens = np.zeros((v.shape[0], int(degree.max(initial=0)), 6))
    for u in range(v.shape[0]):
        nb = np.flatnonzero(adj[u])
        g = w[nb] - w[u]
        gens[u, : nb.size] = g / np.linalg.norm(g, axis=1, keepdims=True)
    return _Contact(forces=v, wrenches=w, generators=gens)


# --------------------------------------------------------------------------------------------
# Minkowski sum (eq. 13): pointedness of tangent cones by a batched phase-1 simplex
# --------------------------------------------------------------------------------------------


def _phase1_depth(gens: FloatArray, rng: np.random.Generator) -> FloatArray:
    """Phase-1 value ``min ||G^T y - eps||_1 + r`` s.t. ``1^T y + r = 1``, ``y, r >= 0``, per candidate.

    ``gens`` is (C, K, 6) with zero rows as padding (a zero column never enters the basis). The
    tableau has rows ``G^T y + p - q = eps`` (6) and ``1^T y + r = 1`` with the artificial basis
    (p, r) and a reduced-cost row; Dantzig's rule, vectorised over the candidates that are not yet
    optimal. Returns NaN where ``_SIMPLEX_MAX_PIVOTS`` was not enough.
    """
    c_all, k, _ = gens.shape
    n = k + 13
    tab = np.zeros((c_all, 8, n + 1))
    tab[:, :6, :k] = np.transpose(gens, (0, 2, 1))
    tab[:, 6, :k] = np.any(gens != 0.0, axis=2)
    tab[:, :6, k : k + 6] = np.eye(6)
    tab[:, :6, k + 6 : k + 12] = -np.eye(6)
    tab[:, 6, k + 12] = 1.0
    # Random positive perturbation of the zero right-hand side against degenerate cycling.
    tab[:, :6, n] = _SIMPLEX_PERTURBATION * (1.0 + rng.random(6))
    tab[:, 6, n] = 1.0
    cost = np.zeros(n)
    cost[k:] = 1.0
    tab[:, 7, :n] = cost - tab[:, :7, :n].sum(axis=1)  # all basic costs are 1
    tab[:, 7, n] = -tab[:, :7, n].sum(axis=1)
    out = np.full(c_all, np.nan)
    idx = np.arange(c_all)
    for _ in range(_SIMPLEX_MAX_PIVOTS):
        reduced = tab[:, 7, :n]
        enter = np.argmin(reduced, axis=1)
        rows = np.arange(idx.size)
        done = reduced[rows, enter] >= -1e-12
        if done.any():
            out[idx[done]] = -tab[done, 7, n]
            keep = ~done
            tab, idx, enter = tab[keep], idx[keep], enter[keep]
            if idx.size == 0:
                break
            rows = np.arange(idx.size)
        col = tab[rows, :7, enter]
        positive = col > 1e-12
        ratio = np.where(positive, tab[:, :7, n] / np.where(positive, col, 1.0), np.inf)
        leave = np.argmin(ratio, axis=1)
        pivot_row = tab[rows, leave, :] / col[rows, leave][:, None]
        tab -= tab[rows, :, enter][:, :, None] * pivot_row[:, None, :]
        tab[rows, leave, :] = pivot_row
    return out


def _minkowski_vertices(contacts: list[_Contact]) -> tuple[IntArray, int]:
    """Index tuples of the vertices of sum_i G_i, adding one contact at a time; also the candidates tested."""
    rng = np.random.default_rng(0)  # fixed: the result must not depend on a global state
    tuples = np.arange(contacts[0].forces.shape[0], dtype=np.intp)[:, None]
    n_tested = 0
    for j in range(1, len(contacts)):
        m = contacts[j].forces.shape[0]
        cand = np.hstack([np.repeat(tuples, m, axis=0), np.tile(np.arange(m, dtype=np.intp), tuples.shape[0])[:, None]])
        n_tested += cand.shape[0]
        keep = np.zeros(cand.shape[0], dtype=bool)
        for start in range(0, cand.shape[0], _SIMPLEX_CHUNK):
            chunk = cand[start : start + _SIMPLEX_CHUNK]
            gens = np.concatenate([contacts[i].generators[chunk[:, i]] for i in range(j + 1)], axis=1)
            depth = _phase1_depth(gens, rng)
            for r in np.flatnonzero(np.isnan(depth)):  # rare: ran out of pivots
                depth[r] = depth_lp(gens[r])
            # A candidate still undecided (NaN) is kept: an extra point never changes the hull.
            keep[start : start + chunk.shape[0]] = ~(depth <= _POINTED_TOL)
        tuples = cand[keep]
    return tuples, n_tested


# --------------------------------------------------------------------------------------------
# The FWP
# --------------------------------------------------------------------------------------------


def span_basis(points: FloatArray, scale: float) -> FloatArray:
    """Orthonormal basis (6, r) of the linear span of the rows of ``points`` (rank to 1e-9 * scale).

    QR first: the SVD of the small triangular factor has the same singular values and right vectors,
    and a direct SVD of a (6, thousands) matrix is ~1000x slower here.
    """
    if points.shape[0] == 0:
        return np.zeros((6, 0))
    r = np.linalg.qr(points, mode="r")
    _, sv, vt = np.linalg.svd(r)
    return vt[: sv.size][sv > 1e-9 * max(scale, 1e-300)].T


def feasible_wrench_polytope(
    points: ArrayLike,
    normals: ArrayLike,
    stance: ArrayLike,
    mu: float,
    jacobians: ArrayLike,
    torque_limits: ArrayLike | tuple[ArrayLike, ArrayLike],
    leg_bias: ArrayLike | None = None,
    n_faces: int = DEFAULT_N_FACES,
    prune: bool = True,
) -> FeasibleWrenchPolytope:
    r"""Feasible Wrench Polytope :math:`\bigoplus_i \mathcal{G}_i` (eq. 10-13) in frame H.

    Parameters
    ----------
    points : (n, 3) array_like
        Contact points [m] relative to the CoM, frame H (e.g. ``ContactProblem.contact_points``).
    normals : (n, 3) array_like
        Contact normals (out of the ground); normalised here.
    stance : (n,) array_like of bool
        Contacts in stance; the others are ignored (their rows may hold anything).
    mu : float
        Friction coefficient (> 0).
    jacobians : (n, 3, k) array_like
        Translational foot Jacobians, frame H [m/rad], k >= 3, rank 3 for stance legs.
    torque_limits : (n, k) array_like, or a pair (lower, upper) of (n, k) arrays
        Symmetric limits ``|tau| <= limit`` or explicit bounds [N m]; finite for stance legs.
    leg_bias : (n, k) array_like, optional
        Bias torques :math:`\delta_i` [N m] (default zeros).
    n_faces : int
        Faces of the linearised friction cones (>= 3).
    prune : bool
        Compute the vertices of eq. (13) (the expensive part). Without it the result still carries
        the :math:`\mathcal{B}_i`, the centre and the dimension, which is all that
        :func:`minkowski_feasibility_factor` needs.

    Returns
    -------
    FeasibleWrenchPolytope

    Raises
    ------
    ValueError
        On malformed inputs; the message names the argument.
    """
    t0 = time.perf_counter()
    pts, nrm, jac, lo, hi, bias, idx = validate_contact_arrays(
        points, normals, stance, jacobians, torque_limits, leg_bias, points_name="points", min_joints=3
    )
    mu_v = positive_scalar("mu", mu)
    k_faces = check_n_faces(n_faces)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ValueError("torque_limits must be finite for stance legs (the FWP would be unbounded)")
    for i in range(idx.size):
        _check_jacobian(jac[i], f"jacobians[{idx[i]}]")
    ell = max(0.1, float(np.max(np.linalg.norm(pts, axis=1), initial=0.0)))

    # Eq. (3), (8), (10), (11): per-contact sets, in 3-D.
    forces, actuation, edges, contacts = [], [], [], []
    for i in range(idx.size):
        v, active, a = _bounded_cone(nrm[i], mu_v, jac[i], lo[i], hi[i], bias[i], k_faces)
        ta, tb = _torque_rows(jac[i], lo[i], hi[i], bias[i])
        forces.append(frozen_array(v))
        actuation.append(frozen_array(_polytope_vertices(ta, tb)[0]))
        edges.append(frozen_array(friction_cone_edges(nrm[i], mu_v, k_faces)))
        contacts.append(_contact(pts[i], v, active, a, ell))
    t1 = time.perf_counter()

    empty = any(c.forces.shape[0] == 0 for c in contacts)
    homog = np.concatenate([np.ones(3), np.full(3, ell)])  # homogenised -> physical wrench units
    if empty:
        center = np.full(6, np.nan)
        dim = -1
    elif not contacts:
        center = np.zeros(6)
        dim = 0
    else:
        center = homog * sum(c.wrenches.mean(axis=0) for c in contacts)
        centred = np.concatenate([c.wrenches - c.wrenches.mean(axis=0) for c in contacts])
        dim = span_basis(centred, float(np.max(np.abs(centred), initial=0.0))).shape[1]

    tuples = np.zeros((0, idx.size), dtype=np.intp)
    n_tested = 0
    if prune and not empty:
        if contacts:
            tuples, n_tested = _minkowski_vertices(contacts)
        else:
            tuples = np.zeros((1, 0), dtype=np.intp)  # the empty sum is {0}
    vertices = np.zeros((tuples.shape[0], 6))
    for i, c in enumerate(contacts):
        vertices += c.wrenches[tuples[:, i]]
    t2 = time.perf_counter()
    return FeasibleWrenchPolytope(
        vertices=frozen_array(vertices * homog),
        vertex_tuples=frozen_array(tuples, np.intp),
        center=frozen_array(center),
        points=frozen_array(pts),
        stance_index=frozen_array(idx, np.intp),
        force_vertices=tuple(forces),
        actuation_vertices=tuple(actuation),
        cone_edges=tuple(edges),
        dim=int(dim),
        length_scale=ell,
        pruned=bool(prune),
        n_candidates=int(n_tested),
        timings={"cones": t1 - t0, "minkowski": t2 - t1, "total": t2 - t0},
    )
