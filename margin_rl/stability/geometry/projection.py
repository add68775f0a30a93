r"""Bretl & Lall iterative projection of a compact convex planar set given its support oracle (Alg. 1).

One loop (:func:`iterative_projection`) with two stopping rules:

* :class:`_AreaRule` (Alg. 1): refine the largest cap until the total cap area
  :math:`area(outer) - area(inner) \le` ``tol``;
* :class:`_FocusRule`: refine the cap nearest to a focus point until the inner and outer polygons
  bracket its signed distance to the set within ``focus_tol``.

The loop owns the support points (CCW in their direction angle) and their cap areas, asks the rule
when to stop and which cap to refine, refines it (:func:`_refine_cap`: the edge's outward normal,
then the wedge's bisector if that program fails) and tells the rule about a failed cap or a new
point. The caps' geometry is in :mod:`margin_rl.stability.geometry.polygon`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from margin_rl.stability.geometry.polygon import cap_area, cap_distance_bounds

__all__ = [
    "DEFAULT_FOCUS_TOL",
    "DEFAULT_MAX_LPS",
    "DEFAULT_TOL",
    "SUPPORT_FAILED",
    "SUPPORT_INFEASIBLE",
    "SUPPORT_OK",
    "ProjectionResult",
    "SupportOracle",
    "iterative_projection",
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

# Distance [m] beyond an inner edge's line at which a focus counts as outside it (the polygon
# module's merge tolerance: below it the support points' noise decides the side).
_SIDE_TOL: float = 1e-6

# Outcomes of one support-function evaluation in :func:`iterative_projection`.
SUPPORT_OK: int = 0
SUPPORT_INFEASIBLE: int = 1
SUPPORT_FAILED: int = 2

# The four initial directions are the diagonals: for an axis-aligned rectangular support
# polygon (the common quadruped case in the yaw frame) each one hits a corner exactly, while
# axis directions would hit whole edges and return their midpoints.
_INITIAL_ANGLES: tuple[float, ...] = tuple(math.pi / 4 + k * math.pi / 2 for k in range(4))

FloatArray = NDArray[np.float64]
#: ``(a_x, a_y) -> (code, x, y)``: see :func:`iterative_projection`.
SupportOracle = Callable[[float, float], tuple[int, float, float]]


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


class _Hull:
    """The support points found so far (CCW in their direction angle) and the area of each cap.

    Cap k lies over the inner edge from point k to point k + 1 (cyclic). The lists are shared with
    the stopping rule, which reads them (and keeps its own per-cap data in step with them).
    """

    def __init__(self, angles: list[float], xs: list[float], ys: list[float]) -> None:
        self.angles, self.xs, self.ys = angles, xs, ys
        self.caps = [self.cap(k) for k in range(len(angles))]

    def upper_angle(self, k: int) -> float:
        """Angle of point k + 1, unwrapped to above angle k (the end of cap k's wedge)."""
        angles = self.angles
        k2 = (k + 1) % len(angles)
        return angles[k2] if k2 > k else angles[k2] + 2.0 * math.pi

    def cap(self, k: int) -> float:
        angles, xs, ys = self.angles, self.xs, self.ys
        if len(angles) == 1:
            return 0.0
        k2 = (k + 1) % len(angles)
        return cap_area(angles[k], xs[k], ys[k], self.upper_angle(k), xs[k2], ys[k2])

    def insert(self, k: int, t_new: float, x: float, y: float) -> int:
        """Insert the new support point after k (keeps the angles increasing within [angles[0],
        angles[0] + 2 pi)); returns its index."""
        pos = k + 1
        self.angles.insert(pos, t_new)
        self.xs.insert(pos, x)
        self.ys.insert(pos, y)
        self.caps.insert(pos, 0.0)
        return pos

    def update_caps(self, k: int, pos: int) -> None:
        """Recompute the two caps that replaced cap k (k and the new pos)."""
        caps = self.caps
        caps[k], caps[pos] = self.cap(k), self.cap(pos)


class _AreaRule:
    """Alg. 1's stopping rule: refine the largest cap until the total cap area is within ``tol``.

    A cap whose refining direction failed is frozen: its area moves to ``frozen_gap`` and its slot
    is zeroed so that it is never selected again (its two points never change).
    """

    def __init__(self, hull: _Hull, tol: float) -> None:
        self.hull, self.tol = hull, tol
        self.frozen_gap = 0.0

    def done(self) -> bool:
        return sum(self.hull.caps) <= self.tol

    def select(self) -> int | None:
        caps = self.hull.caps
        return caps.index(max(caps))

    def freeze(self, k: int) -> None:
        caps = self.hull.caps
        self.frozen_gap += caps[k]
        caps[k] = 0.0

    def inserted(self, k: int, pos: int, t_new: float, x: float, y: float) -> None:
        self.hull.update_caps(k, pos)

    def gap(self) -> float:
        return float(sum(self.hull.caps) + self.frozen_gap)

    def margin_bounds(self) -> tuple[float, float]:
        return (math.nan, math.nan)


class _FocusRule:
    """The focused stopping rule (see the ``focus`` parameter of :func:`iterative_projection`).

    Refines the cap nearest to the focus among those whose boundary is still uncertain, and stops
    when the signed-distance bracket ``sd(f, P_in) <= sd(f, S) <= sd(f, P_out)`` is within
    ``focus_tol`` (or when no cap is uncertain any more).
    """

    def __init__(self, hull: _Hull, focus: tuple[float, float], focus_tol: float) -> None:
        self.hull, self.focus_tol = hull, focus_tol
        self.fx, self.fy = float(focus[0]), float(focus[1])
        angles, xs, ys = hull.angles, hull.xs, hull.ys
        self.lo_hi = [self.bounds(k) for k in range(len(angles))]
        self.frozen = [False] * len(angles)
        # Support-line offsets h_k = max over all found (feasible) points of a_k . p: the solver's own
        # point can fall short of the optimum by ~1e-5 m, and taking the max keeps P_in inside P_out.
        self.dirs = [(math.cos(t), math.sin(t)) for t in angles]
        self.offsets = [max(cx * x + sy * y for x, y in zip(xs, ys, strict=True)) for cx, sy in self.dirs]
        self.sd_in = self.sd_out = math.nan

    def bounds(self, k: int) -> tuple[float, float]:
        """(inner, outer) distances from the focus to cap k's two boundaries."""
        hull, fx, fy = self.hull, self.fx, self.fy
        angles, xs, ys = hull.angles, hull.xs, hull.ys
        k2 = (k + 1) % len(angles)
        t2 = hull.upper_angle(k)
        if len(angles) == 1:
            d = math.hypot(xs[0] - fx, ys[0] - fy)
            return d, math.inf
        return cap_distance_bounds(angles[k], xs[k], ys[k], t2, xs[k2], ys[k2], fx, fy)

    def done(self) -> bool:
        xs, ys, fx, fy, lo_hi = self.hull.xs, self.hull.ys, self.fx, self.fy, self.lo_hi
        # Sign of the bracket ends: inside P_in iff left of every inner edge (CCW), inside P_out
        # iff on the inner side of every support line. An edge between two nearly coincident support
        # points (solver noise, ~1e-9 m apart) has an arbitrary direction, so the focus only counts as
        # right of an edge when it is farther than _SIDE_TOL from its line (measured: a focus 97 mm
        # inside read as outside, and the projection ran to max_lps).
        m = len(self.hull.angles)
        inside_in = m >= 3 and all(
            (xs[(k + 1) % m] - xs[k]) * (fy - ys[k]) - (ys[(k + 1) % m] - ys[k]) * (fx - xs[k])
            >= -_SIDE_TOL * math.hypot(xs[(k + 1) % m] - xs[k], ys[(k + 1) % m] - ys[k])
            for k in range(m)
        )
        # Slack of the focus w.r.t. each support line a_k . c <= a_k . p_k.
        slack = min(h - cx * fx - sy * fy for (cx, sy), h in zip(self.dirs, self.offsets, strict=True))
        lo = min(b[0] for b in lo_hi)
        self.sd_in = lo if inside_in else -lo
        # Inside P_out its boundary distance is the smallest line slack (no apex needed, so no
        # ill-conditioned intersection of nearly parallel lines); outside, the distance to P_out's
        # boundary polylines through the cap apexes.
        self.sd_out = slack if slack >= 0.0 else -min(b[1] for b in lo_hi)
        return self.sd_out - self.sd_in <= self.focus_tol

    def select(self) -> int | None:
        # Refine the cap nearest to the focus among those whose boundary is still uncertain (inner
        # and outer distances differ; which one is larger depends on the side the focus is on).
        lo_hi, frozen, focus_tol = self.lo_hi, self.frozen, self.focus_tol
        m = len(self.hull.angles)
        candidates = [k for k in range(m) if not frozen[k] and abs(lo_hi[k][1] - lo_hi[k][0]) > 0.05 * focus_tol]
        if not candidates:
            # A focus inside a cap (outside P_in, inside P_out) can be as far from its inner edge as from
            # its outer polyline while the bracket is as wide as the cap (measured: 10 mm, left
            # unrefined): refine the open cap nearest to the focus then.
            caps = self.hull.caps
            candidates = [k for k in range(m) if not frozen[k] and caps[k] > 0.0]
            if not candidates:
                return None
            return min(candidates, key=lambda k: lo_hi[k][0])
        return min(candidates, key=lambda k: min(lo_hi[k]))

    def freeze(self, k: int) -> None:
        self.frozen[k] = True

    def inserted(self, k: int, pos: int, t_new: float, x: float, y: float) -> None:
        xs, ys, dirs = self.hull.xs, self.hull.ys, self.dirs
        self.frozen.insert(pos, False)
        new_dir = (math.cos(t_new), math.sin(t_new))
        self.offsets = [max(h, cx * x + sy * y) for (cx, sy), h in zip(dirs, self.offsets, strict=True)]
        dirs.insert(pos, new_dir)
        self.offsets.insert(pos, max(new_dir[0] * px + new_dir[1] * py for px, py in zip(xs, ys, strict=True)))
        self.lo_hi.insert(pos, (0.0, 0.0))
        self.hull.update_caps(k, pos)
        self.lo_hi[k], self.lo_hi[pos] = self.bounds(k), self.bounds(pos)

    def gap(self) -> float:
        return float(sum(self.hull.caps))

    def margin_bounds(self) -> tuple[float, float]:
        return (self.sd_in, self.sd_out)


def iterative_projection(
    support: SupportOracle,
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

    hull = _Hull(angles, xs, ys)
    rule: _AreaRule | _FocusRule = _AreaRule(hull, tol) if focus is None else _FocusRule(hull, focus, focus_tol)
    status = "ok"
    while True:
        if rule.done():
            break
        if n_evals >= max_evals:
            status = "max_lps"
            break
        k = rule.select()
        if k is None:
            break
        code, x, y, t_new, evals = _refine_cap(support, angles, xs, ys, k)
        n_evals += evals
        if code != SUPPORT_OK:
            # (Infeasible cannot happen for a non-empty set: a numerical failure as well.)
            failed = True
            rule.freeze(k)
            continue
        pos = hull.insert(k, t_new, x, y)
        rule.inserted(k, pos, t_new, x, y)
    if failed and status == "ok":
        status = "inaccurate"
    pts = np.column_stack([np.asarray(xs), np.asarray(ys)])
    return ProjectionResult(pts, np.asarray(angles), rule.gap(), n_evals, status, rule.margin_bounds())


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
    support: SupportOracle,
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
