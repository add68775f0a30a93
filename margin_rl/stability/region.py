r"""Feasible Region of a legged robot by iterative projection (Orsolino et al., Alg. 1).

The Feasible Region :math:`\mathcal{Y}_{fr}` is the set of horizontal CoM positions
:math:`c_{xy}` for which the robot, with its feet where they are and with the given
centroidal accelerations and external wrench, can find contact forces that satisfy the
Newton--Euler equations, the friction constraints and the joint-torque limits.  It is the
projection onto :math:`c_{xy}` of a convex set in :math:`(c_{xy}, f, w)`; we compute it with
the iterative projection of Bretl & Lall, solving one conic program per support direction
with Clarabel.

Frame and variables
-------------------
Everything is expressed in the *horizontal* frame :math:`\mathcal{H}`: origin at the current
CoM, :math:`z` against gravity, :math:`x, y` horizontal.  The candidate CoM is
:math:`c = (c_x, c_y, 0)` (relative to the current CoM); the stance feet stay at
:math:`p_i`, so the moment arms are :math:`p_i - c`.  The decision vector is

.. math:: x = (c_x,\ c_y,\ W_x,\ W_y,\ f_1, \dots, f_n) \in \mathbb{R}^{4 + 3n},

with one 3-D force :math:`f_i` (ground on robot) per stance foot.

Dynamic equilibrium (III.a)
---------------------------
Newton, with :math:`g_{vec} = (0, 0, -g)` and the external force :math:`f_{ext}` applied at
the CoM:

.. math:: m\ddot c = \sum_i f_i + m g_{vec} + f_{ext}
          \;\Rightarrow\; \sum_i f_i = F := m(\ddot c - g_{vec}) - f_{ext}.

Euler about the (fixed) origin :math:`O` of :math:`\mathcal{H}`.  Gravity, inertia and the
external force all act at :math:`c`, the external torque :math:`\tau_{ext}` and the rate of
centroidal angular momentum :math:`\dot L` are free vectors, and the contact torques
:math:`w_i` (see below) are pure moments:

.. math:: \dot L + c \times m\ddot c
          = \sum_i p_i \times f_i + \sum_i w_i + c \times (m g_{vec} + f_{ext}) + \tau_{ext}

.. math:: \Rightarrow\quad \sum_i p_i \times f_i + \sum_i w_i - c \times F = \dot L - \tau_{ext},

and, because :math:`c_z = 0`,

.. math:: c \times F = (c_y F_z,\ -c_x F_z,\ c_x F_y - c_y F_x),

which is linear in :math:`c_{xy}`.  All six rows are kept.  The :math:`z` row couples
:math:`c_{xy}` with the horizontal part of :math:`F`; dropping it (as some implementations do)
changes the region whenever there is horizontal CoM acceleration or external force and
friction is limiting.

Contact torques (III.d, eq. 3)
------------------------------
Each stance foot may exert a small torque :math:`w_i = (w_{ix}, w_{iy}, 0)` about the
horizontal :math:`x, y` axes of :math:`\mathcal{H}` with the box :math:`|w_{ix}|, |w_{iy}| \le
w_M`.  They keep one- and two-contact stances well posed (a region of small positive width
instead of a point or a segment).  Because the :math:`w_i` only appear summed in the moment
rows and their boxes are independent, they are replaced *exactly* by their sum
:math:`W = \sum_i w_i` with :math:`|W_x|, |W_y| \le n\, w_M` (Minkowski sum of boxes), which
saves :math:`2n - 2` variables and :math:`4n - 4` rows.  We express :math:`w_i` in
:math:`\mathcal{H}` rather than in each contact's tangent plane so that this reduction is
exact and the effect of :math:`w_M` is easy to bound.  For a vertical :math:`F` (no horizontal
acceleration or external force), taking moments about the line through two feet shows that a
two-contact region has half-width at most :math:`2\sqrt{2}\, w_M / F_z`; with flat coplanar
feet every region is the same polygon as with :math:`w_M = 0`, grown by :math:`n w_M / F_z`
along x and y (Minkowski sum with that box).

Friction (III.b, eq. 1)
-----------------------
With unit normal :math:`n_i` and an orthonormal tangent basis :math:`t_{i1}, t_{i2}`:

* ``"cone"``: :math:`(\mu n_i^T f_i,\ t_{i1}^T f_i,\ t_{i2}^T f_i) \in` second-order cone
  (exact eq. 1; it implies :math:`n_i^T f_i \ge 0`).
* ``("pyramid", k)``: :math:`d_j^T f_i \le \mu\cos(\pi/k)\, n_i^T f_i` for the :math:`k`
  unit directions :math:`d_j = \cos(2\pi j/k) t_{i1} + \sin(2\pi j/k) t_{i2}`, plus
  :math:`n_i^T f_i \ge 0`.  The regular :math:`k`-gon with apothem :math:`\mu\cos(\pi/k)`
  is inscribed in the circle of radius :math:`\mu`, so the pyramid is inside the cone and the
  resulting region is inside the cone region.

Force polytope (III.c, eq. 2)
-----------------------------
With the bias torques :math:`\delta_i` (gravity, Coriolis and inertial terms of the leg
dynamics, computed outside), the joint torques needed are
:math:`\tau_i = \delta_i - J_i^T f_i`, and :math:`\underline\tau_i \le \tau_i \le
\bar\tau_i` gives the linear rows :math:`J_i^T f_i \le \delta_i - \underline\tau_i` and
:math:`-J_i^T f_i \le \bar\tau_i - \delta_i` (rows with an infinite bound are dropped).

Clipping box
------------
:math:`|c_x|, |c_y| \le` ``extent`` keeps every LP bounded (e.g. in free fall, where
:math:`F = 0` and :math:`c` drops out of the equations).  A region that touches the box is
reported with status ``"unbounded"``.

Iterative projection (Alg. 1)
-----------------------------
For a unit direction :math:`a_j` the conic program maximises :math:`a_j^T c_{xy}` (Clarabel
minimises :math:`q^T x` with :math:`q = -a_j` on the :math:`c` entries).  The problem data are
built once per call and only :math:`q` is updated between directions.  The inner
approximation is the convex hull of the optimal points, the outer one the intersection of the
half-planes :math:`a_j^T c \le a_j^T c^*_j`.  Between two angularly consecutive directions the
outer polygon exceeds the inner one by a triangle ("cap") on the inner edge; the next
direction is the outward normal of the inner edge with the largest cap.  Iterations stop when
the total cap area :math:`area(outer) - area(inner) \le` ``tol`` or after ``max_lps`` programs.
The four first directions are the diagonals (each hits a corner of an axis-aligned rectangle).
An interior-point solver returns a point inside an optimal *face* (e.g. the middle of an edge)
rather than a vertex; such points are harmless (their cap areas are zero) and are removed, with
near-duplicates, when the CCW vertex list is built.

Solver
------
Clarabel (interior point) with tolerances 1e-8, presolve off and iterative refinement off
(about 1/3 faster on these tiny problems, with support values unchanged to < 1e-9 m in our
tests).  A direction whose solve ends in anything but Solved or (Almost)PrimalInfeasible
(AlmostSolved included: it only meets reduced tolerances) is retried once with a second solver
that has iterative refinement on; if that fails too, its cap is left unrefined and
``converged`` is False.  An infeasible first program means the region is empty (infeasibility
does not depend on the direction).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DEFAULT_CONTACT_TORQUE_LIMIT",
    "DEFAULT_EXTENT",
    "DEFAULT_MAX_LPS",
    "DEFAULT_TOL",
    "SUPPORT_FAILED",
    "SUPPORT_INFEASIBLE",
    "SUPPORT_OK",
    "FeasibleRegion",
    "ProjectionResult",
    "feasible_region",
    "halfspaces_from_polygon",
    "iterative_projection",
    "polygon_area",
]

#: Default stopping tolerance ``area(outer) - area(inner)`` [m^2].  Chosen from a study on random
#: 30 kg quadruped states (tilted normals, accelerations, external wrench, cone friction; see the
#: benchmark): against a reference with tol = 1e-7, 5e-4 m^2 gives a boundary (Hausdorff) error of
#: ~1.7 mm median / 2.8 mm 95th percentile and an inside-margin error <= 1.5 mm with ~20 programs
#: for 4 contacts and ~12 for 3; 1e-4 m^2 cuts the error ~3x for ~40 % more programs.  Polygonal
#: regions (pyramids, or cones that never bind) reach a zero gap after ~2 programs per vertex.
DEFAULT_TOL: float = 5e-4
#: Default cap on the number of conic programs per call (the initial 4 included); the study above
#: never needed more than 27 at the default tol.
DEFAULT_MAX_LPS: int = 40
#: Default width [m] of the signed-distance bracket at which a focused projection stops
#: (``feasible_region(focus=...)``): the margin of the focus point is then known to 0.5 mm.
DEFAULT_FOCUS_TOL: float = 5e-4
#: Default w_M of eq. (3) [N m].  The paper lets w_M -> 0; 0.01 N m changes the region of a
#: 30 kg robot by at most n * 0.01 / 294 m ~ 0.1 mm (4 feet) and gives a two-contact region a
#: half-width <= 2 sqrt(2) * 0.01 / 294 m ~ 0.1 mm, while keeping it full-dimensional.
DEFAULT_CONTACT_TORQUE_LIMIT: float = 1e-2
#: Default half-size of the clipping box on c_xy [m]; far beyond any leg's reach.
DEFAULT_EXTENT: float = 10.0

# Outcomes of one support-function evaluation in :func:`iterative_projection`.
SUPPORT_OK: int = 0
SUPPORT_INFEASIBLE: int = 1
SUPPORT_FAILED: int = 2

# Points closer than this [m] are merged, and a vertex closer than _COLLINEAR_TOL [m] to the chord
# of its neighbours is dropped, so that noise from the interior-point solver (~1e-9 m) never
# produces a tiny edge whose normal would be meaningless.
_MERGE_TOL: float = 1e-6
_COLLINEAR_TOL: float = 1e-8
# A vertex within this distance [m] of the clipping box marks the region "unbounded".
_BOX_TOL: float = 1e-6

# The four initial directions are the diagonals: for an axis-aligned rectangular support
# polygon (the common quadruped case in the yaw frame) each one hits a corner exactly, while
# axis directions would hit whole edges and return their midpoints.
_INITIAL_ANGLES: tuple[float, ...] = tuple(math.pi / 4 + k * math.pi / 2 for k in range(4))

# AlmostSolved is *not* accepted: it meets only the reduced tolerances (5e-5 on the gap), and a
# point that far from optimal along a nearly flat face breaks the angular order of the support
# points; such directions are retried with the robust solver instead.
_SOLVED = (clarabel.SolverStatus.Solved,)
_INFEASIBLE = (clarabel.SolverStatus.PrimalInfeasible, clarabel.SolverStatus.AlmostPrimalInfeasible)

FloatArray = NDArray[np.float64]


def _frozen(a: ArrayLike, dtype: Any = np.float64) -> Any:
    """A read-only copy (results are frozen dataclasses; their arrays must not change either)."""
    out = np.array(a, dtype=dtype)
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class FeasibleRegion:
    """Result of :func:`feasible_region` (arrays are read-only).

    Attributes
    ----------
    vertices : (m, 2) ndarray
        Counter-clockwise vertices [m] of the inner approximation, in the x-y plane of frame H
        (current CoM at the origin), without duplicates or collinear points.  ``m`` is 0 for an
        empty region, 1 for a single point and 2 for a segment (only possible with
        ``contact_torque_limit == 0``).
    halfspaces : (h, 3) ndarray
        Rows ``[n_x, n_y, a]`` with inward unit normals: ``n . p - a >= 0`` inside (eq. 6).
        One row per edge (``h == m``) for a polygon; a segment gets its two sides and two end
        caps and a point four axis-aligned rows (so eq. 7 gives minus the distance along the
        worst axis); empty region: ``h == 0``.
    status : str
        ``"ok"``: a non-empty region (check ``converged`` for its accuracy);
        ``"unbounded"``: the region reaches the clipping box (vertices are those of the clipped
        region); ``"empty"``: no equilibrium is possible (infeasible program, or no stance
        foot); ``"solver_error"``: no direction could be solved.
    converged : bool
        ``gap <= tol``.  False when ``max_lps`` stopped the projection first, or when a
        direction's program failed (twice) and its cap was left unrefined; the vertices are then
        still feasible CoM positions, only the approximation is coarser (see ``message``).
    n_lps : int
        Number of conic programs solved (a retried direction counts twice).
    solve_time : float
        Wall-clock time of the whole call [s] (validation, set-up and all programs).
    area : float
        Area of the inner polygon [m^2].
    gap : float
        ``area(outer) - area(inner)`` at termination [m^2] (``nan`` if empty).
    message : str
        Human-readable detail when ``status != "ok"`` or not ``converged``.
    margin_bounds : (float, float) or None
        With ``focus``: lower and upper bounds [m] on the focus point's signed distance to the
        true region (from the inner and outer approximations); ``None`` otherwise.
    """

    vertices: FloatArray
    halfspaces: FloatArray
    status: str
    converged: bool
    n_lps: int
    solve_time: float
    area: float
    gap: float
    message: str = ""
    margin_bounds: tuple[float, float] | None = None

    @property
    def usable(self) -> bool:
        """True when ``vertices``/``halfspaces`` describe a non-empty region."""
        return self.vertices.shape[0] > 0


@dataclass(frozen=True)
class ProjectionResult:
    """Result of :func:`iterative_projection`.

    Attributes
    ----------
    points : (N, 2) ndarray
        Support points, one per successful direction, in increasing direction angle (CCW).
    angles : (N,) ndarray
        Direction angles [rad] of ``points``.
    gap : float
        Total cap area ``area(outer) - area(inner)`` at termination, caps whose refining
        direction failed included (the loop itself stops once the other caps are within
        ``tol``).
    n_evals : int
        Number of support evaluations.
    status : str
        ``"ok"``, ``"max_lps"``, ``"inaccurate"``, ``"empty"`` or ``"solver_error"``.
    margin_bounds : (float, float)
        With a focus point: the signed distances [m] of the focus to the inner and to the outer
        polygon, which bracket its signed distance to the true set; ``(nan, nan)`` otherwise.
    """

    points: FloatArray
    angles: FloatArray
    gap: float
    n_evals: int
    status: str
    margin_bounds: tuple[float, float] = (math.nan, math.nan)


# --------------------------------------------------------------------------------------------
# Planar geometry (pure Python floats: the polygons have tens of vertices at most)
# --------------------------------------------------------------------------------------------


def _cap_area(t1: float, x1: float, y1: float, t2: float, x2: float, y2: float) -> float:
    r"""Area of the outer "cap" triangle over the inner edge from point 1 to point 2.

    Point :math:`k` maximises :math:`a_k^T c` with :math:`a_k = (\cos t_k, \sin t_k)` and
    :math:`0 < t_2 - t_1`.  With :math:`e = p_2 - p_1`, its outward normal :math:`\nu = (e_y,
    -e_x)` (both of length :math:`\ell`), :math:`S_k = a_k^T e` and :math:`C_k = a_k^T \nu`, the
    apex of the triangle bounded by the two support lines has height :math:`\ell |S_1| S_2 /
    (C_1 S_2 + C_2 |S_1|)` over the edge, and :math:`C_1 S_2 + C_2 |S_1| = \ell^2 \sin(t_2 -
    t_1)`.  Hence :math:`A = \ell^2 |S_1| S_2 / (2 \ell^2 \sin(t_2 - t_1))`.
    """
    ex = x2 - x1
    ey = y2 - y1
    l2 = ex * ex + ey * ey
    if l2 <= _MERGE_TOL * _MERGE_TOL:
        return 0.0
    s1 = -(math.cos(t1) * ex + math.sin(t1) * ey)  # >= 0 up to solver noise: p1 maximises a1
    s2 = math.cos(t2) * ex + math.sin(t2) * ey  # >= 0 up to solver noise: p2 maximises a2
    if s1 <= 0.0 or s2 <= 0.0:
        return 0.0
    dt = t2 - t1
    if dt >= math.pi - 1e-12:
        return math.inf  # the two support lines do not close the cap
    sin_dt = math.sin(dt)
    if sin_dt <= 0.0:
        return 0.0
    return s1 * s2 / (2.0 * sin_dt)


def _segment_distance(px: float, py: float, x1: float, y1: float, x2: float, y2: float) -> float:
    """Euclidean distance from (px, py) to the segment (x1, y1)-(x2, y2)."""
    ex, ey = x2 - x1, y2 - y1
    l2 = ex * ex + ey * ey
    t = 0.0 if l2 <= 0.0 else min(1.0, max(0.0, ((px - x1) * ex + (py - y1) * ey) / l2))
    return math.hypot(x1 + t * ex - px, y1 + t * ey - py)


def _cap_distance_bounds(
    t1: float, x1: float, y1: float, t2: float, x2: float, y2: float, fx: float, fy: float
) -> tuple[float, float]:
    r"""Distances from the focus f to the two boundaries of one cap: ``(inner, outer)`` [m].

    The true set's boundary between support points 1 and 2 lies in the cap triangle bounded by the
    inner edge p1-p2 and the two support lines :math:`a_k^T c = a_k^T p_k`, which meet at the apex
    :math:`c^*` solving :math:`[a_1; a_2] c^* = [a_1^T p_1; a_2^T p_2]` (determinant
    :math:`\sin(t_2 - t_1)`). ``inner`` is the distance to the segment p1-p2, ``outer`` the distance
    to the polyline p1-c*-p2 (the outer polygon's boundary there); ``inf`` for an open cap.
    """
    inner = _segment_distance(fx, fy, x1, y1, x2, y2)
    dt = t2 - t1
    if dt >= math.pi - 1e-12:
        return inner, math.inf
    det = math.sin(dt)
    c1, s1, c2, s2 = math.cos(t1), math.sin(t1), math.cos(t2), math.sin(t2)
    h1, h2 = c1 * x1 + s1 * y1, c2 * x2 + s2 * y2
    if det <= 1e-6:
        # Nearly parallel support lines: the apex is ill-conditioned and the cap negligibly thin.
        return inner, inner
    ax, ay = (h1 * s2 - h2 * s1) / det, (c1 * h2 - c2 * h1) / det
    outer = min(_segment_distance(fx, fy, x1, y1, ax, ay), _segment_distance(fx, fy, ax, ay, x2, y2))
    return inner, outer


def _cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _convex_polygon(points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """CCW convex polygon of the support points, without near-duplicate or collinear vertices.

    First the exact convex hull (Andrew's monotone chain with a strict turn test, so it does
    not depend on the order of the points); then, on that convex polygon, vertices closer than
    ``_MERGE_TOL`` to their predecessor are merged and vertices closer than ``_COLLINEAR_TOL`` to
    the chord of their neighbours are dropped (removing a vertex of a convex polygon keeps it
    convex).  Tolerances are applied only after the hull: inside the chain, noise of 1e-11 m
    in x scrambles the order of points on a vertical edge and a tolerant turn test can then
    drop a true corner.  Returns 1 point or 2 (a segment) for degenerate sets.
    """
    pts = sorted(set(points))
    if len(pts) <= 2:
        hull = pts
    else:
        lower: list[tuple[float, float]] = []
        for p in pts:
            while len(lower) >= 2 and _cross(lower[-2], lower[-1], p) <= 0.0:
                lower.pop()
            lower.append(p)
        upper: list[tuple[float, float]] = []
        for p in reversed(pts):
            while len(upper) >= 2 and _cross(upper[-2], upper[-1], p) <= 0.0:
                upper.pop()
            upper.append(p)
        hull = lower[:-1] + upper[:-1]
    out: list[tuple[float, float]] = []
    for p in hull:
        if not out or math.hypot(p[0] - out[-1][0], p[1] - out[-1][1]) > _MERGE_TOL:
            out.append(p)
    while len(out) > 1 and math.hypot(out[0][0] - out[-1][0], out[0][1] - out[-1][1]) <= _MERGE_TOL:
        out.pop()
    i = 0
    stable = 0  # consecutive vertices checked without a removal
    while len(out) >= 3 and stable < len(out):
        i %= len(out)
        o, a, b = out[i - 1], out[i], out[(i + 1) % len(out)]
        if _cross(o, a, b) > _COLLINEAR_TOL * math.hypot(b[0] - o[0], b[1] - o[1]):
            i += 1
            stable += 1
        else:
            del out[i]
            stable = 0
    if len(out) >= 3:
        return out
    # Degenerate (a segment or a point up to the tolerances): the farthest pair of all points,
    # since the deletions above may have kept interior points of the segment.
    best = (-1.0, pts[0], pts[0])
    for j, p in enumerate(pts):
        for q in pts[j + 1 :]:
            d = math.hypot(p[0] - q[0], p[1] - q[1])
            if d > best[0]:
                best = (d, p, q)
    return [best[1]] if best[0] <= _MERGE_TOL else [best[1], best[2]]


def _shoelace(pts: Sequence[tuple[float, float]]) -> float:
    """Signed area of a polygon given as a list of (x, y) tuples (pure Python: tiny inputs)."""
    if len(pts) < 3:
        return 0.0
    acc = 0.0
    x0, y0 = pts[-1]
    for x1, y1 in pts:
        acc += x0 * y1 - x1 * y0
        x0, y0 = x1, y1
    return 0.5 * acc


def polygon_area(vertices: ArrayLike) -> float:
    """Signed area (shoelace) [m^2] of a polygon given as (m, 2) vertices; positive if CCW."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.shape[0] < 3:
        return 0.0
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def halfspaces_from_polygon(vertices: ArrayLike) -> FloatArray:
    """Half-space rows ``[n_x, n_y, a]`` (inward unit normals, ``n . p - a >= 0`` inside).

    Parameters
    ----------
    vertices : (m, 2) array_like
        CCW vertices of a convex polygon [m], as in :attr:`FeasibleRegion.vertices`.  Degenerate
        inputs: ``m == 2`` (segment) gives the two sides plus the two end caps; ``m == 1``
        (point) gives four axis-aligned rows; ``m == 0`` gives an empty (0, 3) array.

    Returns
    -------
    (h, 3) ndarray
    """
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 2)
    m = v.shape[0]
    if m == 0:
        return np.zeros((0, 3))
    if m == 1:
        normals = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
        return np.column_stack([normals, normals @ v[0]])
    if m == 2:
        d = v[1] - v[0]
        d = d / np.linalg.norm(d)
        left = np.array([-d[1], d[0]])
        normals = np.array([left, -left, d, -d])
        anchors = np.array([v[0], v[0], v[0], v[1]])
        return np.column_stack([normals, np.einsum("ij,ij->i", normals, anchors)])
    # Edge vectors v[i+1] - v[i] (cyclic), without np.roll's overhead.
    e = np.empty_like(v)
    np.subtract(v[1:], v[:-1], out=e[:-1])
    np.subtract(v[0], v[-1], out=e[-1])
    inward = np.empty_like(v)  # left of a CCW edge is inside
    inward[:, 0], inward[:, 1] = -e[:, 1], e[:, 0]
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    out = np.empty((m, 3))
    out[:, :2] = inward
    out[:, 2] = np.einsum("ij,ij->i", inward, v)
    return out


