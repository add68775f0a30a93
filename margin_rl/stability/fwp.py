r"""Feasible Wrench Polytope (FWP) and its feasibility factor (seed 004, Orsolino et al. 2018).

A second stability criterion next to the analytic margin of :mod:`margin_rl.stability.analytic`:
instead of projecting the equilibrium set onto the CoM plane, it asks whether the wrench the
contacts must produce lies in the set of wrenches the contacts *can* produce without slipping and
without exceeding the joint-torque limits, and measures how deep inside it is.

Frame, units and sign conventions
---------------------------------
Everything is in the horizontal frame :math:`\mathcal{H}` of :mod:`margin_rl.stability.region`:
origin at the current CoM, :math:`z` against gravity, :math:`x` along the heading. Contact
:math:`i` is at :math:`p_i` [m]; :math:`f_i` [N] is the force the ground exerts on the robot there.
Wrenches are :math:`w = (f, \tau)` [N, N m] with moments about the origin of :math:`\mathcal{H}`.

*Gravito-inertial wrench (eq. 14-15).* With the CoM at :math:`c` (zero by default, i.e. moments
about the CoM), gravity :math:`\vec g = (0, 0, -g)`, the rate of centroidal angular momentum
:math:`\dot L` and an external wrench :math:`(f_{ext}, \tau_{ext})` applied at the CoM,
Newton--Euler about the origin read

.. math:: m\ddot c = \sum_i f_i + m\vec g + f_{ext}, \qquad
          \dot L + c \times m\ddot c = \sum_i p_i \times f_i + c \times (m\vec g + f_{ext}) + \tau_{ext},

so the contacts must produce

.. math:: \sum_i \begin{bmatrix} f_i \\ p_i \times f_i \end{bmatrix} = w_{GI} :=
          \dot h - w_G - w_{ext} = \begin{bmatrix} F \\ \dot L - \tau_{ext} + c \times F \end{bmatrix},
          \qquad F = m(\ddot c - \vec g) - f_{ext},

with :math:`\dot h = (m\ddot c,\ \dot L + c \times m\ddot c)` and :math:`w_G = (m\vec g,\ c \times
m\vec g)` of eq. (15) and :math:`w_{ext} = (f_{ext},\ \tau_{ext} + c \times f_{ext})`. These are
exactly the Newton--Euler rows of :func:`~margin_rl.stability.region.feasible_region` (its
``force`` and ``moment`` at :math:`c = 0`). A standing robot needs :math:`w_{GI} = (0, 0, mg, 0, 0,
0)`: the ground pushes up with its weight.

*Force polytope (eq. 3).* The joint torques that leg :math:`i` needs to exert :math:`f_i` are
:math:`\tau_i = \delta_i - J_i^T f_i` (bias torques :math:`\delta_i` of the leg's own gravity and
inertia, translational foot Jacobian :math:`J_i` in :math:`\mathcal{H}`), so the limits
:math:`\underline\tau_i \le \tau_i \le \bar\tau_i` give the polytope
:math:`\mathcal{F}_i = \{f : J_i^T f \le \delta_i - \underline\tau_i,\ -J_i^T f \le \bar\tau_i -
\delta_i\}`; for a square :math:`J_i` its :math:`2^3` vertices are
:math:`J_i^{-T}(\delta_i - \tau^{lim})` over the corners :math:`\tau^{lim}` of the torque box
(eq. 3 with the bias term; we enumerate vertices of the H-description, which is also exact for
redundant legs where the pseudo-inverse of eq. 3 is not).

*Linearised friction cone.* The ``("pyramid", k)`` cone of the feasible region, inscribed in the
Coulomb cone: :math:`d_j^T f \le \mu\cos(\pi/k)\, n_i^T f` with :math:`d_j = \cos(2\pi j/k)
t_{i1} + \sin(2\pi j/k) t_{i2}` and the same tangent basis, so both criteria see the same friction
set. Its edges (eq. 8) are :math:`e_i^j = n_i + \mu(\cos\theta_j t_{i1} + \sin\theta_j t_{i2})`,
:math:`\theta_j = (2j + 1)\pi/k`. The pyramid implies :math:`n_i^T f \ge 0` (sum its faces).

Construction (eq. 10-13)
------------------------
1. *Bounded friction cone* :math:`\mathcal{B}_i = \mathcal{C}_i \cap \mathcal{F}_i` (eq. 10), in
   3-D as the paper proposes: :math:`k + 2 n_a` half-spaces; every vertex is the intersection of
   three of their planes, so all :math:`\binom{k + 2n_a}{3}` triples are solved at once and the
   feasible, distinct solutions kept (:func:`bounded_friction_cone`).
2. *Contact wrench vertices* :math:`\hat b_i^k = (b_i^k, p_i \times b_i^k)` (eq. 11), spanning
   :math:`\mathcal{G}_i` (eq. 12) (:func:`contact_wrench_vertices`).
3. *Minkowski sum* :math:`\mathrm{FWP} = \bigoplus_i \mathcal{G}_i` (eq. 13), pruned to its
   vertices (:func:`feasible_wrench_polytope`). Every vertex of :math:`P \oplus Q` is the sum of a
   vertex of :math:`P` and one of :math:`Q`, so contacts are added one at a time and each step
   tests the :math:`|V(P)| \cdot |V(Q)|` candidate sums. A sum :math:`x = \sum_i \hat b_i^{k_i}` is
   a vertex iff its tangent cone is pointed, i.e. iff the origin is not in the convex hull of the
   unit edge directions :math:`g` of the summands at their vertices (the edges of
   :math:`\mathcal{G}_i` at :math:`\hat b_i^{k_i}` generate its tangent cone, and the tangent cone
   of a Minkowski sum is the sum of the tangent cones). That is decided by a phase-1 linear
   program :math:`\min \|G^T y\|_1 + r` s.t. :math:`\mathbf{1}^T y + r = 1,\ y, r \ge 0`, whose
   value is :math:`\min(1, \max_{\|c\|_\infty \le 1} \min_g -g^T c)`: zero for non-vertices and the
   depth of the normal cone for vertices. The programs have 7 rows and about 30 columns, so we
   solve thousands of them at once with a dense, vectorised simplex (Dantzig's rule, right-hand
   side perturbed by ~1e-11 against cycling); the rare program that does not finish in
   ``_SIMPLEX_MAX_PIVOTS`` pivots is re-solved with Clarabel. This is the "normal fan" test of
   the Minkowski-sum algorithm the paper uses (Delos & Teissandier), without a per-candidate
   solver call. Wrench coordinates are homogenised (moments divided by a length, below) so that
   the threshold ``_POINTED_TOL`` on the depth is unit-free.

The pruning is exact up to that threshold: on ANYmal C it reproduces brute-force per-candidate LPs
and an independent qhull hull of the vertices (see the tests), where qhull on the raw candidates
fails on the many coplanar facets of a Minkowski sum.

Feasibility factor (eq. 21-24)
------------------------------
With the vertices :math:`v_j` and a centre :math:`v_c` in the interior, eq. (24) is

.. math:: \max_{\lambda, s}\ s \quad \text{s.t.}\quad \sum_j \lambda_j (v_j - v_c) = w_{GI} - v_c,
          \quad \mathbf{1}^T\lambda = 1 - s, \quad \lambda \ge 0,

i.e. :math:`s = 1 - \gamma(w_{GI} - v_c)` with :math:`\gamma` the gauge of the polytope centred at
:math:`v_c`: :math:`s \le 1`, :math:`s = 1` at the centre, :math:`s > 0` strictly inside,
:math:`s = 0` on the boundary, :math:`s < 0` outside, and :math:`s = 1 - \alpha` at
:math:`v_c + \alpha (v - v_c)` for a boundary point :math:`v`. Because :math:`\gamma` is invariant
under linear maps, :math:`s` needs no unit weighting (the paper's remark). It is solved with
Clarabel (:func:`feasibility_factor`): eq. (24) has :math:`n_v + 1` variables and 7 equality rows
as in Table I; by default we solve its LP dual, :math:`s = 1 - \max\{(w_{GI} - v_c)^T u :
(v_j - v_c)^T u \le 1\ \forall j\}` (6 variables, :math:`n_v` rows; same value, ~2x faster on
thousands of vertices).

The same value follows from a much smaller program on the summands
(:func:`minkowski_feasibility_factor`): a point is in :math:`t\,\mathrm{FWP}` iff it is
:math:`\sum_i\sum_k \mu_{ik} \hat b_i^k` with :math:`\mu \ge 0` and :math:`\sum_k \mu_{ik} = t` for
every contact, so eq. (24) is equivalent to

.. math:: \min_{\mu, t}\ t \quad\text{s.t.}\quad \sum_{i,k} \mu_{ik} (\hat b_i^k - \bar b_i) =
          w_{GI} - v_c, \quad \sum_k \mu_{ik} = t\ \forall i, \quad \mu \ge 0, \qquad s = 1 - t,

with :math:`\sum_i m_i + 1` variables instead of :math:`\prod_i m_i`, and no pruning at all. Both
forms need the same :math:`v_c`; we use :math:`v_c = \sum_i \bar b_i`, the sum of the centroids of
the :math:`\mathcal{G}_i` vertex sets, which is the centroid of the *unpruned* V-description (all
:math:`\prod_i m_i` sums) and lies in the relative interior of the FWP.

*Deviation from the paper:* the paper centres on the centroid of the *pruned* FWP vertices. Both
are heuristic stand-ins for the Chebyshev centre and give the same sign of :math:`s` (hence the
same feasibility verdict); ours does not depend on the pruning and allows the small program, so
:func:`fwp_feasibility` is fast. ``feasibility_factor(fwp.vertices, w)`` (``center=None``) gives
the paper's centring.

*Reading s.* The centre carries a large normal load (the :math:`\mathcal{B}_i` reach far up their
cones), so :math:`s` of a standing robot *grows* when it is pressed down, until torque limits come
near; :math:`s` is a relative depth, not a distance, and values of different stances are not
comparable (paper, Sec. IV-B).

H-description margin (eq. 17-20)
--------------------------------
When an H-description :math:`\{w : a_j^T w + b_j \le 0\}` is available (:func:`fwp_halfspaces`
builds one with qhull; seconds for 4 contacts), the margin of eq. (19)-(20) is the radius of the
largest ellipsoid :math:`\{w_{GI} + w_d : w_d^T Q w_d \le m^2\}` inside the polytope, disturbance
applied at the CoM (:math:`T = I`). We homogenise units with
:math:`Q = \mathrm{diag}(1, 1, 1, \ell^{-2}, \ell^{-2}, \ell^{-2})`: a moment :math:`\tau` counts
as the force :math:`\tau/\ell` acting at the lever arm :math:`\ell` [m], so :math:`m` is in newtons,
and :math:`m = \min_j -(a_j^T w_{GI} + b_j) / \sqrt{a_j^T Q^{-1} a_j}` (:func:`halfspace_margin`;
negative outside, where it is the largest violation rather than a distance). We write
:math:`m^2` where eq. (20) writes :math:`m` so that :math:`m` is a length in wrench space.

Which limit is violated (eq. 18 discussion)
-------------------------------------------
The paper splits the H-description into the CWC facets :math:`H_c` and the AWP facets :math:`H_a`.
Enumerating those facets costs seconds, so :func:`wrench_violations` decides the two memberships
directly with two small LPs: :math:`w \in \mathrm{CWC}` (eq. 7-8, cone of the edges
:math:`\hat e_i^j`, i.e. :math:`H_c^T w \le 0`) and :math:`w \in \mathrm{AWP}` (eq. 4-6, Minkowski
sum of the force polytopes' wrenches, :math:`H_a^T w \le 0`). Note that eq. (13) gives
:math:`\mathrm{FWP} \subseteq \mathrm{CWC} \cap \mathrm{AWP}` (eq. 9) but not equality in general:
one force distribution may respect friction and another the torque limits with none doing both.
Such a wrench is reported as ``"coupled"``.

Cost
----
Measured with ``benchmarks/bench_fwp.py`` on ANYmal C, static non-coplanar stances, a loaded 2-core
AMD EPYC: :func:`fwp_feasibility` (default, no pruning) takes ~5 ms for 3 contacts and ~9 ms for 4
(the feasible-region margin of the same state: ~1.5 ms). The paper's pipeline (``prune=True``)
takes ~13 ms for 3 contacts (~600-800 FWP vertices) and ~0.2 s for 4 (~3900-4500 vertices: ~0.1 s
to prune, ~30 ms for eq. 24). Use the criterion as an environment margin term only knowingly.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from margin_rl.robot import Robot
from margin_rl.stability.analytic import ContactProblem, contact_problem
from margin_rl.stability.contact import (
    INFEASIBLE,
    as_array,
    as_rows,
    check_finite,
    frozen_array,
    gravito_inertial_wrench,
    positive_scalar,
    solver_settings,
    tangent_bases,
    validate_contact_arrays,
)

__all__ = [
    "DEFAULT_N_FACES",
    "FWP_STATUSES",
    "FWPFeasibility",
    "FeasibilityResult",
    "FeasibleWrenchPolytope",
    "bounded_friction_cone",
    "contact_problem_polytope",
    "contact_wrench_vertices",
    "feasibility_factor",
    "feasible_wrench_polytope",
    "force_polytope",
    "friction_cone_edges",
    "fwp_feasibility",
    "fwp_halfspaces",
    "gravito_inertial_wrench",
    "halfspace_margin",
    "minkowski_feasibility_factor",
    "wrench_violations",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Default number of faces of the linearised friction cone (as the k of ``("pyramid", k)``).
DEFAULT_N_FACES: int = 4
#: Statuses of :func:`fwp_feasibility`: those of the analytic margin (``"infeasible"`` also covers an
#: empty FWP).
FWP_STATUSES: tuple[str, ...] = ("ok", "unreachable", "infeasible", "no_contact", "solver_error")

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
# Relative tolerance of the membership LPs of wrench_violations (residual / wrench scale).
_MEMBER_TOL = 1e-6
# Relative tolerance on the part of a wrench outside the span of a lower-dimensional FWP.
_SPAN_TOL = 1e-9


# --------------------------------------------------------------------------------------------
# Results
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


@dataclass(frozen=True)
class FWPFeasibility:
    """Result of :func:`fwp_feasibility` for one lambda.

    Attributes
    ----------
    s : float
        Feasibility factor of eq. (24). NaN without a contact problem (``"unreachable"``,
        ``"no_contact"``, or ``"infeasible"`` for a CoM not above its feet, as in the analytic margin)
        or on solver failure; ``-inf`` when no contact forces can produce the wrench (an empty FWP,
        status ``"infeasible"``, or a wrench off the span of a lower-dimensional FWP, status ``"ok"``).
    status : str
        One of :data:`FWP_STATUSES`.
    wrench : (6,) ndarray
        Gravito-inertial wrench :math:`w_{GI}` [N, N m] about the CoM, frame H (NaN without a problem).
    violated : tuple of str
        Empty if ``s >= 0``; otherwise from :func:`wrench_violations`: ``"contact"`` (outside the
        CWC, :math:`H_c^T w > 0`: slipping, pulling or tipping), ``"actuation"`` (outside the AWP,
        :math:`H_a^T w > 0`: torque limits), or ``("coupled",)`` when inside both but not in the FWP.
    n_vertices : int or None
        Number of FWP vertices when pruned, else None.
    contact_vertex_counts : tuple of int
        Vertices of each bounded friction cone.
    timings : dict
        Seconds: ``kinematics`` (IK, Jacobians, bias), ``fwp`` (eq. 10-13), ``lp`` (eq. 24),
        ``violations`` (if computed), ``total``.
    message : str
        Detail when the status is not ok or ``s`` is infinite.
    fwp : FeasibleWrenchPolytope or None
        The polytope (None when there is no contact problem).
    """

    s: float
    status: str
    wrench: FloatArray
    violated: tuple[str, ...]
    n_vertices: int | None
    contact_vertex_counts: tuple[int, ...]
    timings: dict[str, float]
    message: str = ""
    fwp: FeasibleWrenchPolytope | None = None


# --------------------------------------------------------------------------------------------
# Per contact: friction pyramid, force polytope, bounded friction cone (eq. 3, 8, 10)
# --------------------------------------------------------------------------------------------


def _check_n_faces(n_faces: Any) -> int:
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
    k = _check_n_faces(n_faces)
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
    k = _check_n_faces(n_faces)
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


def _depth_lp(gens: FloatArray) -> float:
    """Fallback for one candidate: ``max t`` s.t. ``g^T c + t <= 0``, ``|c|_inf <= 1``, ``t <= 1`` (Clarabel).

    Same value as :func:`_phase1_depth` by LP duality (without the perturbation).
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
                depth[r] = _depth_lp(gens[r])
            # A candidate still undecided (NaN) is kept: an extra point never changes the hull.
            keep[start : start + chunk.shape[0]] = ~(depth <= _POINTED_TOL)
        tuples = cand[keep]
    return tuples, n_tested


