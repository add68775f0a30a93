r"""Feasible Wrench Polytope (FWP) and its feasibility factor (seed 004, Orsolino et al. 2018).

A second stability criterion next to the analytic margin of :mod:`margin_rl.stability.analytic.margin`:
instead of projecting the equilibrium set onto the CoM plane, it asks whether the wrench the
contacts must produce lies in the set of wrenches the contacts *can* produce without slipping and
without exceeding the joint-torque limits, and measures how deep inside it is.

Frame, units and sign conventions
---------------------------------
Everything is in the horizontal frame :math:`\mathcal{H}` of :mod:`margin_rl.stability.geometry.region`:
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
exactly the Newton--Euler rows of :func:`~margin_rl.stability.geometry.region.feasible_region` (its
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
Measured with ``benchmarks/speed/bench_fwp.py`` on ANYmal C, static non-coplanar stances, a loaded 2-core
AMD EPYC: :func:`fwp_feasibility` (default, no pruning) takes ~5 ms for 3 contacts and ~9 ms for 4
(the feasible-region margin of the same state: ~1.5 ms). The paper's pipeline (``prune=True``)
takes ~13 ms for 3 contacts (~600-800 FWP vertices) and ~0.2 s for 4 (~3900-4500 vertices: ~0.1 s
to prune, ~30 ms for eq. 24). Use the criterion as an environment margin term only knowingly.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.robot import Robot
from margin_rl.stability.analytic.contact_problem import ContactProblem, contact_problem
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, check_lambda
from margin_rl.stability.fwp.factor import feasibility_factor, minkowski_feasibility_factor, wrench_violations
from margin_rl.stability.fwp.polytope import (
    DEFAULT_N_FACES,
    FeasibleWrenchPolytope,
    check_n_faces,
    feasible_wrench_polytope,
)
from margin_rl.stability.geometry.contact import frozen_array

__all__ = ["FWP_STATUSES", "FWPFeasibility", "contact_problem_polytope", "fwp_feasibility"]

FloatArray = NDArray[np.float64]

#: Statuses of :func:`fwp_feasibility`: those of the analytic margin (``"infeasible"`` also covers an
#: empty FWP).
FWP_STATUSES: tuple[str, ...] = ("ok", "unreachable", "infeasible", "no_contact", "solver_error")


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
# Robot layer
# --------------------------------------------------------------------------------------------


def contact_problem_polytope(
    problem: ContactProblem,
    n_faces: int = DEFAULT_N_FACES,
    prune: bool = True,
    torque_limits: ArrayLike | None = None,
) -> FeasibleWrenchPolytope:
    """:func:`feasible_wrench_polytope` of one state's contacts.

    ``problem``: one state's problem, ``contact_problem(robot, lams)[i]``
    (:func:`~margin_rl.stability.analytic.contact_problem.contact_problem`). ``torque_limits`` (4, 3):
    symmetric joint-torque limits [N m] in place of the robot's (a hindered joint, a derated drive).
    """
    limits = problem.torque_limits if torque_limits is None else _torque_limits(torque_limits)
    return feasible_wrench_polytope(
        problem.contact_points,
        problem.normals,
        problem.stance,
        problem.mu,
        problem.jacobians,
        limits,
        problem.leg_bias,
        n_faces=n_faces,
        prune=prune,
    )


def _torque_limits(value: ArrayLike) -> FloatArray:
    limits = np.asarray(value, dtype=float)
    if limits.shape != (4, 3) or not np.all(np.isfinite(limits)) or np.any(limits <= 0):
        raise ValueError(f"torque_limits must be positive finite numbers of shape (4, 3) [N m], got {limits.shape}")
    return limits


def fwp_feasibility(
    robot: Robot,
    lam: ArrayLike,
    n_faces: int = DEFAULT_N_FACES,
    prune: bool = False,
    torque_limits: ArrayLike | None = None,
) -> FWPFeasibility:
    r"""FWP feasibility factor of one state lambda (the same input as the analytic margin).

    Pipeline: :func:`~margin_rl.stability.analytic.contact_problem.contact_problem` (IK, Jacobians and bias
    torques in H, contact points, statuses) :math:`\to` :func:`feasible_wrench_polytope` :math:`\to`
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
        lambda (:mod:`margin_rl.stability.analytic.lambda_state`).
    n_faces : int
        Faces of the linearised friction cones (>= 3).
    prune : bool
        False (default): eq. (24) on the summands (:func:`minkowski_feasibility_factor`), a few ms.
        True: build the pruned V-description and solve eq. (24) on its vertices, as the paper does
        (same ``s``; ~0.1-0.3 s for 4 contacts); ``n_vertices`` is then reported.
    torque_limits : (4, 3) array_like, optional
        Symmetric joint-torque limits [N m] in place of ``robot.torque_limits`` (a hindered joint).

    Returns
    -------
    FWPFeasibility
        Never raises for unreachable feet or missing contacts (statuses, ``s`` NaN).

    Raises
    ------
    ValueError
        Malformed lambda (see :func:`~margin_rl.stability.analytic.contact_problem.contact_problem`) or
        ``n_faces``.
    """
    t0 = time.perf_counter()
    check_n_faces(n_faces)
    limits = None if torque_limits is None else _torque_limits(torque_limits)
    lam = check_lambda(lam)
    if lam.shape != (LAMBDA_DIM,):
        raise ValueError(f"one lambda of shape ({LAMBDA_DIM},) is expected, got {lam.shape}")
    problem = contact_problem(robot, lam[None])[0]  # one state: a batch of one
    t1 = time.perf_counter()
    nan_wrench = frozen_array(np.full(6, np.nan))
    if problem.status != "ok":
        timings = {"kinematics": t1 - t0, "total": time.perf_counter() - t0}
        return FWPFeasibility(math.nan, problem.status, nan_wrench, (), None, (), timings, problem.message)

    fwp = contact_problem_polytope(problem, n_faces=n_faces, prune=prune, torque_limits=limits)
    wrench = frozen_array(problem.wrench)
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