def iterative_projection(
    support: Callable[[float, float], tuple[int, float, float]],
    tol: float = DEFAULT_TOL,
    max_evals: int = DEFAULT_MAX_LPS,
    focus: tuple[float, float] | None = None,
    focus_tol: float = DEFAULT_FOCUS_TOL,
) -> ProjectionResult:
    r"""Bretl & Lall iterative projection of a compact convex planar set given its support oracle.

    Parameters
    ----------
    support : callable ``(a_x, a_y) -> (code, x, y)``
        Returns a point ``(x, y)`` of the set maximising ``a_x x + a_y y`` for the unit
        direction ``a``, with ``code`` :data:`SUPPORT_OK`; :data:`SUPPORT_INFEASIBLE` if the
        set is empty (the projection stops) or :data:`SUPPORT_FAILED` if this direction could
        not be evaluated (it is skipped).
    tol : float
        Stop when ``area(outer) - area(inner) <= tol`` [m^2].
    max_evals : int
        Maximum number of oracle calls (>= 4: the four diagonal directions come first).
    focus : (float, float), optional
        Refine only where it matters for the signed distance of this point to the set. The inner
        polygon P_in and the outer polygon P_out bracket the set S, P_in ⊆ S ⊆ P_out, and the
        signed distance sd (positive inside) is monotone under inclusion, so
        sd(f, P_in) <= sd(f, S) <= sd(f, P_out). Each step refines the cap that limits this
        bracket (the cap nearest to f) and the loop stops once the bracket is within
        ``focus_tol``; ``tol`` is then not used. This typically needs a fraction of the programs
        of a uniformly accurate region (see the analytic-margin benchmark).
    focus_tol : float
        Width of the signed-distance bracket at which a focused projection stops [m].

    Returns
    -------
    ProjectionResult
        Support points in CCW order of their directions (duplicates possible; use a convex hull
        to get vertices).
    """
    angles: list[float] = []
    xs: list[float] = []
    ys: list[float] = []
    n_evals = 0
    failed = False
    for t in _INITIAL_ANGLES:
        n_evals += 1
        code, x, y = support(math.cos(t), math.sin(t))
        if code == SUPPORT_INFEASIBLE:
            return ProjectionResult(np.zeros((0, 2)), np.zeros(0), math.nan, n_evals, "empty")
        if code == SUPPORT_OK:
            angles.append(t)
            xs.append(x)
            ys.append(y)
        else:
            failed = True
    if not angles:
        return ProjectionResult(np.zeros((0, 2)), np.zeros(0), math.nan, n_evals, "solver_error")

    def cap(k: int) -> float:
        if len(angles) == 1:
            return 0.0
        k2 = (k + 1) % len(angles)
        t2 = angles[k2] if k2 > k else angles[k2] + 2.0 * math.pi
        return _cap_area(angles[k], xs[k], ys[k], t2, xs[k2], ys[k2])

    caps = [cap(k) for k in range(len(angles))]
    if focus is not None:
        return _focused_projection(support, angles, xs, ys, caps, n_evals, failed, max_evals, focus, focus_tol, cap)
    # A cap whose refining direction failed is frozen: its area moves to `frozen_gap` and its
    # slot is zeroed so that it is never selected again (its two points never change).
    frozen_gap = 0.0
    status = "ok"
    while True:
        active = sum(caps)
        if active <= tol:
            break
        if n_evals >= max_evals:
            status = "max_lps"
            break
        k = caps.index(max(caps))
        code, x, y, t_new, evals = _refine_cap(support, angles, xs, ys, k)
        n_evals += evals
        if code != SUPPORT_OK:
            # (Infeasible cannot happen for a non-empty set: a numerical failure as well.)
            failed = True
            frozen_gap += caps[k]
            caps[k] = 0.0
            continue
        # Inserting after k keeps `angles` increasing within [angles[0], angles[0] + 2 pi).
        pos = k + 1
        angles.insert(pos, t_new)
        xs.insert(pos, x)
        ys.insert(pos, y)
        caps.insert(pos, 0.0)
        caps[k] = cap(k)
        caps[pos] = cap(pos)
    if failed and status == "ok":
        status = "inaccurate"
    pts = np.column_stack([np.asarray(xs), np.asarray(ys)])
    return ProjectionResult(pts, np.asarray(angles), float(sum(caps) + frozen_gap), n_evals, status)


