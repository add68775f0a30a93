r"""Three CoM planners for a crawl's base-motion phase, one interface (seed 004 §V, §VI-A).

Every planner gets a :class:`BaseMotionTask` (where the CoM starts, where the four feet are, which leg
swings next, the known external wrench and the torque limits) and returns a :class:`BaseMotionPlan`:
``N + 1`` knots of horizontal CoM position and velocity, zero velocity at both ends, and the phase
duration :math:`\Delta t_{bm}`. All three end with the CoM inside the next triple stance's support
triangle shrunk by ``gait.stability_margin`` (static stability of the swing that follows).

* ``"heuristic"`` (:class:`HeuristicPlanner`): the least motion that is safe. The target is the point
  of the shrunk next support triangle nearest to the centre of the four feet (the CoM's natural place),
  reached along a minimum-jerk profile in ``gait.base_motion_duration``. It ends near the triangle's
  diagonal, the way a classical crawl moves "just enough" into the next support triangle.
* ``"cwc"`` and ``"fwp"`` (:class:`WrenchPolytopePlanner`): eq. (25)-(28). Variables
  :math:`\Gamma = \{c_{x,y}[k], \dot c_{x,y}[k], \Delta t_{bm}\}_{k=1..N}` (41 for N = 10, Table III),
  backward Euler :math:`\dot c[k+1] = (c[k+1] - c[k]) / h`, :math:`h = \Delta t_{bm}/N`, zero velocity at
  both ends, the CoM height held, every knot's CoM keeping the feet in the legs' range of motion
  (``gait.workspace_box``, simple bounds) and its acceleration within ``gait.max_acceleration`` per
  axis (without it the optimum starts and stops in one knot interval, and the jerk at the phase's start
  asks the legs for more than their torque limits). The cost is the pseudo-inverse weight deviation of eq. (28) in the
  polytope of each phase (:mod:`~margin_rl.planning.crawl.polytopes`): the mean over the knots
  :math:`k = 1..N` in the four-foot polytope with the knot's acceleration
  :math:`\ddot c[k] = (\dot c[k] - \dot c[k-1]) / h`, plus the static wrench of the final CoM in the
  triple-stance polytope (the pose held through the swing), plus :math:`\rho\,\Delta t_{bm}`, the price of
  time that stands for the crawl's desired speed (``time_weight``). Solved by IPOPT with exact second
  derivatives (CasADi), built once per planner and re-used with the stance as parameters.

Deviations from the paper, stated: the cost is the *squared* norm of eq. (28) (smooth at its minimum;
the same minimiser for one knot), scaled by the vertex count (see the polytopes module); the time price
is ours (the paper keeps "the desired linear speed" without saying how).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import casadi as ca
import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from margin_rl.planning.crawl.gait import (
    CrawlGait,
    leg_index,
    support_triangle,
    triangle_halfplanes,
    workspace_bounds,
)
from margin_rl.planning.crawl.polytopes import StancePolytope, StanceSnapshot, stance_polytope
from margin_rl.robot import Robot

FloatArray = NDArray[np.float64]

PLANNER_NAMES: tuple[str, ...] = ("heuristic", "cwc", "fwp")
"""The crawl's CoM planners, in the order the experiments report them."""


@dataclass(frozen=True)
class BaseMotionTask:
    """One base-motion phase to plan (world frame W, z up, crawl along +x; SI units).

    Attributes:
        com_start: (3,) CoM at the start of the phase; its height is held.
        feet: (4, 3) foot-sphere centres, all four on the ground during the phase.
        swing: the leg that swings after the phase.
        normals: (4, 3) terrain normals at the feet.
        mu: friction coefficient.
        ext_force: (3,) known external force on the robot (a carried load) [N].
        ext_torque: (3,) its moment about the CoM [N m].
        torque_limits: (4, 3) joint-torque limits the planner assumes [N m].
        foothold: (3,) where the swing leg will land; the CoM is held through the swing, so the end pose
            must keep that foothold in reach too. None: no such requirement.
    """

    com_start: FloatArray
    feet: FloatArray
    swing: str
    normals: FloatArray
    mu: float
    ext_force: FloatArray
    ext_torque: FloatArray
    torque_limits: FloatArray
    foothold: FloatArray | None = None

    def __post_init__(self) -> None:
        leg_index(self.swing)
        if self.foothold is not None:
            value = np.asarray(self.foothold, dtype=float)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise ValueError(f"BaseMotionTask.foothold must be a finite array of shape (3,), got {value.shape}")
        for name, shape in (("com_start", (3,)), ("feet", (4, 3)), ("normals", (4, 3)), ("ext_force", (3,)),
                            ("ext_torque", (3,)), ("torque_limits", (4, 3))):  # fmt: skip
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != shape or not np.all(np.isfinite(value)):
                raise ValueError(f"BaseMotionTask.{name} must be a finite array of shape {shape}, got {value.shape}")
        if not (np.isfinite(self.mu) and self.mu > 0):
            raise ValueError(f"BaseMotionTask.mu must be positive, got {self.mu!r}")

    def snapshot(self, com: np.ndarray, swing_lifted: bool) -> StanceSnapshot:
        """The static pose with the CoM at ``com`` (3,), in four-foot or triple stance."""
        stance = np.ones(4, dtype=bool)
        if swing_lifted:
            stance[leg_index(self.swing)] = False
        return StanceSnapshot(
            np.asarray(com, float), np.asarray(self.feet, float), stance, np.asarray(self.normals, float),
            float(self.mu), np.asarray(self.ext_force, float), np.asarray(self.ext_torque, float),
            np.asarray(self.torque_limits, float),
        )  # fmt: skip

    def triangle(self) -> FloatArray:
        """(3, 2) the next triple stance's support triangle (counter-clockwise)."""
        return support_triangle(np.asarray(self.feet)[:, :2], self.swing)


