"""Planar convex-polygon geometry of the feasible region (pure Python floats: tens of vertices at most).

* the caps of the iterative projection: :func:`cap_area` (the area criterion) and
  :func:`cap_distance_bounds` (the focused criterion), with :func:`segment_distance`;
* vertices from support points: :func:`convex_polygon` (hull, merged near-duplicates, no collinear
  vertices) and its area :func:`shoelace`;
* the public helpers on (m, 2) vertex arrays: :func:`polygon_area` and :func:`halfspaces_from_polygon`
  (the half-space rows of eq. 6).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "cap_area",
    "cap_distance_bounds",
    "convex_polygon",
    "halfspaces_from_polygon",
    "polygon_area",
    "segment_distance",
    "shoelace",
]

FloatArray = NDArray[np.float64]

# Points closer than this [m] are merged, and a vertex closer than _COLLINEAR_TOL [m] to the chord
# of its neighbours is dropped, so that noise from the interior-point solver (~1e-9 m) never
# produces a tiny edge whose normal would be meaningless.
_MERGE_TOL: float = 1e-6
_COLLINEAR_TOL: float = 1e-8


def cap_area(t1: float, x1: float, y1: float, t2: float, x2: float, y2: float) -> float:
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


def segment_distance(px: float, py: float, x1: float, y1: float, x2: float, y2: float) -> float:
    """Euclidean distance from (px, py) to the segment (x1, y1)-(x2, y2)."""
    ex, ey = x2 - x1, y2 - y1
    l2 = ex * ex + ey * ey
    t = 0.0 if l2 <= 0.0 else min(1.0, max(0.0, ((px - x1) * ex + (py - y1) * ey) / l2))
    return math.hypot(x1 + t * ex - px, y1 + t * ey - py)


def cap_distance_bounds(
    t1: float, x1: float, y1: float, t2: float, x2: float, y2: float, fx: float, fy: float
) -> tuple[float, float]:
    r"""Distances from the focus f to the two boundaries of one cap: ``(inner, outer)`` [m].

    The true set's boundary between support points 1 and 2 lies in the cap triangle bounded by the
    inner edge p1-p2 and the two support lines :math:`a_k^T c = a_k^T p_k`, which meet at the apex
    :math:`c^*` solving :math:`[a_1; a_2] c^* = [a_1^T p_1; a_2^T p_2]` (determinant
    :math:`\sin(t_2 - t_1)`). ``inner`` is the distance to the segment p1-p2, ``outer`` the distance
    to the polyline p1-c*-p2 (the outer polygon's boundary there); ``inf`` for an open cap.
    """
    inner = segment_distance(fx, fy, x1, y1, x2, y2)
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
    outer = min(segment_distance(fx, fy, x1, y1, ax, ay), segment_distance(fx, fy, ax, ay, x2, y2))
    return inner, outer


def _cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def convex_polygon(points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
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


def shoelace(pts: Sequence[tuple[float, float]]) -> float:
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
        CCW vertices of a convex polygon [m], as in
        :attr:`~margin_rl.stability.geometry.region.FeasibleRegion.vertices`.  Degenerate inputs: ``m == 2``
        (segment) gives the two sides plus the two end caps; ``m == 1`` (point) gives four
        axis-aligned rows; ``m == 0`` gives an empty (0, 3) array.

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