def _next_direction(angles: list[float], xs: list[float], ys: list[float], k: int) -> float:
    """Refining direction [rad] for cap k: the outward normal of its inner edge p_k -> p_k+1.

    Points are CCW, so outward is on the right. If solver noise pushed that normal outside the
    cap's wedge of support directions, or the cap is open (wedge >= pi), the wedge is bisected.
    """
    k2 = (k + 1) % len(angles)
    t1 = angles[k]
    t2 = angles[k2] if k2 > k else angles[k2] + 2.0 * math.pi
    t_new = math.atan2(xs[k] - xs[k2], ys[k2] - ys[k])
    t_new = t1 + (t_new - t1) % (2.0 * math.pi)
    if not (t1 < t_new < t2) or t2 - t1 >= math.pi:
        t_new = 0.5 * (t1 + t2)
    return t_new


def _refine_cap(
    support: Callable[[float, float], tuple[int, float, float]],
    angles: list[float],
    xs: list[float],
    ys: list[float],
    k: int,
) -> tuple[int, float, float, float, int]:
    """Support point for refining cap k: ``(code, x, y, direction used, programs solved)``.

    The edge's outward normal first; if its program fails (e.g. Clarabel stops at AlmostSolved,
    which is not accepted), once more along the bisector of the cap's wedge. Any direction strictly
    inside the wedge yields a valid support point of the same cap, so the cap is only given up
    (frozen) when both fail.
    """
    t_new = _next_direction(angles, xs, ys, k)
    code, x, y = support(math.cos(t_new), math.sin(t_new))
    if code != SUPPORT_FAILED:
        return code, x, y, t_new, 1
    k2 = (k + 1) % len(angles)
    t1 = angles[k]
    t2 = angles[k2] if k2 > k else angles[k2] + 2.0 * math.pi
    t_mid = 0.5 * (t1 + t2)
    if abs(t_mid - t_new) < 1e-9:
        return code, x, y, t_new, 1
    code, x, y = support(math.cos(t_mid), math.sin(t_mid))
    return code, x, y, t_mid, 2


