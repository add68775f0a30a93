r"""Feasible Region of a legged robot by iterative projection (Orsolino et al., Alg. 1).

This module holds the region's derivation and the public entry points (the conic program of one state and
its support oracle are in :mod:`~margin_rl.stability.geometry.region_program`):
:func:`feasible_region` (every input as a keyword) and :func:`solve_region` (the same inputs grouped in
:class:`~margin_rl.stability.geometry.contact.ContactSet`, :class:`~margin_rl.stability.geometry.contact.LegLimits`,
:class:`~margin_rl.stability.geometry.contact.CentroidalLoad` and :class:`RegionSettings`). The input checks and
the solver kit are in :mod:`~margin_rl.stability.geometry.contact` (shared with the wrench polytope), the loop
of Alg. 1 in :mod:`~margin_rl.stability.geometry.projection` and the polygon geometry in
:mod:`~margin_rl.stability.geometry.polygon`; their public names are re-exported here.

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

import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.stability.geometry.contact import (
    DEFAULT_CONTACT_TORQUE_LIMIT,
    CentroidalLoad,
    ContactSet,
    LegLimits,
    as_array,
    check_finite,
    frozen_array,
    gravito_inertial_wrench,
    parse_friction,
    positive_scalar,
    validate_contact_arrays,
)
from margin_rl.stability.geometry.polygon import convex_polygon, halfspaces_from_polygon, polygon_area, shoelace
from margin_rl.stability.geometry.projection import (
    DEFAULT_FOCUS_TOL,
    DEFAULT_MAX_LPS,
    DEFAULT_TOL,
    SUPPORT_FAILED,
    SUPPORT_INFEASIBLE,
    SUPPORT_OK,
    ProjectionResult,
    iterative_projection,
)
from margin_rl.stability.geometry.region_program import SupportOracle, build_program

__all__ = [
    "DEFAULT_CONTACT_TORQUE_LIMIT",
    "DEFAULT_EXTENT",
    "DEFAULT_MAX_LPS",
    "DEFAULT_TOL",
    "SUPPORT_FAILED",
    "SUPPORT_INFEASIBLE",
    "SUPPORT_OK",
    "CentroidalLoad",
    "ContactSet",
    "FeasibleRegion",
    "LegLimits",
    "ProjectionResult",
    "RegionSettings",
    "feasible_region",
    "gravito_inertial_wrench",
    "halfspaces_from_polygon",
    "iterative_projection",
    "polygon_area",
    "solve_region",
    "validate_contact_arrays",
]

#: Default half-size of the clipping box on c_xy [m]; far beyond any leg's reach.
DEFAULT_EXTENT: float = 10.0

#: A vertex within this distance [m] of the clipping box marks the region "unbounded".
UNBOUNDED_TOL: float = 1e-6

FloatArray = NDArray[np.float64]


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
class RegionSettings:
    """How :func:`solve_region` projects: accuracy, program budget and clipping box.

    Attributes:
        tol: stopping tolerance ``area(outer) - area(inner)`` [m^2] (> 0) of the area criterion.
        max_lps: maximum number of conic programs (integer >= 4).
        extent: half-size [m] of the box ``|c_x|, |c_y| <= extent`` that keeps the programs bounded.
        focus_tol: bracket width [m] (> 0) at which a projection focused on a point stops.
    """

    tol: float = DEFAULT_TOL
    max_lps: int = DEFAULT_MAX_LPS
    extent: float = DEFAULT_EXTENT
    focus_tol: float = DEFAULT_FOCUS_TOL


def _empty(status: str, t0: float, message: str, n_lps: int = 0) -> FeasibleRegion:
    return FeasibleRegion(
        vertices=frozen_array(np.zeros((0, 2))),
        halfspaces=frozen_array(np.zeros((0, 3))),
        status=status,
        converged=status == "empty",
        n_lps=n_lps,
        solve_time=time.perf_counter() - t0,
        area=0.0,
        gap=math.nan,
        message=message,
    )


def solve_region(
    contacts: ContactSet,
    legs: LegLimits,
    load: CentroidalLoad,
    settings: RegionSettings | None = None,
    focus: ArrayLike | None = None,
) -> FeasibleRegion:
    r"""Feasible Region of the CoM (Alg. 1 of Orsolino et al.; derivation in the module docstring).

    Parameters
    ----------
    contacts : ContactSet
        Contact points relative to the CoM, normals, stance flags, friction coefficient and model,
        w_M of eq. (3); frame H (origin at the CoM, z up, x-y horizontal).
    legs : LegLimits
        Foot Jacobians in H, torque limits and bias torques of the legs.
    load : CentroidalLoad
        Mass, CoM acceleration, angular-momentum rate, external wrench and gravity, frame H.
    settings : RegionSettings, optional
        Tolerances, program budget and clipping box; defaults if omitted.
    focus : (2,) array_like, optional
        A point [m] (e.g. the capture point) whose signed distance to the region is what matters:
        the projection then refines only the part of the boundary that decides it and stops when
        the inner and outer approximations bracket that distance within ``settings.focus_tol``
        (``margin_bounds``); ``settings.tol`` is not used.

    Returns and raises as :func:`feasible_region` (whose keyword names the error messages use).
    """
    t0 = time.perf_counter()
    s = RegionSettings() if settings is None else settings
    feet_s, nrm, jac_s, lo, hi, bias_s, idx = validate_contact_arrays(
        contacts.points,
        contacts.normals,
        contacts.stance,
        legs.jacobians,
        legs.torque_limits,
        legs.leg_bias,
        points_name="feet",
    )
    mu_v = positive_scalar("mu", contacts.mu)
    tol_v = positive_scalar("tol", s.tol)
    w_max = positive_scalar("contact_torque_limit", contacts.contact_torque_limit, allow_zero=True)
    extent_v = positive_scalar("extent", s.extent)
    max_lps = s.max_lps
    if isinstance(max_lps, bool) or not isinstance(max_lps, (int, np.integer)) or max_lps < 4:
        raise ValueError(f"max_lps must be an integer >= 4, got {max_lps!r}")
    n_faces = parse_friction(contacts.friction)
    wrench = load.wrench()

    # Only stance feet enter the problem (validated above).
    if idx.size == 0:
        return _empty("empty", t0, "no stance foot")
    force, moment = wrench[:3], wrench[3:]
    prob = build_program(feet_s, nrm, mu_v, jac_s, lo, hi, bias_s, force, moment, n_faces, w_max, extent_v)

    oracle = SupportOracle(prob)
    focus_v = None
    if focus is not None:
        focus_arr = as_array("focus", focus, (2,))
        check_finite("focus", focus_arr)
        focus_v = (float(focus_arr[0]), float(focus_arr[1]))
    focus_tol_v = positive_scalar("focus_tol", s.focus_tol)
    proj = iterative_projection(oracle, tol=tol_v, max_evals=int(max_lps), focus=focus_v, focus_tol=focus_tol_v)
    n_lps = oracle.n_solves
    if proj.status in ("empty", "solver_error"):
        msg = (
            "equilibrium infeasible (friction/torque limits)"
            if proj.status == "empty"
            else "no direction could be solved"
        )
        return _empty(proj.status, t0, msg, n_lps)

    hull = convex_polygon([(x, y) for x, y in proj.points.tolist()])
    verts = np.asarray(hull, dtype=np.float64).reshape(-1, 2)
    notes = []
    if proj.status == "max_lps":
        notes.append(f"max_lps={max_lps} reached with gap {proj.gap:.3g} m^2 > tol {tol_v:.3g} m^2")
    if proj.status == "inaccurate":
        notes.append(f"{oracle.n_failed} direction(s) failed to solve; caps where the bisector failed too were skipped")
    elif oracle.n_failed:
        notes.append(f"{oracle.n_failed} direction(s) failed to solve and were replaced by their cap's bisector")
    status = "ok"
    if (np.abs(verts) >= extent_v - UNBOUNDED_TOL).any():
        status = "unbounded"
        notes.append(f"region reaches the clipping box |c| <= {extent_v} m")
    return FeasibleRegion(
        vertices=frozen_array(verts),
        halfspaces=frozen_array(halfspaces_from_polygon(verts)),
        status=status,
        converged=bool(
            proj.gap <= tol_v if focus_v is None else proj.margin_bounds[1] - proj.margin_bounds[0] <= focus_tol_v
        ),
        margin_bounds=None if focus_v is None else proj.margin_bounds,
        n_lps=n_lps,
        solve_time=time.perf_counter() - t0,
        area=shoelace(hull),
        gap=proj.gap,
        message="; ".join(notes),
    )


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

    Every input as a keyword; :func:`solve_region` takes the same inputs grouped in typed dataclasses
    and computes the result (this function only groups them).

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
    return solve_region(
        ContactSet(feet, normals, stance, mu, friction, contact_torque_limit),
        LegLimits(jacobians, torque_limits, leg_bias),
        CentroidalLoad(mass, com_acc, ang_momentum_rate, ext_force, ext_torque, gravity),
        RegionSettings(tol=tol, max_lps=max_lps, extent=extent, focus_tol=focus_tol),
        focus,
    )
