"""Analytic stability margin m_a(lambda) of seed 000 §III for a robot: lambda -> region -> ICP -> margin.

Pipeline of :func:`analytic_margin` (frames as in :mod:`margin_rl.stability.analytic.lambda_state`):

1. Base orientation in the horizontal frame H from e_g (roll and pitch; H has no yaw):
   R_HB = Ry(pitch) Rx(roll).
2. Joint angles by analytic IK of every foot. The feet in lambda are relative to the CoM, but the
   kinematics need them relative to the base origin, p_B = R_HB^T p_H + c_B(q), and the CoM offset
   c_B depends on the legs' configuration q. A fixed-point iteration c_B <- CoM(IK(R_HB^T p_H + c_B)),
   started at the standing pose's CoM, converges geometrically (the legs move the CoM by a fraction of
   their own displacement); it stops at ``com_tol`` or ``com_iterations``.
3. Foot Jacobians in H, bias torques delta_i (eq. 2) and the centroidal angular-momentum rate
   L_dot = I_c w_dot, all from Pinocchio with frozen joints and zero velocities (lambda holds no
   joint or base angular velocities; see Table I: "base angular velocity: -").
4. Contact points p_i - r n_i of the stance feet (sphere radius r), the CoM height above them
   (mean over the stance feet, for the LIP frequency omega = sqrt(g / z)), and the Feasible Region
   (:func:`~margin_rl.stability.geometry.region.solve_region`) with the robot's torque limits.
5. ICP xi = c_dot_xy / omega relative to the current CoM (eq. 5), and the margin. Only the margin at
   xi is needed, so by default the projection is *focused* on xi: the inner and outer
   approximations bracket its signed distance and the loop stops when the bracket is narrower than
   ``focus_tol`` (0.5 mm), refining only the boundary near xi (a fraction of the programs of a
   uniformly refined region; ``focus_tol=None`` restores Alg. 1's area criterion). Inside the region
   m_a = min_j (n_j . xi - a_j) (eq. 7), which for a convex polygon is the distance to its boundary.
   Outside, eq. 7 (the largest violation of an edge *line*) depends on how finely the iterative
   projection discretised the region's curved parts: each added edge can only make it more negative,
   and its limit is minus the Euclidean distance to the region. Measured on ANYmal C: an ICP 14 cm
   outside a 3-contact region read -72 mm with 13 programs and -98 mm with 300. As labels for
   learning that is noise, so by default (``outside="euclidean"``) m_a outside is minus the exact
   Euclidean distance to the polygon, whose error is bounded by the inner/outer approximation gap.
   ``outside="lines"`` gives the paper's formula everywhere.

Statuses: ``"ok"``; ``"unreachable"`` (a foot outside its leg's workspace or joint limits: the state
is not kinematically possible, so it has no margin); ``"infeasible"`` (no CoM position admits an
equilibrium: empty region); ``"no_contact"`` (no foot in contact); ``"solver_error"``. The margin is
NaN unless the status is "ok".
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, fields, replace

import numpy as np

from margin_rl.robot import Robot, load_robot
from margin_rl.stability.analytic.contact_problem import ContactProblem, contact_problem
from margin_rl.stability.analytic.lambda_state import (
    LAMBDA_DIM,
    check_lambda,
)
from margin_rl.stability.analytic.sampling import standing_state
from margin_rl.stability.geometry.contact import (
    DEFAULT_CONTACT_TORQUE_LIMIT,
    parse_friction,
    positive_scalar,
)
from margin_rl.stability.geometry.icp import stability_margin
from margin_rl.stability.geometry.polygon import convex_polygon, halfspaces_from_polygon
from margin_rl.stability.geometry.projection import (
    DEFAULT_FOCUS_TOL,
    DEFAULT_MAX_LPS,
    DEFAULT_TOL,
    iterative_projection,
)
from margin_rl.stability.geometry.region import UNBOUNDED_TOL, FeasibleRegion, RegionSettings, solve_region
from margin_rl.stability.geometry.region_batch import ProgramStructure, ReusedRegionSolver, program_values

STATUSES: tuple[str, ...] = ("ok", "unreachable", "infeasible", "no_contact", "solver_error")
"""Status names; batch results store their index in this tuple (``STATUSES.index("ok") == 0``)."""

LABELLING_PATHS: tuple[str, ...] = ("batched", "per_state")
"""Values of :attr:`AnalyticSettings.labelling`: how :func:`analytic_margin_batch` labels many states."""


@dataclass(frozen=True)
class AnalyticSettings:
    """Settings of the analytic margin (recorded with every dataset and model card)."""

    friction: str | tuple[str, int] = "cone"  # exact cone, or ("pyramid", k)
    tol: float = DEFAULT_TOL  # iterative-projection tolerance [m^2]
    contact_torque_limit: float = DEFAULT_CONTACT_TORQUE_LIMIT  # w_M of eq. (3) [N m]
    max_lps: int = DEFAULT_MAX_LPS  # cap on the programs solved per region
    outside: str = "euclidean"  # margin of an ICP outside the region: "euclidean" or "lines" (eq. 7)
    # Refine the region only where it decides the ICP's margin, to this bracket [m]; None: refine the
    # whole region to `tol` (Alg. 1's area criterion). Only with outside="euclidean".
    focus_tol: float | None = DEFAULT_FOCUS_TOL

    def __post_init__(self) -> None:
        if self.outside not in ("euclidean", "lines"):
            raise ValueError(f"outside must be 'euclidean' or 'lines', got {self.outside!r}")
        if self.focus_tol is not None and self.outside != "euclidean":
            raise ValueError("focus_tol needs outside='euclidean' (eq. 7 outside has no distance bracket)")
        if self.labelling not in LABELLING_PATHS:
            raise ValueError(f"labelling must be one of {LABELLING_PATHS}, got {self.labelling!r}")

    com_iterations: int = 10  # fixed-point iterations for the CoM offset
    com_tol: float = 3e-5  # [m], residual of the CoM fixed point (joint-angle error ~3e-5 rad)
    # How analytic_margin_batch (and so the dataset) labels many states: "batched" (contact problems
    # over the batch, one solver per program structure: the labels of learned margin v2) or "per_state"
    # (analytic_margin on each state, the path before it). Same margins to within focus_tol; the
    # single-state analytic_margin is the same either way.
    labelling: str = "batched"

    @classmethod
    def from_dict(cls, values: dict[str, object]) -> AnalyticSettings:
        """The inverse of :meth:`as_dict` (as recorded in dataset manifests and model cards).

        Raises:
            ValueError: a key that is not a setting (names it).
        """
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown analytic settings {unknown}; known: {sorted(known)}")
        friction = values.get("friction", "cone")
        # Settings recorded before the batched path existed do not name a path: theirs was per state.
        friction = tuple(friction) if isinstance(friction, list) else friction
        return cls(**{**values, "friction": friction, "labelling": values.get("labelling", "per_state")})  # type: ignore[arg-type]

    def as_dict(self) -> dict[str, object]:
        return {
            "friction": list(self.friction) if isinstance(self.friction, tuple) else self.friction,
            "tol": self.tol,
            "contact_torque_limit": self.contact_torque_limit,
            "max_lps": self.max_lps,
            "outside": self.outside,
            "focus_tol": self.focus_tol,
            "com_iterations": self.com_iterations,
            "com_tol": self.com_tol,
            "labelling": self.labelling,
        }


@dataclass(frozen=True)
class AnalyticMarginResult:
    """Result of :func:`analytic_margin`."""

    margin: float  # m_a [m]; NaN unless status == "ok"
    status: str
    region: FeasibleRegion | None  # frame H, relative to the current CoM
    capture_point: np.ndarray  # (2,) ICP in H relative to the current CoM [m]
    com_height: float  # CoM height above the stance contact points [m]
    joint_pos: np.ndarray  # (12,) from IK [rad] (NaN where unreachable)
    timings: dict[str, float] = field(default_factory=dict)  # [s]: kinematics_dynamics, region, total
    message: str = ""

    @property
    def n_lps(self) -> int:
        return 0 if self.region is None else self.region.n_lps


def _failed(status: str, t0: float, q: np.ndarray, message: str, **timings: float) -> AnalyticMarginResult:
    """Result of a state without a margin (status other than ok)."""
    return AnalyticMarginResult(
        margin=float("nan"),
        status=status,
        region=None,
        capture_point=np.full(2, np.nan),
        com_height=float("nan"),
        joint_pos=q,
        timings={**timings, "total": time.perf_counter() - t0},
        message=message,
    )


def analytic_margin(robot: Robot, lam: np.ndarray, settings: AnalyticSettings | None = None) -> AnalyticMarginResult:
    """Analytic stability margin m_a of one state (see the module docstring for the pipeline).

    Args:
        robot: from :func:`margin_rl.load_robot`.
        lam: (47,) lambda (:mod:`margin_rl.stability.analytic.lambda_state`).
        settings: analytic settings; defaults if omitted.

    Returns:
        :class:`AnalyticMarginResult`; never raises for unreachable feet or empty regions (statuses).

    Raises:
        ValueError: lambda of the wrong shape, with NaN/inf (the message names the field), a
            non-unit gravity axis, contact flags other than 0/1, or mu <= 0.
    """
    t0 = time.perf_counter()
    s = AnalyticSettings() if settings is None else settings
    lam = check_lambda(lam)
    if lam.shape != (LAMBDA_DIM,):
        raise ValueError(f"one lambda of shape ({LAMBDA_DIM},) is expected, got {lam.shape}")
    problem = contact_problem(robot, lam[None], s.com_iterations, s.com_tol)[0]  # one state: a batch of one
    t1 = time.perf_counter()
    if problem.status != "ok":
        return _failed(problem.status, t0, problem.joint_pos, problem.message, kinematics=t1 - t0)

    # 4. Feasible region of the CoM over the stance contact points, focused on the ICP (step 5).
    icp = problem.capture_point
    focused = s.focus_tol is not None
    region = solve_region(
        problem.contact_set(s.friction, s.contact_torque_limit),
        problem.leg_limits(),
        problem.load(),
        RegionSettings(tol=s.tol, max_lps=s.max_lps, focus_tol=s.focus_tol if focused else DEFAULT_FOCUS_TOL),
        focus=icp if focused else None,
    )
    t2 = time.perf_counter()
    timings = {"kinematics_dynamics": t1 - t0, "region": t2 - t1}
    if region.status != "ok":
        status = "infeasible" if region.status == "empty" else "solver_error"
        return AnalyticMarginResult(
            margin=float("nan"),
            status=status,
            region=region,
            capture_point=np.full(2, np.nan),
            com_height=problem.com_height,
            joint_pos=problem.joint_pos,
            timings={**timings, "total": time.perf_counter() - t0},
            message=region.message,
        )

    # 5. Margin of the ICP.
    margin = float(stability_margin(region, icp, outside=s.outside))
    return AnalyticMarginResult(
        margin=margin,
        status="ok",
        region=region,
        capture_point=np.asarray(icp),
        com_height=problem.com_height,
        joint_pos=problem.joint_pos,
        timings={**timings, "total": time.perf_counter() - t0},
    )


# ----------------------------------------------------------------------------- batch evaluation
@dataclass(frozen=True)
class BatchMargins:
    """Margins of many states: ``margin`` (N,) [m] (NaN unless ok), ``status`` (N,) int8 indices into
    :data:`STATUSES`, ``n_lps`` (N,) and ``seconds`` (N,) per state."""

    margin: np.ndarray
    status: np.ndarray
    n_lps: np.ndarray
    seconds: np.ndarray

    def counts(self) -> dict[str, int]:
        return {name: int(np.sum(self.status == i)) for i, name in enumerate(STATUSES)}


_WORKER_ROBOT: dict[str, Robot] = {}


def worker_robot(name: str) -> Robot:
    """This process's copy of robot ``name``, loaded once (batch and dataset workers reuse it)."""
    if name not in _WORKER_ROBOT:
        _WORKER_ROBOT[name] = load_robot(name)
    return _WORKER_ROBOT[name]