def _focused_projection(
    support: Callable[[float, float], tuple[int, float, float]],
    angles: list[float],
    xs: list[float],
    ys: list[float],
    caps: list[float],
    n_evals: int,
    failed: bool,
    max_evals: int,
    focus: tuple[float, float],
    focus_tol: float,
    cap: Callable[[int], float],
) -> ProjectionResult:
    """The focused branch of :func:`iterative_projection` (see its ``focus`` parameter)."""
    fx, fy = float(focus[0]), float(focus[1])

    def bounds(k: int) -> tuple[float, float]:
        k2 = (k + 1) % len(angles)
        t2 = angles[k2] if k2 > k else angles[k2] + 2.0 * math.pi
        if len(angles) == 1:
            d = math.hypot(xs[0] - fx, ys[0] - fy)
            return d, math.inf
        return _cap_distance_bounds(angles[k], xs[k], ys[k], t2, xs[k2], ys[k2], fx, fy)

    lo_hi = [bounds(k) for k in range(len(angles))]
    frozen = [False] * len(angles)
    # Support-line offsets h_k = max over all found (feasible) points of a_k . p: the solver's own
    # point can fall short of the optimum by ~1e-5 m, and taking the max keeps P_in inside P_out.
    dirs = [(math.cos(t), math.sin(t)) for t in angles]
    offsets = [max(cx * x + sy * y for x, y in zip(xs, ys, strict=True)) for cx, sy in dirs]
    status = "ok"
    sd_in = sd_out = math.nan
    while True:
        # Sign of the bracket ends: inside P_in iff left of every inner edge (CCW), inside P_out
        # iff on the inner side of every support line.
        m = len(angles)
        inside_in = m >= 3 and all(
            (xs[(k + 1) % m] - xs[k]) * (fy - ys[k]) - (ys[(k + 1) % m] - ys[k]) * (fx - xs[k]) >= 0.0 for k in range(m)
        )
        # Slack of the focus w.r.t. each support line a_k . c <= a_k . p_k.
        slack = min(h - cx * fx - sy * fy for (cx, sy), h in zip(dirs, offsets, strict=True))
        lo = min(b[0] for b in lo_hi)
        sd_in = lo if inside_in else -lo
        # Inside P_out its boundary distance is the smallest line slack (no apex needed, so no
        # ill-conditioned intersection of nearly parallel lines); outside, the distance to P_out's
        # boundary polylines through the cap apexes.
        sd_out = slack if slack >= 0.0 else -min(b[1] for b in lo_hi)
        if sd_out - sd_in <= focus_tol:
            break
        if n_evals >= max_evals:
            status = "max_lps"
            break
        # Refine the cap nearest to the focus among those whose boundary is still uncertain (inner
        # and outer distances differ; which one is larger depends on the side the focus is on).
        candidates = [k for k in range(m) if not frozen[k] and abs(lo_hi[k][1] - lo_hi[k][0]) > 0.05 * focus_tol]
        if not candidates:
            break
        k = min(candidates, key=lambda k: min(lo_hi[k]))
        code, x, y, t_new, evals = _refine_cap(support, angles, xs, ys, k)
        n_evals += evals
        if code != SUPPORT_OK:
            failed = True
            frozen[k] = True
            continue
        pos = k + 1
        angles.insert(pos, t_new)
        xs.insert(pos, x)
        ys.insert(pos, y)
        caps.insert(pos, 0.0)
        frozen.insert(pos, False)
        new_dir = (math.cos(t_new), math.sin(t_new))
        offsets = [max(h, cx * x + sy * y) for (cx, sy), h in zip(dirs, offsets, strict=True)]
        dirs.insert(pos, new_dir)
        offsets.insert(pos, max(new_dir[0] * px + new_dir[1] * py for px, py in zip(xs, ys, strict=True)))
        lo_hi.insert(pos, (0.0, 0.0))
        caps[k], caps[pos] = cap(k), cap(pos)
        lo_hi[k], lo_hi[pos] = bounds(k), bounds(pos)
    if failed and status == "ok":
        status = "inaccurate"
    pts = np.column_stack([np.asarray(xs), np.asarray(ys)])
    return ProjectionResult(pts, np.asarray(angles), float(sum(caps)), n_evals, status, (sd_in, sd_out))