# --------------------------------------------------------------------------------------------
# The FWP
# --------------------------------------------------------------------------------------------


def _span_basis(points: FloatArray, scale: float) -> FloatArray:
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
    k_faces = _check_n_faces(n_faces)
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
        dim = _span_basis(centred, float(np.max(np.abs(centred), initial=0.0))).shape[1]

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


# --------------------------------------------------------------------------------------------
# Gravito-inertial wrench (eq. 14-15)
# --------------------------------------------------------------------------------------------


# --------------------------------------------------------------------------------------------
# Feasibility factor (eq. 21-24)
# --------------------------------------------------------------------------------------------


# Tighter than the region's programs: s is read off directly rather than as a polygon vertex.
_SETTINGS_FAST = solver_settings(robust=False, tol=1e-9, max_iter=200)
_SETTINGS_ROBUST = solver_settings(robust=True, tol=1e-9, max_iter=200)
# Interior-point infeasibility certificates are reliable: not retried (INFEASIBLE).


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


def _gauge_lp(blocks: list[FloatArray], rhs: FloatArray, basis: FloatArray) -> tuple[float, str, float]:
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


def _polar_support_lp(vertices: FloatArray, rhs: FloatArray, basis: FloatArray) -> tuple[float, str]:
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


def _factor(
    blocks: list[FloatArray], rhs: FloatArray, n_equalities_paper: int, dual: bool = False
) -> FeasibilityResult:
    t0 = time.perf_counter()
    centred = np.concatenate(blocks)
    scale = float(np.max(np.abs(centred), initial=0.0))
    basis = _span_basis(centred, scale)
    n_var = centred.shape[0] + 1
    off_span = rhs - basis @ (basis.T @ rhs)
    if np.linalg.norm(off_span) > _SPAN_TOL * max(scale, float(np.linalg.norm(rhs))):
        msg = f"wrench is off the span of the {basis.shape[1]}-dimensional FWP: no contact forces produce it"
        return FeasibilityResult(-math.inf, "ok", time.perf_counter() - t0, n_var, n_equalities_paper, msg)
    if dual and len(blocks) == 1:
        s, msg = _polar_support_lp(blocks[0], rhs, basis)
    else:
        t, msg, _ = _gauge_lp(blocks, rhs, basis)
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