def _evaluate_chunk(args: tuple[Robot | str, np.ndarray, AnalyticSettings]) -> tuple[np.ndarray, ...]:
    robot, lams, settings = args
    robot = worker_robot(robot) if isinstance(robot, str) else robot
    # The batched path needs the focused projection (the labels' default): its margin is the bracket's
    # inner end, and it builds no FeasibleRegion. Other settings are labelled state by state.
    if settings.labelling == "batched" and settings.focus_tol is not None:
        return _label_batched(robot, lams, settings)
    n = len(lams)
    margin, status = np.full(n, np.nan), np.zeros(n, dtype=np.int8)
    n_lps, seconds = np.zeros(n, dtype=np.int16), np.zeros(n)
    for i, lam in enumerate(lams):
        r = analytic_margin(robot, lam, settings)
        margin[i], status[i] = r.margin, STATUSES.index(r.status)
        n_lps[i], seconds[i] = r.n_lps, r.timings["total"]
    return margin, status, n_lps, seconds


def _stance_programs(
    batch: ContactProblem, states: np.ndarray, structure: ProgramStructure, w_max: float, extent: float
) -> tuple[np.ndarray, np.ndarray]:
    """The region programs' data (:func:`program_values`) of ``states`` of ``batch``, each with
    ``structure.n_stance`` stance feet (taken in leg order)."""
    feet = np.nonzero(batch.stance[states])[1].reshape(len(states), structure.n_stance)
    rows = states[:, None]
    limits = batch.torque_limits[feet]
    return program_values(
        structure,
        batch.contact_points[rows, feet],
        batch.normals[rows, feet],
        batch.mu[states],
        batch.jacobians[rows, feet],
        -limits,
        limits,
        batch.leg_bias[rows, feet],
        batch.wrench[states, :3],
        batch.wrench[states, 3:],
        w_max,
        extent,
    )