# --------------------------------------------------------------------------------------------
# Input validation
# --------------------------------------------------------------------------------------------


def _as_array(name: str, value: ArrayLike, shape: tuple[int, ...]) -> FloatArray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {shape}") from exc
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    return arr


def _as_rows(name: str, value: ArrayLike, columns: int, rows: str = "n", min_rows: int = 0) -> FloatArray:
    """A (rows, columns) float array with at least ``min_rows`` rows; the message names ``name``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric ({rows}, {columns}) array") from exc
    if arr.ndim != 2 or arr.shape[1] != columns or arr.shape[0] < min_rows:
        at_least = f" with {rows} >= {min_rows}" if min_rows else ""
        raise ValueError(f"{name} must have shape ({rows}, {columns}){at_least}, got {np.shape(arr)}")
    return arr


def _check_finite(name: str, arr: FloatArray) -> None:
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite (no NaN/inf)")


def _positive_scalar(name: str, value: float, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real number") from exc
    if not math.isfinite(v) or v < 0.0 or (v == 0.0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {bound}, got {value!r}")
    return v


def _parse_friction(friction: Any) -> int:
    """Return 0 for the exact cone, else the number of pyramid faces (>= 3)."""
    if isinstance(friction, str):
        if friction == "cone":
            return 0
        raise ValueError(f"friction must be 'cone' or ('pyramid', k), got {friction!r}")
    if (
        isinstance(friction, (tuple, list))
        and len(friction) == 2
        and friction[0] == "pyramid"
        and isinstance(friction[1], (int, np.integer))
        and not isinstance(friction[1], bool)
        and friction[1] >= 3
    ):
        return int(friction[1])
    raise ValueError(f"friction must be 'cone' or ('pyramid', k) with integer k >= 3, got {friction!r}")


def _torque_bounds(torque_limits: Any, n: int, k: int, idx: NDArray[np.intp]) -> tuple[FloatArray, FloatArray]:
    """(lower, upper) bounds of the stance legs ``idx``; rows of swing legs are not inspected."""
    try:
        arr = np.asarray(torque_limits, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError("torque_limits must be an (n, k) array or a (lower, upper) pair") from exc
    if arr.ndim == 3:
        if arr.shape != (2, n, k):
            raise ValueError(
                f"torque_limits as a (lower, upper) pair must be two ({n}, {k}) arrays matching "
                f"jacobians (n, 3, k), got {arr.shape[1:]}"
            )
        lo, hi = arr[0][idx], arr[1][idx]
    elif arr.ndim == 2:
        if arr.shape != (n, k):
            raise ValueError(f"torque_limits must have shape ({n}, {k}) matching jacobians (n, 3, k), got {arr.shape}")
        lim = arr[idx]
        if (lim < 0.0).any():
            raise ValueError("torque_limits (symmetric) must be >= 0")
        lo, hi = -lim, lim
    else:
        raise ValueError("torque_limits must be an (n, k) array or a (lower, upper) pair of (n, k) arrays")
    if np.isnan(lo).any() or np.isnan(hi).any():
        raise ValueError("torque_limits must not contain NaN")
    if (lo == np.inf).any() or (hi == -np.inf).any():
        raise ValueError("torque_limits: lower must be < +inf and upper > -inf")
    if (lo > hi).any():
        raise ValueError("torque_limits: lower > upper for some joint")
    return lo, hi


def _tangent_bases(normals: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Orthonormal tangents t1, t2, each (n, 3), with (t1, t2, n) right-handed.

    t1 is the projection of the x axis on the tangent plane (of y when the normal is nearly
    along x), so for flat ground t1 = x, t2 = y and a mirror y -> -y maps the basis to itself up
    to the sign of t2 (which leaves the pyramid's set of face directions unchanged).
    """
    nx, ny, nz = normals[:, 0], normals[:, 1], normals[:, 2]
    use_x = np.abs(nx) < 0.9
    # t1 = ref - n (n . ref) with ref = x (or y), normalised.
    dot = np.where(use_x, nx, ny)
    t1 = -normals * dot[:, None]
    t1[:, 0] += use_x
    t1[:, 1] += ~use_x
    t1 /= np.sqrt(np.einsum("ij,ij->i", t1, t1))[:, None]
    # t2 = n x t1, written out (np.cross has a large fixed overhead on tiny arrays).
    ax, ay, az = t1[:, 0], t1[:, 1], t1[:, 2]
    t2 = np.empty_like(t1)
    t2[:, 0], t2[:, 1], t2[:, 2] = ny * az - nz * ay, nz * ax - nx * az, nx * ay - ny * ax
    return t1, t2


# --------------------------------------------------------------------------------------------
# The conic program
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Problem:
    A: sp.csc_matrix
    b: FloatArray
    cones: list[Any]
    n_var: int