@dataclass(frozen=True)
class BaseMotionPlan:
    """A planned base motion: knots k = 0..N at times ``k * duration / N``.

    Attributes:
        planner: the planner's name.
        com_xy: (N + 1, 2) horizontal CoM positions [m, W]; the height stays ``com_height``.
        com_vel_xy: (N + 1, 2) backward-Euler velocities [m/s] (``com_vel_xy[k]`` is the speed of the segment
            ending at knot k); zero at both ends for the optimised plans; the heuristic's minimum-jerk profile
            is at rest at both ends, its last segment moves 0.9 % of the distance.
        com_height: CoM height [m, W].
        duration: Delta t_bm [s].
        solve_seconds: the optimisation (or the heuristic's arithmetic).
        polytope_seconds: building the stance polytopes (zero for the heuristic).
        iterations: IPOPT iterations (0 for the heuristic).
        success: the solver converged (always True for the heuristic).
        polytopes: the stance polytopes planned in (four-foot, triple), empty for the heuristic.
        cost: the optimal wrench cost (without the time price).
    """

    planner: str
    com_xy: FloatArray
    com_vel_xy: FloatArray
    com_height: float
    duration: float
    solve_seconds: float
    polytope_seconds: float
    iterations: int
    success: bool
    polytopes: tuple[StancePolytope, ...] = field(default=(), repr=False)
    cost: float = float("nan")  # the wrench cost of eq. (28) (without the time price); NaN for the heuristic

    @property
    def end_com(self) -> FloatArray:
        """(3,) CoM at the end of the phase."""
        return np.array([*self.com_xy[-1], self.com_height])

    def com_at(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """CoM (3,), velocity (3,) and acceleration (3,) at time ``t`` in [0, duration], from the clamped cubic
        spline through the knots (at rest at both ends). The knots' piecewise-constant backward-Euler
        velocities would step at the start of the phase, a force kick the controller passes to the legs."""
        u = float(np.clip(t, 0.0, self.duration))
        spline = self._spline()
        pos, vel, acc = spline(u), spline(u, 1), spline(u, 2)
        return np.array([*pos, self.com_height]), np.array([*vel, 0.0]), np.array([*acc, 0.0])

    def _spline(self) -> CubicSpline:
        times = np.linspace(0.0, self.duration, self.com_xy.shape[0])
        return CubicSpline(times, self.com_xy, axis=0, bc_type="clamped")


class CrawlPlanner(Protocol):
    """What the crawl executes: a name and ``plan(task) -> BaseMotionPlan``."""

    name: str

    def plan(self, task: BaseMotionTask) -> BaseMotionPlan: ...


def shrunk_triangle_vertices(a: np.ndarray, b: np.ndarray) -> FloatArray:
    """(3, 2) vertices of the triangle ``a c <= b`` (rows as from :func:`triangle_halfplanes`)."""
    verts = [np.linalg.solve(np.array([a[k], a[(k + 1) % 3]]), np.array([b[k], b[(k + 1) % 3]])) for k in range(3)]
    return np.array(verts)


def nearest_point_in_triangle(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> FloatArray:
    """The point (2,) of the triangle ``a c <= b`` nearest to ``point`` (2,)."""
    p = np.asarray(point, dtype=float)
    if np.all(a @ p <= b + 1e-12):
        return p.copy()
    verts = shrunk_triangle_vertices(a, b)
    best, best_d = verts[0], np.inf
    for k in range(3):
        q0, q1 = verts[k], verts[(k + 1) % 3]
        edge = q1 - q0
        t = float(np.clip((p - q0) @ edge / (edge @ edge), 0.0, 1.0))
        cand = q0 + t * edge
        d = float(np.linalg.norm(cand - p))
        if d < best_d:
            best, best_d = cand, d
    return best


def _minimum_jerk(start: FloatArray, end: FloatArray, duration: float, knots: int) -> tuple[FloatArray, FloatArray]:
    s = np.linspace(0.0, 1.0, knots + 1)
    shape = 10 * s**3 - 15 * s**4 + 6 * s**5
    xy = start + shape[:, None] * (end - start)
    # Backward-Euler velocities of the sampled profile, so that every planner's knots obey eq. (25).
    vel = np.zeros_like(xy)
    vel[1:] = np.diff(xy, axis=0) / (duration / knots)
    return xy, vel


class HeuristicPlanner:
    """The least safe motion: into the next support triangle, towards the centre of the four feet."""

    name = "heuristic"

    def __init__(self, gait: CrawlGait) -> None:
        self.gait = gait

    def target(self, task: BaseMotionTask) -> FloatArray:
        """(2,) end CoM: the shrunk next support triangle's point nearest to the centre of the four feet."""
        a, b = triangle_halfplanes(task.triangle(), self.gait.stability_margin)
        return nearest_point_in_triangle(np.asarray(task.feet)[:, :2].mean(axis=0), a, b)

    def plan(self, task: BaseMotionTask) -> BaseMotionPlan:
        t0 = time.perf_counter()
        start = np.asarray(task.com_start, dtype=float)[:2]
        xy, vel = _minimum_jerk(start, self.target(task), self.gait.base_motion_duration, self.gait.knots)
        return BaseMotionPlan(
            self.name, xy, vel, float(task.com_start[2]), self.gait.base_motion_duration,
            time.perf_counter() - t0, 0.0, 0, True,
        )  # fmt: skip


@dataclass(frozen=True)
class _Program:
    solver: ca.Function
    cost: ca.Function  # (x, p) -> the objective, for checks against an independent implementation
    n_knots: int
    n_params: int


def _build_program(knots: int) -> _Program:
    """Eq. (25)-(28) as a parametric NLP (symbols, once per knot count)."""
    n = knots
    cx, cy, vx, vy = (ca.SX.sym(name, n) for name in ("cx", "cy", "vx", "vy"))
    dt = ca.SX.sym("dt")
    # Parameters: start (2), mass, gravity, ext force (3), ext torque (3), reference CoM xy (2),
    # four-foot metric (36) and centroid (6), triple metric (36) and centroid (6), triangle A (6) and b (3), rho,
    # the acceleration bound.
    p = ca.SX.sym("p", 2 + 1 + 1 + 3 + 3 + 2 + 42 + 42 + 9 + 1 + 1)
    i = 0

    def take(size: int) -> ca.SX:
        nonlocal i
        out = p[i : i + size]
        i += size
        return out

    start, mass, g, f_ext, t_ext, ref = take(2), take(1), take(1), take(3), take(3), take(2)
    m4, c4 = ca.reshape(take(36), 6, 6), take(6)
    m3, c3 = ca.reshape(take(36), 6, 6), take(6)
    tri_a, tri_b, rho, a_max = ca.reshape(take(6), 3, 2), take(3), take(1), take(1)
    h = dt / n

    def wrench(x: ca.SX, y: ca.SX, ax: ca.SX, ay: ca.SX) -> ca.SX:
        force = ca.vertcat(mass * ax, mass * ay, mass * g) - f_ext
        offset = ca.vertcat(x - ref[0], y - ref[1], 0.0)
        return ca.vertcat(force, ca.cross(offset, force) - t_ext)

    def quad(metric: ca.SX, centroid: ca.SX, w: ca.SX) -> ca.SX:
        d = w - centroid
        return ca.dot(d, ca.mtimes(metric, d))

    px = ca.vertcat(start[0], cx)
    py = ca.vertcat(start[1], cy)
    qx = ca.vertcat(0.0, vx)
    qy = ca.vertcat(0.0, vy)
    running = 0
    for k in range(1, n + 1):
        running += quad(m4, c4, wrench(px[k], py[k], (qx[k] - qx[k - 1]) / h, (qy[k] - qy[k - 1]) / h))
    terminal = quad(m3, c3, wrench(px[n], py[n], 0.0, 0.0))
    cost = running / n + terminal + rho * dt
    euler = [qx[k + 1] - (px[k + 1] - px[k]) / h for k in range(n)] + [
        qy[k + 1] - (py[k + 1] - py[k]) / h for k in range(n)
    ]
    # Accelerations of the knots, (v[k] - v[k-1]) h = a[k] h^2 ... kept within +-a_max (bounded below as a * h).
    accel = (
        [(qx[k] - qx[k - 1]) - a_max * h for k in range(1, n + 1)]
        + [-(qx[k] - qx[k - 1]) - a_max * h for k in range(1, n + 1)]
        + [(qy[k] - qy[k - 1]) - a_max * h for k in range(1, n + 1)]
        + [-(qy[k] - qy[k - 1]) - a_max * h for k in range(1, n + 1)]
    )
    g_all = ca.vertcat(*euler, vx[n - 1], vy[n - 1], ca.mtimes(tri_a, ca.vertcat(cx[n - 1], cy[n - 1])) - tri_b, *accel)
    x = ca.vertcat(cx, cy, vx, vy, dt)
    options = {
        "ipopt.print_level": 0,
        "print_time": False,
        "ipopt.sb": "yes",
        "ipopt.tol": 1e-8,
        "ipopt.max_iter": 200,
    }
    solver = ca.nlpsol("crawl_base_motion", "ipopt", {"x": x, "p": p, "f": cost, "g": g_all}, options)
    return _Program(solver, ca.Function("cost", [x, p], [cost]), n, int(p.shape[0]))


class WrenchPolytopePlanner:
    """Eq. (25)-(28) in the FWP (``kind="fwp"``) or the bounded contact wrench cone (``kind="cwc"``)."""

    def __init__(self, robot: Robot, gait: CrawlGait, kind: str = "fwp", time_weight: float = 0.05) -> None:
        if kind not in ("fwp", "cwc"):
            raise ValueError(f"kind must be 'fwp' or 'cwc', got {kind!r}")
        if not (np.isfinite(time_weight) and time_weight >= 0):
            raise ValueError(f"time_weight must be >= 0, got {time_weight!r}")
        self.robot, self.gait, self.kind, self.time_weight = robot, gait, kind, float(time_weight)
        self.name = kind
        self._heuristic = HeuristicPlanner(gait)
        self._program = _build_program(gait.knots)
        q = robot.standing_joint_pos
        self.nominal_offsets = (robot.foot_positions(q) - robot.com_position(q))[:, :2]

    def polytopes(self, task: BaseMotionTask) -> tuple[StancePolytope, StancePolytope]:
        """Four-foot and triple-stance polytopes at the heuristic plan's end pose (constant J(q_0), §V-A)."""
        reference = np.array([*self._heuristic.target(task), float(task.com_start[2])])
        four = stance_polytope(self.robot, task.snapshot(reference, swing_lifted=False), self.kind)
        triple = stance_polytope(self.robot, task.snapshot(reference, swing_lifted=True), self.kind)
        return four, triple

    def parameters(self, task: BaseMotionTask, four: StancePolytope, triple: StancePolytope) -> FloatArray:
        a, b = triangle_halfplanes(task.triangle(), self.gait.stability_margin)
        return np.concatenate([
            np.asarray(task.com_start, float)[:2], [self.robot.total_mass, self.robot.gravity],
            np.asarray(task.ext_force, float), np.asarray(task.ext_torque, float), four.reference_com[:2],
            four.metric.ravel(order="F"), four.centroid, triple.metric.ravel(order="F"), triple.centroid,
            a.ravel(order="F"), b, [self.time_weight], [self.gait.max_acceleration],
        ])  # fmt: skip

    def position_bounds(self, task: BaseMotionTask) -> tuple[FloatArray, FloatArray]:
        """Simple bounds on the variables: the workspace box of the four feet at every knot, and at the last
        knot (held through the swing) also of the swing leg's foothold; Delta t_bm is bounded in :meth:`solve`."""
        n = self.gait.knots
        feet, offsets = np.asarray(task.feet, dtype=float)[:, :2], self.nominal_offsets
        lower, upper = workspace_bounds(feet, offsets, self.gait.workspace_box)
        lower_end, upper_end = lower.copy(), upper.copy()
        if task.foothold is not None:
            swing = leg_index(task.swing)
            feet_end = np.vstack([feet, np.asarray(task.foothold, dtype=float)[:2]])
            lower_end, upper_end = workspace_bounds(
                feet_end, np.vstack([offsets, offsets[swing]]), self.gait.workspace_box
            )
        lo = np.column_stack([np.full(n, lower[0]), np.full(n, lower[1])])
        hi = np.column_stack([np.full(n, upper[0]), np.full(n, upper[1])])
        lo[-1], hi[-1] = lower_end, upper_end
        lbx = np.concatenate([lo[:, 0], lo[:, 1], np.full(2 * n, -np.inf), [0.0]])
        ubx = np.concatenate([hi[:, 0], hi[:, 1], np.full(2 * n, np.inf), [0.0]])
        return lbx, ubx

    def wrench_cost_at(
        self, task: BaseMotionTask, four: StancePolytope, triple: StancePolytope, duration: float
    ) -> float:
        """The optimal cost without the time price, with Delta t_bm fixed at ``duration`` [s]."""
        saved = self.time_weight
        try:
            self.time_weight = 0.0
            plan = self.solve(task, four, triple, bounds=(duration, duration))
        finally:
            self.time_weight = saved
        return plan.cost

    def calibrate(self, task: BaseMotionTask, step: float = 0.1) -> float:
        """Set the time price rho so that ``task`` is planned at the nominal duration, and return it.

        Rule: rho = -dJ/d(Delta t_bm) at ``gait.base_motion_duration`` (central difference over +-``step``),
        the wrench cost's marginal gain from a slower phase. Calibrated on the unloaded crawl's first
        step, the planner keeps the nominal pace there and slows down only where accelerating costs more
        (a load, a hindered joint), which is how the paper's planner "finds a new duration".
        """
        four, triple = self.polytopes(task)
        nominal = self.gait.base_motion_duration
        slower = self.wrench_cost_at(task, four, triple, nominal + step)
        faster = self.wrench_cost_at(task, four, triple, nominal - step)
        self.time_weight = max(0.0, (faster - slower) / (2.0 * step))
        return self.time_weight

    def solve(
        self,
        task: BaseMotionTask,
        four: StancePolytope,
        triple: StancePolytope,
        polytope_seconds: float = 0.0,
        bounds: tuple[float, float] | None = None,
    ) -> BaseMotionPlan:
        """The optimisation alone, in given polytopes (what the paper times as step b); ``bounds`` overrides
        ``gait.duration_bounds``."""
        n, gait = self.gait.knots, self.gait
        start = np.asarray(task.com_start, dtype=float)[:2]
        target = self._heuristic.target(task)
        guess_xy, guess_v = _minimum_jerk(start, target, gait.base_motion_duration, n)
        x0 = np.concatenate(
            [guess_xy[1:, 0], guess_xy[1:, 1], guess_v[1:, 0], guess_v[1:, 1], [gait.base_motion_duration]]
        )
        lbx, ubx = self.position_bounds(task)
        lbx[-1], ubx[-1] = gait.duration_bounds if bounds is None else bounds
        n_g = 2 * n + 2 + 3 + 4 * n
        lbg = np.concatenate([np.zeros(2 * n + 2), np.full(3 + 4 * n, -np.inf)])
        ubg = np.zeros(n_g)
        t0 = time.perf_counter()
        sol = self._program.solver(x0=x0, p=self.parameters(task, four, triple), lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        seconds = time.perf_counter() - t0
        stats = self._program.solver.stats()
        x = np.asarray(sol["x"]).ravel()
        xy = np.vstack([start, np.column_stack([x[:n], x[n : 2 * n]])])
        vel = np.vstack([np.zeros(2), np.column_stack([x[2 * n : 3 * n], x[3 * n : 4 * n]])])
        return BaseMotionPlan(
            self.name, xy, vel, float(task.com_start[2]), float(x[-1]), seconds, polytope_seconds,
            int(stats.get("iter_count", -1)), bool(stats.get("success", False)), (four, triple),
            float(sol["f"]) - self.time_weight * float(x[-1]),
        )  # fmt: skip

    def plan(self, task: BaseMotionTask) -> BaseMotionPlan:
        """Eq. (25)-(28) in the polytopes of the heuristic plan's end pose (the paper's step a, then step b)."""
        t0 = time.perf_counter()
        four, triple = self.polytopes(task)
        return self.solve(task, four, triple, polytope_seconds=time.perf_counter() - t0)


def make_planner(name: str, robot: Robot, gait: CrawlGait, time_weight: float = 0.05) -> CrawlPlanner:
    """The planner called ``name`` (one of :data:`PLANNER_NAMES`)."""
    if name == "heuristic":
        return HeuristicPlanner(gait)
    if name in ("cwc", "fwp"):
        return WrenchPolytopePlanner(robot, gait, kind=name, time_weight=time_weight)
    raise ValueError(f"unknown crawl planner {name!r}; choose from {', '.join(PLANNER_NAMES)}")