def _label_batched(robot: Robot, lams: np.ndarray, s: AnalyticSettings) -> tuple[np.ndarray, ...]:
    """``(margin, status, n_lps, seconds)`` of many states by the batched path (``labelling="batched"``).

    The same steps as :func:`analytic_margin` with ``s.focus_tol`` set: the contact problems of the
    whole batch at once (:func:`~margin_rl.stability.analytic.contact_problem.contact_problem`), then, per
    number of stance feet, the programs' data of all those states at once and one re-used solver
    (:mod:`~margin_rl.stability.geometry.region_batch`), the focused projection of each state, and its margin
    from the region's vertices as in step 5 (the bare vertices and half-spaces: no FeasibleRegion is
    returned). A region reaching the clipping box is a solver error, as an "unbounded" one is. ``seconds``
    spreads the shared work evenly over the states.
    """
    assert s.focus_tol is not None  # callers dispatch unfocused settings to the per-state path
    t_start = time.perf_counter()
    n_states = len(lams)
    batch = contact_problem(robot, lams, s.com_iterations, s.com_tol)
    margin, status = np.full(n_states, np.nan), np.zeros(n_states, dtype=np.int8)
    n_lps, seconds = np.zeros(n_states, dtype=np.int16), np.zeros(n_states)
    status[batch.below_feet] = STATUSES.index("infeasible")
    status[batch.unreachable] = STATUSES.index("unreachable")
    status[batch.no_contact] = STATUSES.index("no_contact")
    # Validated once for the batch (solve_region checks them on every call).
    n_faces = parse_friction(s.friction)
    tol = positive_scalar("tol", s.tol)
    focus_tol = positive_scalar("focus_tol", s.focus_tol)
    w_max = positive_scalar("contact_torque_limit", s.contact_torque_limit, allow_zero=True)
    if isinstance(s.max_lps, bool) or not isinstance(s.max_lps, (int, np.integer)) or s.max_lps < 4:
        raise ValueError(f"max_lps must be an integer >= 4, got {s.max_lps!r}")
    extent = RegionSettings().extent
    box = extent - UNBOUNDED_TOL
    solvable = batch.solvable
    n_stance = batch.stance.sum(axis=1)
    limits = batch.torque_limits
    seconds += (time.perf_counter() - t_start) / max(n_states, 1)

    # The solvers' set-up (equilibration) comes from the standing state, the same for every batch.
    reference = contact_problem(robot, standing_state(robot)[None], s.com_iterations, s.com_tol)
    for n in np.unique(n_stance[solvable]).tolist():
        t_group = time.perf_counter()
        states = np.flatnonzero(solvable & (n_stance == n))
        structure = ProgramStructure.of(n, limits.shape[1], n_faces)
        values, b = _stance_programs(batch, states, structure, w_max, extent)
        # The standing state's first n feet: a program of this structure with typical magnitudes.
        stance_n = np.arange(len(robot.legs)) < n
        ref_values, ref_b = _stance_programs(
            replace(reference, stance=stance_n[None]), np.zeros(1, dtype=int), structure, w_max, extent
        )
        oracle = ReusedRegionSolver(structure, ref_values[0], ref_b[0])
        seconds[states] += (time.perf_counter() - t_group) / len(states)
        for j, i in enumerate(states.tolist()):
            t_state = time.perf_counter()
            oracle.load(values[j], b[j])
            fx, fy = batch.capture_point[i].tolist()
            proj = iterative_projection(oracle, tol, int(s.max_lps), focus=(fx, fy), focus_tol=focus_tol)
            n_lps[i] = oracle.n_solves
            if proj.status == "empty":
                status[i] = STATUSES.index("infeasible")
            elif proj.status == "solver_error":
                status[i] = STATUSES.index("solver_error")
            else:
                # The region's vertices and eq. 7 / the Euclidean distance, as solve_region and step 5.
                vertices = np.asarray(convex_polygon([(x, y) for x, y in proj.points.tolist()])).reshape(-1, 2)
                if (np.abs(vertices) >= box).any():  # an "unbounded" region
                    status[i] = STATUSES.index("solver_error")
                else:
                    region = FeasibleRegion(
                        vertices, halfspaces_from_polygon(vertices), "ok", True, proj.n_evals, 0.0, math.nan, proj.gap
                    )
                    margin[i] = stability_margin(region, (fx, fy), outside="euclidean")
            seconds[i] += time.perf_counter() - t_state
    return margin, status, n_lps, seconds


