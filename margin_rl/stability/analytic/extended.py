r"""The extended margin m_x: a margin for every state, also those without an analytic margin.

The analytic margin m_a (:mod:`margin_rl.stability.analytic.margin`) exists only for states whose Feasible
Region is non-empty ("ok"). Walking policies also visit states whose region is empty ("infeasible":
the accelerations and external wrench they carry cannot be produced by the stance feet within their
friction cones and torque limits) and flight phases ("no_contact"). A reward that gives all of those
one floor value is a cliff with no slope to climb back. m_x continues m_a into them:

**Relaxed load.** Let lambda_alpha be lambda with its dynamic load scaled by alpha in [0, 1]: the CoM
acceleration c_ddot, the base angular acceleration w_dot and the external force and torque multiplied
by alpha, everything else (gravity axis, CoM velocity, feet, friction, contacts, normals) unchanged.
alpha = 1 is the state itself; alpha = 0 its static counterpart (gravity only). With R(.) the Feasible
Region and xi the ICP (which does not depend on alpha: it is built from the CoM velocity and height),

.. math::

    \alpha^* = \sup\{\alpha \in [0, 1] : R(\lambda_\alpha) \ne \emptyset\}

is the largest fraction of the state's dynamic load the stance can support, and

.. math::

    m_x(\lambda) = \begin{cases}
        m_a(\lambda) & \text{ok } (\alpha^* = 1) \\
        m_a(\lambda_{\alpha^*}) - \kappa\,(1 - \alpha^*) & \text{infeasible, static stance feasible} \\
        -\kappa - d(\xi_S, \operatorname{conv} S) & \text{otherwise (static stance infeasible, no contact)}
    \end{cases}

with the load penalty kappa [m] (:data:`DEFAULT_LOAD_PENALTY`). alpha* is found by bisection
(``bisection_steps`` halvings, alpha* is the feasible end of the final bracket, so R(lambda_alpha*) is
non-empty); where feasibility is not monotone in alpha the bisection returns one boundary point of the
feasible set, which still makes m_x a valid lower bound on how much of the load is supportable. As a
state approaches the edge of feasibility from the "ok" side its region shrinks to a point and m_a tends
to minus the ICP's distance to that point; from the "infeasible" side alpha* tends to 1 and the
relaxed region tends to the same point, so m_x has no jump at the status change (measured in
``benchmarks/studies/bench_extended_margin.py``).

**Support fallback.** When even the static stance is infeasible (e.g. one stance foot), the CoM is not
above the stance feet, or no foot is in contact, no region exists at any alpha. Then S is the stance
feet's contact points (all four feet's when none is in contact: the polygon the robot lands on),
d(xi_S, conv S) >= 0 the horizontal Euclidean distance of the ICP to their convex hull (0 inside), and
xi_S = c_dot_xy sqrt(z / g) with z the CoM height above the mean of S, at least
:data:`MIN_FALLBACK_HEIGHT`. These states rank below every relaxed state of the same ICP distance.

Frames and units as in :mod:`margin_rl.stability.analytic.lambda_state`: H, relative to the CoM, metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from margin_rl.robot import Robot
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, LAMBDA_SLICES, check_lambda, from_lambda
from margin_rl.stability.analytic.margin import STATUSES, AnalyticSettings, BatchMargins, analytic_margin_batch
from margin_rl.stability.geometry.polygon import convex_polygon, halfspaces_from_polygon, segment_distance

DEFAULT_LOAD_PENALTY = 0.2
"""kappa [m]: m_x drops by this much per unit of dynamic load fraction (1 - alpha*) the stance cannot carry."""

DEFAULT_BISECTION_STEPS = 8
"""Halvings of [0, 1] for alpha* (resolution 1/256 of the load; 6 halvings left 3.6-4.0 cm RMS against 10)."""

MIN_FALLBACK_HEIGHT = 0.05
"""[m] lower bound on the CoM height used for the fallback ICP (a CoM at or below its feet has none)."""

DYNAMIC_LOAD_FIELDS: tuple[str, ...] = ("com_acc", "base_ang_acc", "ext_force", "ext_torque")
"""The lambda fields scaled by alpha in lambda_alpha."""

SOURCES: tuple[str, ...] = ("analytic", "relaxed", "support", "none")
"""Where a state's m_x comes from: m_a itself, the relaxed region, the support fallback, or no value
(unreachable feet or a solver error: the state has no kinematically valid stance)."""


@dataclass(frozen=True)
class ExtendedMargins:
    """m_x of many states (:func:`extended_margin_batch`).

    ``margin`` (N,) [m], NaN only where ``source`` is "none"; ``load_fraction`` (N,) alpha* (1 for ok, NaN
    for the fallback and "none"); ``source`` (N,) int8 index into :data:`SOURCES`; ``analytic`` the analytic
    margins of the states themselves (m_a, status, programs solved, seconds).
    """

    margin: np.ndarray
    load_fraction: np.ndarray
    source: np.ndarray
    analytic: BatchMargins

    @property
    def status(self) -> np.ndarray:
        """(N,) the analytic status of each state itself (index into ``analytic.STATUSES``)."""
        return self.analytic.status

    def counts(self) -> dict[str, int]:
        return {name: int(np.sum(self.source == i)) for i, name in enumerate(SOURCES)}


def scale_dynamic_load(lams: np.ndarray, alpha: np.ndarray | float) -> np.ndarray:
    """lambda_alpha: ``lams`` (N, 47) with the :data:`DYNAMIC_LOAD_FIELDS` multiplied by ``alpha`` (N,) or scalar."""
    out = np.array(lams, dtype=float, copy=True)
    factor = np.broadcast_to(np.asarray(alpha, dtype=float), out.shape[:-1])[..., None]
    for name in DYNAMIC_LOAD_FIELDS:
        out[..., LAMBDA_SLICES[name]] *= factor
    return out


def support_hull_distance(points_xy: np.ndarray, p: np.ndarray) -> float:
    """Horizontal distance [m] of ``p`` (2,) to the convex hull of ``points_xy`` (k, 2), k >= 1; 0 inside."""
    hull = np.asarray(convex_polygon([(float(x), float(y)) for x, y in points_xy]), dtype=float).reshape(-1, 2)
    px, py = float(p[0]), float(p[1])
    if len(hull) >= 3:
        halfspaces = halfspaces_from_polygon(hull)
        if (halfspaces[:, :2] @ p - halfspaces[:, 2] >= 0.0).all():
            return 0.0
    if len(hull) == 1:
        return math.hypot(px - hull[0, 0], py - hull[0, 1])
    edges = zip(hull, np.roll(hull, -1, axis=0), strict=True)
    return min(segment_distance(px, py, a[0], a[1], b[0], b[1]) for a, b in edges)


def support_fallback(robot: Robot, lam: np.ndarray, penalty: float = DEFAULT_LOAD_PENALTY) -> float:
    """-kappa - d(xi_S, conv S) of one lambda (47,): the third case of the module docstring."""
    st = from_lambda(check_lambda(lam))
    normals = st.normals / np.linalg.norm(st.normals, axis=-1, keepdims=True)
    points = st.feet - robot.foot_radius * normals
    stance = st.contacts.astype(bool)
    support = points[stance] if stance.any() else points
    height = max(-float(support[:, 2].mean()), MIN_FALLBACK_HEIGHT)
    icp = st.com_vel[:2] * math.sqrt(height / robot.gravity)
    return -penalty - support_hull_distance(support[:, :2], icp)


def check_extended_settings(penalty: object, bisection_steps: object, penalty_name: str = "penalty") -> None:
    """A ValueError naming the setting unless kappa is a finite number >= 0 [m] and the halvings an integer >= 1."""
    if not (isinstance(penalty, (int, float)) and math.isfinite(penalty) and penalty >= 0):
        raise ValueError(f"{penalty_name} (kappa of m_x) must be a finite number >= 0 [m], got {penalty!r}")
    if isinstance(bisection_steps, bool) or not isinstance(bisection_steps, int) or bisection_steps < 1:
        raise ValueError(f"bisection_steps must be an integer >= 1, got {bisection_steps!r}")


def extended_margin_batch(
    robot: Robot,
    lams: np.ndarray,
    settings: AnalyticSettings | None = None,
    workers: int | None = 1,
    penalty: float = DEFAULT_LOAD_PENALTY,
    bisection_steps: int = DEFAULT_BISECTION_STEPS,
    chunk_size: int = 256,
) -> ExtendedMargins:
    """m_x of many states (module docstring), with the analytic margins of the batched labelling path.

    The bisection runs over all infeasible states at once: each halving is one
    :func:`~margin_rl.stability.analytic.margin.analytic_margin_batch` call on their lambda_alpha, whose status
    alone is used, so those calls use a loose focus bracket (the region only has to be found non-empty).

    Args:
        robot: from :func:`margin_rl.load_robot` (worker processes load their own copy by ``robot.name``).
        lams: (N, 47) lambda.
        settings: analytic settings of m_a and of the relaxed margin.
        workers: processes for the analytic calls (None: all cores).
        penalty: kappa [m] >= 0.
        bisection_steps: halvings for alpha*, >= 1.

    Raises:
        ValueError: lambda of the wrong shape or not finite (names the field), a negative or
            non-finite penalty, or fewer than one bisection step.
    """
    lams = check_lambda(lams, "lams")
    if lams.ndim != 2:
        raise ValueError(f"lams must have shape (N, {LAMBDA_DIM}), got {lams.shape}")
    check_extended_settings(penalty, bisection_steps)
    s = AnalyticSettings() if settings is None else settings
    # Only the status of lambda_alpha is read during the bisection: a coarse bracket finds it.
    probe = replace(s, focus_tol=max(s.focus_tol or 0.0, 0.05), outside="euclidean")

    def label(x: np.ndarray, how: AnalyticSettings):
        return analytic_margin_batch(robot, x, how, workers=workers, chunk_size=chunk_size)

    ok, infeasible = STATUSES.index("ok"), STATUSES.index("infeasible")
    base = label(lams, s)
    has_region = base.status == ok
    margin = np.where(has_region, base.margin, np.nan)
    load_fraction = np.where(has_region, 1.0, np.nan)
    source = np.where(has_region, SOURCES.index("analytic"), SOURCES.index("none")).astype(np.int8)

    candidates = np.flatnonzero(base.status == infeasible)
    relaxed = np.zeros(0, dtype=int)
    if len(candidates):
        static_ok = label(scale_dynamic_load(lams[candidates], 0.0), probe).status == ok
        relaxed = candidates[static_ok]
    if len(relaxed):
        low, high = np.zeros(len(relaxed)), np.ones(len(relaxed))  # R(low) non-empty, R(high) empty
        for _ in range(bisection_steps):
            mid = 0.5 * (low + high)
            feasible = label(scale_dynamic_load(lams[relaxed], mid), probe).status == ok
            low, high = np.where(feasible, mid, low), np.where(feasible, high, mid)
        final = label(scale_dynamic_load(lams[relaxed], low), s)
        good = final.status == ok
        margin[relaxed[good]] = final.margin[good] - penalty * (1.0 - low[good])
        load_fraction[relaxed[good]] = low[good]
        source[relaxed[good]] = SOURCES.index("relaxed")

    # No region at any alpha: the support fallback (also for a relaxed solve that failed numerically).
    no_region = (base.status == infeasible) | (base.status == STATUSES.index("no_contact"))
    for i in np.flatnonzero(no_region & (source == SOURCES.index("none"))).tolist():
        margin[i] = support_fallback(robot, lams[i], penalty)
        source[i] = SOURCES.index("support")
    return ExtendedMargins(margin=margin, load_fraction=load_fraction, source=source, analytic=base)


def extended_margin(
    robot: Robot, lam: np.ndarray, settings: AnalyticSettings | None = None, penalty: float = DEFAULT_LOAD_PENALTY
) -> float:
    """m_x [m] of one lambda (47,) (module docstring); NaN for unreachable feet or a solver error."""
    lam = check_lambda(lam)
    if lam.shape != (LAMBDA_DIM,):
        raise ValueError(f"one lambda of shape ({LAMBDA_DIM},) is expected, got {lam.shape}")
    return float(extended_margin_batch(robot, lam[None], settings, workers=1, penalty=penalty).margin[0])