def _residual_lp(blocks: list[FloatArray], w: FloatArray, convex: bool) -> float:
    """Smallest ``||w - sum alpha g||_1`` with alpha >= 0 (and sum_k alpha_ik = 1 per block if convex).

    NaN if the solver fails, which :func:`wrench_violations` reads as "not a member".
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
    if not _residual_lp(wrenches(fwp.cone_edges), wh, convex=False) <= tol:
        out.append("contact")
    if not _residual_lp(wrenches(fwp.actuation_vertices), wh, convex=True) <= tol:
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


# --------------------------------------------------------------------------------------------
# Robot layer
# --------------------------------------------------------------------------------------------


def contact_problem_polytope(
    problem: ContactProblem, n_faces: int = DEFAULT_N_FACES, prune: bool = True
) -> FeasibleWrenchPolytope:
    """:func:`feasible_wrench_polytope` of a state's contacts.

    ``problem`` comes from :func:`~margin_rl.stability.analytic.contact_problem`.
    """
    return feasible_wrench_polytope(
        problem.contact_points,
        problem.normals,
        problem.stance,
        problem.mu,
        problem.jacobians,
        problem.torque_limits,
        problem.leg_bias,
        n_faces=n_faces,
        prune=prune,
    )


def fwp_feasibility(
    robot: Robot, lam: ArrayLike, n_faces: int = DEFAULT_N_FACES, prune: bool = False
) -> FWPFeasibility:
    r"""FWP feasibility factor of one state lambda (the same input as the analytic margin).

    Pipeline: :func:`~margin_rl.stability.analytic.contact_problem` (IK, Jacobians and bias torques in
    H, contact points, statuses) :math:`\to` :func:`feasible_wrench_polytope` :math:`\to`
    :func:`gravito_inertial_wrench` (about the CoM) :math:`\to` ``s`` (eq. 24) :math:`\to` for
    ``s < 0``, :func:`wrench_violations`.

    Unlike the analytic margin, the criterion is instantaneous: the CoM velocity (the ICP) does not
    enter, and friction is the ``n_faces`` pyramid inscribed in the cone (the analytic margin
    defaults to the exact cone). ``s`` is a relative, unitless depth that cannot be compared across
    contact configurations (paper, Sec. IV-B).

    Parameters
    ----------
    robot : Robot
        From :func:`margin_rl.load_robot`.
    lam : (47,) array_like
        lambda (:mod:`margin_rl.stability.lambda_state`).
    n_faces : int
        Faces of the linearised friction cones (>= 3).
    prune : bool
        False (default): eq. (24) on the summands (:func:`minkowski_feasibility_factor`), a few ms.
        True: build the pruned V-description and solve eq. (24) on its vertices, as the paper does
        (same ``s``; ~0.1-0.3 s for 4 contacts); ``n_vertices`` is then reported.

    Returns
    -------
    FWPFeasibility
        Never raises for unreachable feet or missing contacts (statuses, ``s`` NaN).

    Raises
    ------
    ValueError
        Malformed lambda (see :func:`~margin_rl.stability.analytic.contact_problem`) or ``n_faces``.
    """
    t0 = time.perf_counter()
    _check_n_faces(n_faces)
    problem = contact_problem(robot, np.asarray(lam, dtype=np.float64))
    t1 = time.perf_counter()
    nan_wrench = frozen_array(np.full(6, np.nan))
    if not isinstance(problem, ContactProblem):
        status, message, _ = problem
        timings = {"kinematics": t1 - t0, "total": time.perf_counter() - t0}
        return FWPFeasibility(math.nan, status, nan_wrench, (), None, (), timings, message)

    fwp = contact_problem_polytope(problem, n_faces=n_faces, prune=prune)
    wrench = frozen_array(problem.gravito_inertial_wrench())
    t2 = time.perf_counter()
    if prune and fwp.n_vertices > 0:
        res = feasibility_factor(fwp.vertices, wrench, center=fwp.center, length_scale=fwp.length_scale)
    else:
        res = minkowski_feasibility_factor(fwp, wrench)
    t3 = time.perf_counter()
    timings = {"kinematics": t1 - t0, "fwp": t2 - t1, "lp": t3 - t2}
    violated: tuple[str, ...] = ()
    if res.status != "solver_error" and res.s < 0.0:
        violated = wrench_violations(fwp, wrench)
        timings["violations"] = time.perf_counter() - t3
    timings["total"] = time.perf_counter() - t0
    return FWPFeasibility(
        s=res.s,
        status=res.status,
        wrench=wrench,
        violated=violated,
        n_vertices=fwp.n_vertices if prune else None,
        contact_vertex_counts=fwp.contact_vertex_counts,
        timings=timings,
        message=res.message,
        fwp=fwp,
    )