def _chunks(robot: Robot | str, lams: np.ndarray, settings: AnalyticSettings, size: int) -> Iterator[tuple]:
    for start in range(0, len(lams), size):
        yield robot, lams[start : start + size], settings


def analytic_margin_batch(
    robot: Robot | str,
    lams: np.ndarray,
    settings: AnalyticSettings | None = None,
    workers: int | None = None,
    chunk_size: int = 256,
) -> BatchMargins:
    """Analytic margins of many states, in parallel over local processes.

    Args:
        robot: a :class:`Robot`, or a name accepted by :func:`margin_rl.load_robot`; worker processes load
            their own copy by name, one process (``workers=1``) uses a Robot as given.
        lams: (N, 47) lambda.
        settings: analytic settings.
        workers: number of processes; ``os.cpu_count()`` if omitted, 1 runs in this process.
        chunk_size: states per task.
    """
    lams = check_lambda(lams, "lams")
    if lams.ndim != 2:
        raise ValueError(f"lams must have shape (N, {LAMBDA_DIM}), got {lams.shape}")
    s = AnalyticSettings() if settings is None else settings
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if workers == 1 or len(lams) <= chunk_size:
        parts = [_evaluate_chunk(t) for t in _chunks(robot, lams, s, chunk_size)]
    else:
        name = robot if isinstance(robot, str) else robot.name
        tasks = list(_chunks(name, lams, s, chunk_size))
        # fork is cheap and safe here: workers only run numpy, Pinocchio and Clarabel.
        with multiprocessing.get_context("fork").Pool(workers) as pool:
            parts = pool.map(_evaluate_chunk, tasks)
    if not parts:
        empty = np.zeros(0)
        return BatchMargins(empty, empty.astype(np.int8), empty.astype(np.int16), empty)
    return BatchMargins(*(np.concatenate(p) for p in zip(*parts, strict=True)))