@functools.lru_cache(maxsize=64)
def _block_diag_index(n: int, r: int, row0: int = 0) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices ``(rows, cols)``, shapes (n, r, 1) and (n, 1, 3), that place n per-foot (r, 3) blocks on
    the diagonal of the force columns (4 + 3 i ...) from row ``row0`` on; cached, read-only."""
    rows = row0 + np.arange(n * r).reshape(n, r, 1)
    cols = 4 + 3 * np.arange(n).reshape(n, 1, 1) + np.arange(3).reshape(1, 1, 3)
    rows.flags.writeable = cols.flags.writeable = False
    return rows, cols


def _block_diag(blocks: FloatArray) -> FloatArray:
    """(n, r, 3) per-foot blocks -> (n r, 4 + 3 n) rows acting block-diagonally on (f_1, ..., f_n).

    The first 4 (zero) columns are those of (c_x, c_y, W_x, W_y).
    """
    n, r, _ = blocks.shape
    out = np.zeros((n * r, 4 + 3 * n))
    rows, cols = _block_diag_index(n, r)
    out[rows, cols] = blocks
    return out


def _dense_to_csc(a: FloatArray) -> sp.csc_matrix:
    """CSC matrix of the non-zero entries of a dense matrix, in CSC order (columns, then rows).

    The same arrays as ``sp.csc_matrix(dense)`` (explicit zeros dropped, rows sorted), about 2x faster
    for these tiny matrices; fastest when ``a`` is Fortran-ordered (its column-major ravel is then a
    view). Indices are int32, which spares scipy's constructor a downcast.
    """
    m, n = a.shape
    flat = a.ravel(order="F")
    nz = np.flatnonzero(flat)
    indptr = np.searchsorted(nz, np.arange(n + 1) * m).astype(np.int32)  # first entry of each column
    return sp.csc_matrix((flat[nz], (nz % m).astype(np.int32), indptr), shape=(m, n))


_BOX = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
# Row offsets of the blocks of A: 6 Newton-Euler equalities, then 4 clipping-box rows on c and 4
# rows |W| <= n w_M, then the torque and friction rows.
_N_EQ: int = 6
_ROW_TORQUE: int = _N_EQ + 8


def _fill_equilibrium(a: FloatArray, b: FloatArray, feet: FloatArray, force: FloatArray, moment: FloatArray) -> None:
    """Rows 0-5 of ``A x + s = b`` (s = 0): Newton  sum_i f_i = F,  Euler  sum_i p_i x f_i + W - c x F = M,
    with ``force`` F [N] and ``moment`` M = L_dot - tau_ext [N m] (module docstring).

    With c = (c_x, c_y, 0): -(c x F) = (-c_y F_z, c_x F_z, -(c_x F_y - c_y F_x)). Column 4 + 3 i + j
    holds component j of f_i, so row 3 gets (p_i x f_i)_x = p_y f_z - p_z f_y as -p_z at f_y and p_y
    at f_z, and so on.
    """
    fx, fy, fz = force
    a[0, 4::3] = a[1, 5::3] = a[2, 6::3] = 1.0  # sum_i f_i
    a[3, 1] = -fz
    a[4, 0] = fz
    a[5, 0] = -fy
    a[5, 1] = fx
    a[3, 2] = a[4, 3] = 1.0  # W_x, W_y
    px, py, pz = feet[:, 0], feet[:, 1], feet[:, 2]
    a[3, 5::3], a[3, 6::3] = -pz, py
    a[4, 4::3], a[4, 6::3] = pz, -px
    a[5, 4::3], a[5, 5::3] = -py, px
    b[0:3] = force
    b[3:6] = moment


def _build_problem(
    feet: FloatArray,
    normals: FloatArray,
    mu: float,
    jac: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    bias: FloatArray,
    force: FloatArray,
    moment: FloatArray,
    n_faces: int,
    w_max: float,
    extent: float,
) -> _Problem:
    """Assemble ``A x + s = b`` with ``s`` in Zero(6) x NonNeg(.) [x SOC(3)^n] (stance feet only).

    Row blocks: 6 Newton-Euler equalities; 4 clipping-box rows on c; 4 rows |W| <= n w_M;
    2 k torque rows per foot (finite bounds only); then the friction rows, per foot either
    k_p + 1 pyramid rows (non-negative cone) or 3 rows of a second-order cone.

    A is filled in place in one Fortran-ordered array (its column-major ravel is then the CSC
    order); only its non-zero entries are passed to Clarabel.
    """
    n, k = jac.shape[0], jac.shape[2]
    n_var = 4 + 3 * n

    # Torque rows: J_i^T f_i <= delta_i - lo_i and -J_i^T f_i <= hi_i - delta_i.
    jt = np.transpose(jac, (0, 2, 1))  # (n, k, 3)
    tau_blocks = np.concatenate([jt, -jt], axis=1)
    tau_b = np.concatenate([bias - lo, hi - bias], axis=1).ravel()
    finite = np.isfinite(tau_b)
    all_finite = bool(finite.all())
    n_tau = tau_b.size if all_finite else int(finite.sum())

    t1, t2 = _tangent_bases(normals)
    if n_faces:
        th = 2.0 * np.pi * np.arange(n_faces) / n_faces
        # d_j^T f - mu cos(pi/k) n^T f <= 0 for the k face directions d_j; then -n^T f <= 0.
        d = np.cos(th)[None, :, None] * t1[:, None, :] + np.sin(th)[None, :, None] * t2[:, None, :]
        faces = d - mu * math.cos(math.pi / n_faces) * normals[:, None, :]
        fric_blocks = np.concatenate([faces, -normals[:, None, :]], axis=1)
    else:
        # s = -A f = (mu n^T f, t1^T f, t2^T f) must lie in the second-order cone.
        fric_blocks = -np.stack([mu * normals, t1, t2], axis=1)
    row_fric = _ROW_TORQUE + n_tau
    n_rows = row_fric + fric_blocks.shape[0] * fric_blocks.shape[1]

    a = np.zeros((n_rows, n_var), order="F")
    b = np.zeros(n_rows)  # the friction rows' right-hand side stays 0
    _fill_equilibrium(a, b, feet, force, moment)
    # Clipping box on c and aggregated contact-torque box.
    a[_N_EQ : _N_EQ + 4, 0:2] = _BOX
    a[_N_EQ + 4 : _ROW_TORQUE, 2:4] = _BOX
    b[_N_EQ : _N_EQ + 4] = extent
    b[_N_EQ + 4 : _ROW_TORQUE] = n * w_max
    if all_finite:
        a[_block_diag_index(n, 2 * k, _ROW_TORQUE)] = tau_blocks
        b[_ROW_TORQUE:row_fric] = tau_b
    else:  # rows with an infinite bound are dropped
        a[_ROW_TORQUE:row_fric] = _block_diag(tau_blocks)[finite]
        b[_ROW_TORQUE:row_fric] = tau_b[finite]
    a[_block_diag_index(n, fric_blocks.shape[1], row_fric)] = fric_blocks

    cones = [clarabel.ZeroConeT(_N_EQ)]
    if n_faces:
        cones.append(clarabel.NonnegativeConeT(n_rows - _N_EQ))
    else:
        cones.append(clarabel.NonnegativeConeT(row_fric - _N_EQ))
        cones += [clarabel.SecondOrderConeT(3)] * n
    return _Problem(_dense_to_csc(a), b, cones, n_var)


def _settings(robust: bool, tol: float = 1e-8, max_iter: int = 100) -> Any:
    """Clarabel settings: the fast ones, or the robust fallback (iterative refinement on).

    Iterative refinement of the KKT solves costs ~1/3 of the solve time on these tiny problems
    and, in our tests, changes the optimal support values by < 1e-9 m; it is therefore off by
    default and only used to retry a direction whose fast solve did not converge.
    """
    s = clarabel.DefaultSettings()
    s.verbose = False
    # No presolve: the data contain no infinite bounds, and presolve may forbid data updates.
    s.presolve_enable = False
    s.max_iter = max_iter
    s.tol_gap_abs = tol
    s.tol_gap_rel = tol
    s.tol_feas = tol
    s.iterative_refinement_enable = robust
    return s


_FAST_SETTINGS = _settings(robust=False)
_ROBUST_SETTINGS = _settings(robust=True)
_ZERO_P: dict[int, sp.csc_matrix] = {}


def _zero_p(n_var: int) -> sp.csc_matrix:
    """The all-zero quadratic cost (cached: Clarabel copies its inputs)."""
    p = _ZERO_P.get(n_var)
    if p is None:
        p = _ZERO_P.setdefault(n_var, sp.csc_matrix((n_var, n_var)))
    return p


class _SupportOracle:
    """Maximise a^T c over the equilibrium set, re-using one Clarabel solver across directions.

    Only the linear cost q changes between directions (``solver.update(q=...)``), so the
    problem is set up (and its KKT pattern analysed) once per region.  A direction whose fast
    solve fails is retried once with a robust solver, built lazily.
    """

    def __init__(self, prob: _Problem) -> None:
        self._prob = prob
        self._q = np.zeros(prob.n_var)
        self._fast = clarabel.DefaultSolver(_zero_p(prob.n_var), self._q, prob.A, prob.b, prob.cones, _FAST_SETTINGS)
        self._robust: Any = None
        self.n_solves = 0
        self.n_retries = 0
        self.n_failed = 0

    def _solve(self, solver: Any, ax: float, ay: float) -> tuple[int, float, float]:
        self.n_solves += 1
        q = self._q
        q[0] = -ax
        q[1] = -ay
        solver.update(q=q)
        sol = solver.solve()
        status = sol.status
        if status in _SOLVED:
            x = sol.x
            return SUPPORT_OK, x[0], x[1]
        if status in _INFEASIBLE:
            return SUPPORT_INFEASIBLE, math.nan, math.nan
        return SUPPORT_FAILED, math.nan, math.nan

    def __call__(self, ax: float, ay: float) -> tuple[int, float, float]:
        out = self._solve(self._fast, ax, ay)
        if out[0] != SUPPORT_FAILED:
            # Interior-point infeasibility certificates are reliable: no second opinion.
            return out
        if self._robust is None:
            prob = self._prob
            self._robust = clarabel.DefaultSolver(
                _zero_p(prob.n_var), self._q, prob.A, prob.b, prob.cones, _ROBUST_SETTINGS
            )
        self.n_retries += 1
        out = self._solve(self._robust, ax, ay)
        if out[0] == SUPPORT_FAILED:
            self.n_failed += 1
        return out


def _empty(status: str, t0: float, message: str, n_lps: int = 0) -> FeasibleRegion:
    return FeasibleRegion(
        vertices=_frozen(np.zeros((0, 2))),
        halfspaces=_frozen(np.zeros((0, 3))),
        status=status,
        converged=status == "empty",
        n_lps=n_lps,
        solve_time=time.perf_counter() - t0,
        area=0.0,
        gap=math.nan,
        message=message,
    )


def gravito_inertial_wrench(
    mass: float,
    com_acc: ArrayLike = (0.0, 0.0, 0.0),
    ang_momentum_rate: ArrayLike = (0.0, 0.0, 0.0),
    ext_force: ArrayLike = (0.0, 0.0, 0.0),
    ext_torque: ArrayLike = (0.0, 0.0, 0.0),
    gravity: float = 9.81,
    com: ArrayLike = (0.0, 0.0, 0.0),
) -> FloatArray:
    r"""Wrench :math:`w_{GI} = \dot h - w_G - w_{ext}` the contacts must produce (eq. 14-15), frame H.

    See the module docstring for the derivation: with :math:`F = m(\ddot c - \vec g) - f_{ext}`,
    :math:`w_{GI} = (F,\ \dot L - \tau_{ext} + c \times F)`, moments about the origin of H.

    Parameters
    ----------
    mass : float
        Total mass [kg] (> 0).
    com_acc : (3,) array_like
        CoM acceleration [m/s^2].
    ang_momentum_rate : (3,) array_like
        Rate of centroidal angular momentum :math:`\dot L` [N m].
    ext_force, ext_torque : (3,) array_like
        External wrench on the robot, force applied at the CoM [N], [N m].
    gravity : float
        Gravity magnitude [m/s^2] (> 0); gravity is (0, 0, -g) in H.
    com : (3,) array_like
        CoM position [m] relative to the moment reference (zero: moments about the CoM, which is how
        :func:`fwp_feasibility` and the feasible region use it). A non-zero ``com`` evaluates the
        state with the CoM displaced by ``com`` and everything else fixed.

    Returns
    -------
    (6,) ndarray
        ``(force, moment)`` [N, N m].
    """
    m = _positive_scalar("mass", mass)
    g = _positive_scalar("gravity", gravity)
    vec = {}
    for name, value in (
        ("com_acc", com_acc),
        ("ang_momentum_rate", ang_momentum_rate),
        ("ext_force", ext_force),
        ("ext_torque", ext_torque),
        ("com", com),
    ):
        arr = _as_array(name, value, (3,))
        _check_finite(name, arr)
        vec[name] = arr
    force = m * (vec["com_acc"] - np.array([0.0, 0.0, -g])) - vec["ext_force"]
    # com x force, written out (np.cross has a large fixed overhead on 3-vectors; same operations).
    (cx, cy, cz), (fx, fy, fz) = vec["com"].tolist(), force.tolist()
    com_x_force = np.array([cy * fz - cz * fy, cz * fx - cx * fz, cx * fy - cy * fx])
    wrench = np.empty(6)
    wrench[:3] = force
    wrench[3:] = vec["ang_momentum_rate"] - vec["ext_torque"] + com_x_force
    return wrench


def validate_contact_arrays(
    points: ArrayLike,
    normals: ArrayLike,
    stance: ArrayLike,
    jacobians: ArrayLike,
    torque_limits: ArrayLike | tuple[ArrayLike, ArrayLike],
    leg_bias: ArrayLike | None,
    points_name: str = "feet",
    min_joints: int = 1,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.intp]]:
    """Shared input checks of the contact-based criteria (feasible region, wrench polytope).

    Shapes are checked for all n contacts; values only for the stance contacts, whose rows are
    returned: ``(points, unit normals, jacobians, torque_lo, torque_hi, leg_bias, stance_indices)``
    (swing rows may hold anything, even NaN).

    Raises:
        ValueError: naming the malformed argument.
    """
    pts = _as_rows(points_name, points, 3)
    n_all = pts.shape[0]
    nrm = _as_array("normals", normals, (n_all, 3))
    stance_a = np.asarray(stance)
    if stance_a.shape != (n_all,):
        raise ValueError(f"stance must have shape ({n_all},), got {stance_a.shape}")
    if stance_a.dtype != np.bool_:
        if not np.issubdtype(stance_a.dtype, np.integer) or np.any((stance_a != 0) & (stance_a != 1)):
            raise ValueError("stance must be boolean (or 0/1 integers)")
        stance_a = stance_a.astype(bool)
    try:
        jac = np.asarray(jacobians, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError("jacobians must be a numeric (n, 3, k) array") from exc
    if jac.ndim != 3 or jac.shape[:2] != (n_all, 3) or jac.shape[2] < min_joints:
        raise ValueError(f"jacobians must have shape ({n_all}, 3, k) with k >= {min_joints}, got {jac.shape}")
    k = jac.shape[2]
    idx = np.flatnonzero(stance_a)
    lo, hi = _torque_bounds(torque_limits, n_all, k, idx)
    bias = np.zeros((n_all, k)) if leg_bias is None else _as_array("leg_bias", leg_bias, (n_all, k))

    pts_s = pts[idx]
    _check_finite(points_name, pts_s)
    nrm_s = nrm[idx]
    _check_finite("normals", nrm_s)
    lengths = np.linalg.norm(nrm_s, axis=1)
    if (lengths < 1e-9).any():
        raise ValueError("normals must be non-zero for stance contacts")
    jac_s = jac[idx]
    _check_finite("jacobians", jac_s)
    bias_s = bias[idx]
    _check_finite("leg_bias", bias_s)
    return pts_s, nrm_s / lengths[:, None], jac_s, lo, hi, bias_s, idx


def feasible_region(
    feet: ArrayLike,
    normals: ArrayLike,
    stance: ArrayLike,
    mu: float,
    mass: float,
    jacobians: ArrayLike,
    torque_limits: ArrayLike | tuple[ArrayLike, ArrayLike],
    leg_bias: ArrayLike | None = None,
    com_acc: ArrayLike = (0.0, 0.0, 0.0),
    ang_momentum_rate: ArrayLike = (0.0, 0.0, 0.0),
    ext_force: ArrayLike = (0.0, 0.0, 0.0),
    ext_torque: ArrayLike = (0.0, 0.0, 0.0),
    friction: str | tuple[str, int] = "cone",
    tol: float = DEFAULT_TOL,
    contact_torque_limit: float = DEFAULT_CONTACT_TORQUE_LIMIT,
    gravity: float = 9.81,
    max_lps: int = DEFAULT_MAX_LPS,
    extent: float = DEFAULT_EXTENT,
    focus: ArrayLike | None = None,
    focus_tol: float = DEFAULT_FOCUS_TOL,
) -> FeasibleRegion:
    r"""Feasible Region of the CoM (Alg. 1 of Orsolino et al.; derivation in the module docstring).

    Parameters
    ----------
    feet : (n, 3) array_like
        Contact points [m] relative to the CoM, frame H (origin at the CoM, z up, x-y
        horizontal).
    normals : (n, 3) array_like
        Contact normals (out of the ground, into the robot); normalised here.
    stance : (n,) array_like of bool
        Which feet are in contact.  Feet not in stance are ignored entirely (their rows may hold
        anything, even NaN).
    mu : float
        Friction coefficient (> 0), the same for all contacts.
    mass : float
        Total mass [kg] (> 0).
    jacobians : (n, 3, k) array_like
        Translational foot Jacobians w.r.t. each leg's k joints, in frame H [m/rad].
    torque_limits : (n, k) array_like, or a pair (lower, upper) of (n, k) arrays
        Symmetric limits ``|tau| <= limit`` (>= 0, may be inf) or explicit bounds [N m].
    leg_bias : (n, k) array_like, optional
        Bias torques delta_i [N m]; the joint torques needed are ``tau_i = delta_i - J_i^T f_i``.
        Default zeros.
    com_acc : (3,) array_like
        CoM acceleration [m/s^2], frame H.
    ang_momentum_rate : (3,) array_like
        Rate of change of the centroidal angular momentum [N m], frame H.
    ext_force, ext_torque : (3,) array_like
        External wrench on the robot, applied at the CoM [N], [N m], frame H.
    friction : ``"cone"`` or ``("pyramid", k)``
        Exact second-order cone (eq. 1) or a k-face pyramid inscribed in it (k >= 3).
    tol : float
        Stopping tolerance ``area(outer) - area(inner)`` [m^2] (> 0), default
        :data:`DEFAULT_TOL`.
    contact_torque_limit : float
        w_M of eq. (3) [N m] (>= 0), default :data:`DEFAULT_CONTACT_TORQUE_LIMIT`.  With 0,
        one- and two-contact regions degenerate to a point or a segment.
    gravity : float
        Gravity magnitude g [m/s^2] (> 0); gravity is (0, 0, -g) in H.
    max_lps : int
        Maximum number of conic programs (>= 4), default :data:`DEFAULT_MAX_LPS`.
    focus : (2,) array_like, optional
        A point [m] (e.g. the capture point) whose signed distance to the region is what matters:
        the projection then refines only the part of the boundary that decides it and stops when
        the inner and outer approximations bracket that distance within ``focus_tol``
        (``margin_bounds``); ``tol`` is not used. Far fewer programs than a uniformly accurate
        region; the vertices are still exact feasible CoM positions.
    focus_tol : float
        Bracket width [m] for ``focus`` (> 0), default :data:`DEFAULT_FOCUS_TOL`.
    extent : float
        Half-size [m] of the box ``|c_x|, |c_y| <= extent`` that keeps the programs bounded.

    Returns
    -------
    FeasibleRegion
        Never raises for an empty region: no stance foot or an infeasible program give status
        ``"empty"`` with no vertices.

    Raises
    ------
    ValueError
        On malformed inputs; the message names the argument.
    """
    t0 = time.perf_counter()
    feet_s, nrm, jac_s, lo, hi, bias_s, idx = validate_contact_arrays(
        feet, normals, stance, jacobians, torque_limits, leg_bias, points_name="feet"
    )
    mu_v = _positive_scalar("mu", mu)
    tol_v = _positive_scalar("tol", tol)
    w_max = _positive_scalar("contact_torque_limit", contact_torque_limit, allow_zero=True)
    extent_v = _positive_scalar("extent", extent)
    if isinstance(max_lps, bool) or not isinstance(max_lps, (int, np.integer)) or max_lps < 4:
        raise ValueError(f"max_lps must be an integer >= 4, got {max_lps!r}")
    n_faces = _parse_friction(friction)
    wrench = gravito_inertial_wrench(mass, com_acc, ang_momentum_rate, ext_force, ext_torque, gravity)

    # Only stance feet enter the problem (validated above).
    if idx.size == 0:
        return _empty("empty", t0, "no stance foot")
    force, moment = wrench[:3], wrench[3:]
    prob = _build_problem(feet_s, nrm, mu_v, jac_s, lo, hi, bias_s, force, moment, n_faces, w_max, extent_v)

    oracle = _SupportOracle(prob)
    focus_v = None
    if focus is not None:
        focus_arr = _as_array("focus", focus, (2,))
        _check_finite("focus", focus_arr)
        focus_v = (float(focus_arr[0]), float(focus_arr[1]))
    focus_tol_v = _positive_scalar("focus_tol", focus_tol)
    proj = iterative_projection(oracle, tol=tol_v, max_evals=int(max_lps), focus=focus_v, focus_tol=focus_tol_v)
    n_lps = oracle.n_solves
    if proj.status in ("empty", "solver_error"):
        msg = (
            "equilibrium infeasible (friction/torque limits)"
            if proj.status == "empty"
            else "no direction could be solved"
        )
        return _empty(proj.status, t0, msg, n_lps)

    hull = _convex_polygon([(x, y) for x, y in proj.points.tolist()])
    verts = np.asarray(hull, dtype=np.float64).reshape(-1, 2)
    notes = []
    if proj.status == "max_lps":
        notes.append(f"max_lps={max_lps} reached with gap {proj.gap:.3g} m^2 > tol {tol_v:.3g} m^2")
    if proj.status == "inaccurate":
        notes.append(f"{oracle.n_failed} direction(s) failed to solve; caps where the bisector failed too were skipped")
    elif oracle.n_failed:
        notes.append(f"{oracle.n_failed} direction(s) failed to solve and were replaced by their cap's bisector")
    status = "ok"
    if (np.abs(verts) >= extent_v - _BOX_TOL).any():
        status = "unbounded"
        notes.append(f"region reaches the clipping box |c| <= {extent_v} m")
    return FeasibleRegion(
        vertices=_frozen(verts),
        halfspaces=_frozen(halfspaces_from_polygon(verts)),
        status=status,
        converged=bool(
            proj.gap <= tol_v if focus_v is None else proj.margin_bounds[1] - proj.margin_bounds[0] <= focus_tol_v
        ),
        margin_bounds=None if focus_v is None else proj.margin_bounds,
        n_lps=n_lps,
        solve_time=time.perf_counter() - t0,
        area=_shoelace(hull),
        gap=proj.gap,
        message="; ".join(notes),
    )
