"""The trajectory optimisation of seed 000 eq. (9), transcribed for IPOPT through CasADi.

Decision variables (world frame W, z up; m, rad, s):

* base nodes k = 0..N every dT (N = T / dT): CoM position c_k, roll-pitch-yaw rpy_k, CoM velocity v_k,
  Euler-angle rates rpy_dot_k (12 per node). Between nodes the base is the cubic Hermite polynomial
  of the two nodes' values and rates; equality constraints make the second derivatives continuous at
  the interior nodes (a C2 cubic spline), so the CoM acceleration in lambda is unique at every node;
* footholds: one contact point q_j = (x, y, z) per touchdown of the gait in the horizon, held through
  the stance that follows (:mod:`margin_rl.planning.schedule`).

Constraints:

* minimum stability margin: m(lambda(t_k)) >= m_min + backoff at every node, with m the learned margin
  network (or, for the benchmark, the analytic margin with finite differences; or none, the contrast);
  ``backoff`` (default 2 cm) tightens the bound by the network's typical over-estimate near the
  3-contact support edges, measured against the analytic margin (see docs/planning.md), so that the plan's
  *analytic* margin stays above m_min - 1 cm;
* range of motion: every foot-sphere centre inside a box of half-extents ``rom_half_extents``
  around its nominal position in the base frame, at every node (for a swing foot the box's top is
  raised by the swing's height above the line between its footholds at that instant);
* terrain height: q_j,z = h(q_j,xy);
* initial state (node 0) and target state (node N): variable bounds;
* C2 continuity (see above) and acceleration bounds at the nodes (CoM |a_xy| <= 2 m/s^2,
  |a_z| <= 1 m/s^2, Euler accelerations <= 0.8 rad/s^2), which keep lambda inside the ranges the
  network was trained on (Table I: 2.5 m/s^2, 1.25 m/s^2, 1 rad/s^2).

Cost: the paper's w_s sum_j ||dh/dp_xy(q_j)||^2 (terrain slope under each foothold), plus, for a
well-posed problem:

* w_a integral ||c_ddot||^2 + ||rpy_ddot||^2 dt (exact for cubic segments): without it the base
  between the constrained nodes is undetermined wherever the margin constraint is inactive, and IPOPT
  would return any of a continuum of jerky solutions;
* w_f sum_j ||q_j,xy - q_j,ref||^2 with q_j,ref the nominal foot position under the hip at the middle
  of the stance (CoM at that time plus the yaw-rotated nominal foot offset): on level ground the slope
  cost is zero and footholds would otherwise be free within their range of motion (a singular
  Hessian); a small weight keeps them where a nominal gait puts them, so the slope term and the margin
  constraint decide the deviations.

Optional (for the side-step contrast of seed 000 Fig. 7 only): w_c sum_k ||c_k,xy - mean_i f_i,xy(t_k)||^2,
which keeps the CoM over the centroid of the feet as a simplified (single rigid body) model would.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from margin_rl.planning.gait import Gait
from margin_rl.planning.lambda_map import hermite, node_function
from margin_rl.planning.robot_model import PlanningRobot
from margin_rl.planning.schedule import HorizonSchedule, horizon_schedule
from margin_rl.planning.terrain import HeightMap

BASE_DIM = 12
"""Per base node: CoM position (3), roll-pitch-yaw (3), CoM velocity (3), Euler rates (3)."""

MARGIN_KINDS: tuple[str, ...] = ("learned", "analytic_fd", "none")
HESSIANS: dict[str, str] = {"quasi-newton": "limited-memory", "exact": "exact"}
"""PlannerConfig.hessian -> IPOPT's hessian_approximation (exact: every term's second derivatives, the network's
from numpy)."""

_SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


@dataclass(frozen=True)
class BaseState:
    """Base state in W: CoM position [m], roll-pitch-yaw [rad], CoM velocity [m/s], Euler rates [rad/s]."""

    position: np.ndarray
    rpy: np.ndarray
    velocity: np.ndarray
    rpy_rate: np.ndarray

    def __post_init__(self) -> None:
        for name in ("position", "rpy", "velocity", "rpy_rate"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise ValueError(f"BaseState.{name} must be 3 finite numbers, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)

    def as_vector(self) -> np.ndarray:
        return np.concatenate([self.position, self.rpy, self.velocity, self.rpy_rate])

    @classmethod
    def from_vector(cls, x: np.ndarray) -> BaseState:
        x = np.asarray(x, dtype=float)
        if x.shape != (BASE_DIM,):
            raise ValueError(f"a base state vector has {BASE_DIM} entries, got shape {x.shape}")
        return cls(x[0:3], x[3:6], x[6:9], x[9:12])


@dataclass(frozen=True)
class PlannerConfig:
    """Settings of one trajectory optimisation (lengths m, times s, angles rad)."""

    horizon: float = 3.0  # T (seed 000 §V-B)
    node_dt: float = 0.2  # dT (seed 000 §V-B)
    mu: float = 0.7  # friction coefficient in lambda (inside Table I's U(0.2, 0.9))
    margin: str = "learned"  # "learned", "analytic_fd" (benchmark contrast) or "none" (no margin constraint)
    margin_backoff: float = 0.02  # the constraint is m >= m_min + backoff (see the module docstring)
    max_com_acc_xy: float = 2.0
    max_com_acc_z: float = 1.0
    max_euler_acc: float = 0.8
    max_tilt: float = 0.2  # |roll|, |pitch| (Table I samples +-pi/15 = 0.21)
    max_com_vel_xy: float = 1.0
    weight_slope: float = 1.0  # w_s
    weight_foothold: float = 10.0  # w_f [1/m^2]
    weight_acc: float = 0.02  # w_a [s^3/m^2]
    weight_centroid: float = 0.0  # w_c, contrast only
    max_iter: int = 150
    # IPOPT's Hessian of the Lagrangian: "exact" (the network's block Hessians in numpy, assembled with the lambda
    # map's derivatives by the chain rule, margin_rl.planning.lagrangian: 8-17 iterations per horizon) or
    # "quasi-newton" (L-BFGS: 80-120 iterations, 87-100 % converged; the analytic_fd margin has only first derivatives)
    hessian: str = "exact"
    tol: float = 1e-3  # IPOPT tol (scaled optimality error); constraints are met to constr_viol_tol 1e-4
    fd_step: float = 2e-3  # finite-difference step of the analytic_fd margin (lambda units)
    # Half-widths of the box around the target state (BaseState.as_vector order). Lateral position, height,
    # tilt and the non-forward rates are left some freedom: a walk sways its CoM into the next support
    # triangle, and a target pinned on the course line is infeasible when the horizon ends in a
    # three-foot stance (the CoM would sit on a support edge).
    ipopt_options: tuple[tuple[str, object], ...] = ()  # extra IPOPT options, e.g. (("mu_init", 1e-2),)
    target_tolerance: tuple[float, ...] = (0.0, 0.1, 0.03, 0.1, 0.1, 0.0, 0.03, 0.1, 0.1, 0.3, 0.3, 0.1)

    def __post_init__(self) -> None:
        if self.margin not in MARGIN_KINDS:
            raise ValueError(f"margin must be one of {', '.join(MARGIN_KINDS)}, got {self.margin!r}")
        if self.hessian not in HESSIANS:
            raise ValueError(f"PlannerConfig.hessian must be one of {', '.join(HESSIANS)}, got {self.hessian!r}")
        if self.margin == "analytic_fd" and self.hessian == "exact":
            raise ValueError(
                "the analytic_fd margin has first derivatives only (finite differences): use "
                "PlannerConfig(margin='analytic_fd', hessian='quasi-newton')"
            )
        positive = ("horizon", "node_dt", "mu", "max_com_acc_xy", "max_com_acc_z", "max_euler_acc", "max_tilt")
        for name in (*positive, "max_com_vel_xy", "tol", "fd_step"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"PlannerConfig.{name} must be positive, got {value!r}")
        for name in ("weight_slope", "weight_foothold", "weight_acc", "weight_centroid", "margin_backoff"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"PlannerConfig.{name} must be >= 0, got {getattr(self, name)!r}")
        tolerance = np.asarray(self.target_tolerance, dtype=float)
        if tolerance.shape != (BASE_DIM,) or not np.all(tolerance >= 0):
            raise ValueError(
                f"PlannerConfig.target_tolerance needs {BASE_DIM} values >= 0, got {self.target_tolerance!r}"
            )
        if (
            not (isinstance(self.max_iter, int | float) and np.isfinite(self.max_iter))
            or int(self.max_iter) != self.max_iter
            or self.max_iter < 1
        ):
            raise ValueError(f"PlannerConfig.max_iter must be a positive integer, got {self.max_iter!r}")


@dataclass(frozen=True, eq=False)
class Plan:
    """A solved horizon: the base nodes, the footholds and the solver's report."""

    schedule: HorizonSchedule
    base: np.ndarray  # (N + 1, 12) node values (BaseState.as_vector order)
    initial_footholds: np.ndarray  # (4, 3) contact points the legs start from [m]
    footholds: np.ndarray  # (n_slots, 3) contact points, in schedule.slots order [m]
    learned_margins: np.ndarray  # (N + 1,) m_l at the nodes [m] (NaN where no network was given)
    margin_bound: float  # m_min + backoff [m] (NaN without a margin constraint)
    status: str  # IPOPT's return status
    iterations: int
    solve_seconds: float  # wall time of the IPOPT call
    decision: np.ndarray = field(repr=False)  # the raw decision vector (warm starts)

    @property
    def success(self) -> bool:
        return self.status in _SUCCESS

    @property
    def seconds_per_iteration(self) -> float:
        return self.solve_seconds / max(self.iterations, 1)

    @property
    def t0(self) -> float:
        return self.schedule.t0

    @property
    def t_end(self) -> float:
        return float(self.schedule.node_times[-1])

    def leg_footholds(self, leg: int) -> list[np.ndarray]:
        """Contact points of ``leg`` in time order, starting with its current one."""
        return [self.initial_footholds[leg]] + [self.footholds[k] for k in self.schedule.slot_indices(leg)]

    def base_at(self, t: float) -> tuple[np.ndarray, ...]:
        """(position, rpy, velocity, rpy_rate, acceleration, rpy_acc) at time t in [t0, t_end] (numpy)."""
        times = self.schedule.node_times
        if not (times[0] - 1e-9 <= t <= times[-1] + 1e-9):
            raise ValueError(f"time {t} s is outside the plan [{times[0]}, {times[-1]}] s")
        dt = float(times[1] - times[0])
        k = int(min(max(np.floor((t - times[0]) / dt + 1e-9), 0), len(times) - 2))
        tau = float(np.clip(t - times[k], 0.0, dt))
        a, b = self.base[k], self.base[k + 1]
        pos, vel, acc = hermite(a[0:3], a[6:9], b[0:3], b[6:9], dt, tau)
        rpy, rate, rpy_acc = hermite(a[3:6], a[9:12], b[3:6], b[9:12], dt, tau)
        return pos, rpy, vel, rate, acc, rpy_acc

    def state_at(self, t: float) -> BaseState:
        pos, rpy, vel, rate, _, _ = self.base_at(t)
        return BaseState(pos, rpy, vel, rate)

    def foot_centres(self, height_map: HeightMap, radius: float, t: float) -> np.ndarray:
        """(4, 3) foot-sphere centres at time t [m] (W)."""
        out = np.empty((4, 3))
        up = np.array([0.0, 0.0, 1.0])
        for leg in range(4):
            holds = np.array(self.leg_footholds(leg))
            centres = list(holds + radius * height_map.normal(holds[:, :2]))
            out[leg] = self.schedule.foot_centre(leg, t, centres, up)
        return out

    def current_footholds(self, t: float) -> np.ndarray:
        """(4, 3): per leg the foothold it stands on at t, or the one it lifted off from if in swing."""
        out = np.empty((4, 3))
        for leg in range(4):
            holds = self.leg_footholds(leg)
            j = 0
            for swing in self.schedule.swings[leg]:
                if t >= swing.touchdown:
                    j += 1
            out[leg] = holds[j]
        return out


class TrajectoryProblem:
    """Eq. (9) for one horizon structure (gait phase at t0), built once and solved many times.

    Args:
        model: planner facts of the robot.
        height_map: the terrain.
        gait: the gait.
        t0: start time of the horizon [s] (absolute: fixes the gait phase).
        config: the planner settings.
        margin_model: the learned margin (``LearnedMargin``) for ``config.margin == "learned"`` (also
            used to report the learned margin of plans made with another kind).
        chain_rule_hessian: with the learned margin and the exact Hessian, give IPOPT the Lagrangian's Hessian
            assembled by the chain rule (:mod:`margin_rl.planning.lagrangian`); False: CasADi's own second
            derivatives through the network's callbacks, the same matrix at about 1.5 times the time per
            iteration (kept for the benchmark and the tests).
    """

    def __init__(
        self,
        model: PlanningRobot,
        height_map: HeightMap,
        gait: Gait,
        t0: float,
        config: PlannerConfig,
        margin_model: object | None = None,
        *,
        chain_rule_hessian: bool = True,
    ) -> None:
        import casadi as ca

        if config.margin == "learned" and margin_model is None:
            raise ValueError("config.margin='learned' needs margin_model=LearnedMargin.load(robot_name)")
        self.model, self.height_map, self.gait, self.config = model, height_map, gait, config
        self.margin_model = margin_model
        sched = horizon_schedule(gait, t0, config.horizon, config.node_dt)
        self.schedule = sched
        n_nodes, n_slots = sched.n_nodes, len(sched.slots)
        self.n_base = BASE_DIM * n_nodes
        self.n_decision = self.n_base + 3 * n_slots
        dt = config.node_dt
        r = model.foot_radius

        z = ca.MX.sym("z", self.n_decision)
        par = ca.MX.sym("p", 14)  # initial contact points (4 x 3, leg-major) and the target velocity (2)
        B = ca.reshape(z[: self.n_base], BASE_DIM, n_nodes)
        Q = ca.reshape(z[self.n_base :], 3, n_slots) if n_slots else ca.MX.zeros(3, 0)
        P0 = ca.reshape(par[:12], 3, 4)
        v_ref = par[12:14]

        terrain = _terrain_function(height_map)
        up = ca.DM([0.0, 0.0, 1.0])

        def centre(q):  # sphere centre resting on the terrain at contact point q
            _, grad = terrain(q[0:2])
            n = ca.vertcat(-grad[0], -grad[1], 1.0)
            return q + r * n / ca.norm_2(n)

        centres = [[centre(P0[:, leg])] for leg in range(4)]
        for k, slot in enumerate(sched.slots):
            centres[slot.leg].append(centre(Q[:, k]))
        for leg in range(4):
            if len(centres[leg]) != 1 + len(sched.swings[leg]):
                raise AssertionError("foothold slots and swings disagree")

        # Node accelerations from the cubic segments (start of segment k, end of the last one).
        def seg(k, tau, rows_p, rows_v):
            return hermite(B[rows_p, k], B[rows_v, k], B[rows_p, k + 1], B[rows_v, k + 1], dt, tau)

        acc, rpy_acc = [], []
        for k in range(n_nodes):
            kk, tau = (k, 0.0) if k < n_nodes - 1 else (k - 1, dt)
            acc.append(seg(kk, tau, slice(0, 3), slice(6, 9))[2])
            rpy_acc.append(seg(kk, tau, slice(3, 6), slice(9, 12))[2])

        feet_cols, normal_cols = [], []
        for k, t in enumerate(sched.node_times):
            feet_k, normals_k = [], []
            for leg in range(4):
                feet_k.append(sched.foot_centre(leg, float(t), centres[leg], up))
                if sched.contacts[k, leg] > 0:
                    normals_k.append(
                        (feet_k[-1] - sched.foot_centre(leg, float(t), _contact_points(P0, Q, sched, leg), up)) / r
                    )
                else:
                    normals_k.append(up)
            feet_cols.append(ca.vertcat(*feet_k))
            normal_cols.append(ca.vertcat(*normals_k))
        node_fn = node_function(model.com_offset_base, model.nominal_feet_base).map(n_nodes)
        LAM, ROM = node_fn(
            B[0:3, :],
            B[3:6, :],
            B[6:9, :],
            B[9:12, :],
            ca.horzcat(*acc),
            ca.horzcat(*rpy_acc),
            ca.horzcat(*feet_cols),
            ca.horzcat(*normal_cols),
            ca.DM(sched.contacts.T),
            ca.DM.ones(1, n_nodes) * config.mu,
        )

        g, lbg, ubg = [], [], []

        def add(expr, lo, hi):
            expr = ca.vec(expr)
            g.append(expr)
            lbg.append(np.broadcast_to(lo, expr.shape[0]).astype(float))
            ubg.append(np.broadcast_to(hi, expr.shape[0]).astype(float))

        self.margin_bound = float("nan")
        self._margin_rows = slice(0, 0)
        if config.margin != "none":
            self.margin_bound = gait.min_margin + config.margin_backoff
            if config.margin == "learned":
                from margin_rl.planning.mlp import margin_function

                # Kept with the problem: the function's second-derivative callback lives as long as it does.
                self._margin_function = margin_function(margin_model, n_nodes)
                margins = self._margin_function(LAM)
            else:
                from margin_rl.planning.analytic_fd import analytic_margin_function

                self._analytic = analytic_margin_function(model.robot, config.fd_step)
                margins = ca.horzcat(*[self._analytic(LAM[:, k]) for k in range(n_nodes)])
            self._margin_rows = slice(0, n_nodes)
            add(margins, self.margin_bound, np.inf)
        rom_lo = np.tile(-model.rom_half_extents, (n_nodes, 4, 1))
        rom_hi = np.tile(model.rom_half_extents, (n_nodes, 4, 1))
        for k, t in enumerate(sched.node_times):
            for leg in range(4):
                s = sched.swing_fraction(leg, float(t))
                if s is not None:  # the swing apex is above the stance box by construction
                    rom_hi[k, leg, 2] += 4 * s * (1 - s) * gait.swing_height
        add(ROM, rom_lo.reshape(-1), rom_hi.reshape(-1))
        for k in range(n_slots):
            h, _ = terrain(Q[0:2, k])
            add(Q[2, k] - h, 0.0, 0.0)
        for k in range(1, n_nodes - 1):
            end_p, end_r = seg(k - 1, dt, slice(0, 3), slice(6, 9))[2], seg(k - 1, dt, slice(3, 6), slice(9, 12))[2]
            add(ca.vertcat(end_p - acc[k], end_r - rpy_acc[k]), 0.0, 0.0)
        a_max = np.array([config.max_com_acc_xy] * 2 + [config.max_com_acc_z] + [config.max_euler_acc] * 3)
        for k in range(n_nodes):
            add(ca.vertcat(acc[k], rpy_acc[k]), -a_max, a_max)

        # Cost.
        cost = 0
        nominal_xy = model.nominal_feet_com[:, 0:2]
        t_end = float(sched.node_times[-1])
        for k, slot in enumerate(sched.slots):
            _, grad = terrain(Q[0:2, k])
            cost += config.weight_slope * ca.sumsqr(grad)
            t_mid = 0.5 * (slot.touchdown + slot.stance_end)
            c_mid, yaw_mid = self._base_xy_yaw(B, sched, min(t_mid, t_end), dt)
            c_mid = c_mid + v_ref * max(t_mid - t_end, 0.0)
            rot = ca.vertcat(
                ca.horzcat(ca.cos(yaw_mid), -ca.sin(yaw_mid)), ca.horzcat(ca.sin(yaw_mid), ca.cos(yaw_mid))
            )
            ref = c_mid + ca.mtimes(rot, ca.DM(nominal_xy[slot.leg]))
            cost += config.weight_foothold * ca.sumsqr(Q[0:2, k] - ref)
        for k in range(n_nodes - 1):
            for rows in ((slice(0, 3), slice(6, 9)), (slice(3, 6), slice(9, 12))):
                a0, a1 = seg(k, 0.0, *rows)[2], seg(k, dt, *rows)[2]
                cost += config.weight_acc * dt / 3.0 * (ca.dot(a0, a0) + ca.dot(a0, a1) + ca.dot(a1, a1))
        if config.weight_centroid > 0:
            for k in range(n_nodes):
                feet = ca.reshape(feet_cols[k], 3, 4)
                centroid = ca.sum2(feet[0:2, :]) / 4
                cost += config.weight_centroid * dt * ca.sumsqr(B[0:2, k] - centroid)

        self._g = ca.vertcat(*g)
        self.lbg, self.ubg = np.concatenate(lbg), np.concatenate(ubg)
        self.n_constraints = int(self._g.shape[0])
        opts = {
            "ipopt.print_level": 0,
            "print_time": False,
            "ipopt.sb": "yes",
            "ipopt.max_iter": int(config.max_iter),
            "ipopt.tol": config.tol,
            "ipopt.acceptable_tol": 10 * config.tol,
            "ipopt.hessian_approximation": HESSIANS[config.hessian],
            "ipopt.mu_strategy": "adaptive",
        }
        if config.margin == "learned" and config.hessian == "exact" and chain_rule_hessian:
            from margin_rl.planning.lagrangian import margin_lagrangian_hessian

            # Kept with the problem, like the margin function: its chain-rule callback is Python.
            if self._margin_rows != slice(0, n_nodes):  # margin_lagrangian_hessian takes them as the first rows
                raise AssertionError("the margin rows must be the first constraints")
            others = ca.vertcat(*g[1:])
            self._hess_lag = margin_lagrangian_hessian(z, par, cost, others, LAM, margin_model.network)
            opts["hess_lag"] = self._hess_lag
        opts.update({f"ipopt.{key}": value for key, value in config.ipopt_options})
        self.solver = ca.nlpsol("trajectory", "ipopt", {"x": z, "p": par, "f": cost, "g": self._g}, opts)
        self.lambda_function = ca.Function("lambdas", [z, par], [LAM])
        self.constraint_function = ca.Function("constraints", [z, par], [self._g])
        self.cost_function = ca.Function("cost", [z, par], [cost])

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _base_xy_yaw(B, sched: HorizonSchedule, t: float, dt: float):
        times = sched.node_times
        k = int(min(max(np.floor((t - times[0]) / dt + 1e-9), 0), len(times) - 2))
        tau = float(np.clip(t - times[k], 0.0, dt))
        pos = hermite(B[0:2, k], B[6:8, k], B[0:2, k + 1], B[6:8, k + 1], dt, tau)[0]
        yaw = hermite(B[5, k], B[11, k], B[5, k + 1], B[11, k + 1], dt, tau)[0]
        return pos, yaw

    def parameters(self, initial_footholds: np.ndarray, target_velocity_xy: np.ndarray) -> np.ndarray:
        p0 = np.asarray(initial_footholds, dtype=float)
        if p0.shape != (4, 3):
            raise ValueError(f"initial_footholds must have shape (4, 3), got {p0.shape}")
        return np.concatenate([p0.reshape(-1), np.asarray(target_velocity_xy, dtype=float).reshape(2)])

    def bounds(self, initial: BaseState, target: BaseState) -> tuple[np.ndarray, np.ndarray]:
        c = self.config
        n_nodes = self.schedule.n_nodes
        lo_node = np.array(
            [-np.inf] * 3 + [-c.max_tilt] * 2 + [-np.inf] + [-c.max_com_vel_xy] * 2 + [-0.5] + [-1.0] * 3
        )
        lo = np.tile(lo_node, n_nodes)
        hi = -lo
        lo[:BASE_DIM] = hi[:BASE_DIM] = initial.as_vector()
        tolerance = np.asarray(c.target_tolerance)
        lo[-BASE_DIM:] = np.maximum(target.as_vector() - tolerance, lo[-BASE_DIM:])
        hi[-BASE_DIM:] = np.minimum(target.as_vector() + tolerance, hi[-BASE_DIM:])
        x_min, x_max, y_min, y_max = self.height_map.extent
        margin = 2 * self.height_map.resolution
        h = self.height_map.heights
        foot_lo = np.array([x_min + margin, y_min + margin, h.min() - 0.05])
        foot_hi = np.array([x_max - margin, y_max - margin, h.max() + 0.05])
        n_slots = len(self.schedule.slots)
        lbx = np.concatenate([lo, np.tile(foot_lo, n_slots)])
        ubx = np.concatenate([hi, np.tile(foot_hi, n_slots)])
        return lbx, ubx

    def initial_guess(
        self, initial: BaseState, target: BaseState, initial_footholds: np.ndarray, previous: Plan | None = None
    ) -> np.ndarray:
        """A decision vector to start from: the previous plan where it overlaps (warm start), a straight
        line to the target elsewhere, footholds at their nominal places on the terrain."""
        sched, dt = self.schedule, self.config.node_dt
        times = sched.node_times
        T = times[-1] - times[0]
        base = np.empty((sched.n_nodes, BASE_DIM))
        x0, x1 = initial.as_vector(), target.as_vector()
        for k, t in enumerate(times):
            if previous is not None and t <= previous.t_end + 1e-9:
                base[k] = np.concatenate(previous.base_at(float(t))[:4])
                continue
            s = (t - times[0]) / T
            base[k] = (1 - s) * x0 + s * x1
            base[k, 6:9] = (x1[0:3] - x0[0:3]) / T if 0 < k < len(times) - 1 else base[k, 6:9]
            base[k, 9:12] = 0.0 if 0 < k < len(times) - 1 else base[k, 9:12]
        base[0], base[-1] = x0, x1
        feet = []
        nominal_xy = self.model.nominal_feet_com[:, 0:2]
        t_end = float(times[-1])
        for slot in sched.slots:
            found = None
            if previous is not None:
                for k, old in enumerate(previous.schedule.slots):
                    if old.leg == slot.leg and abs(old.touchdown - slot.touchdown) < 1e-6:
                        found = previous.footholds[k]
            if found is None:
                t_mid = 0.5 * (slot.touchdown + slot.stance_end)
                tm = min(t_mid, t_end)
                k = int(min(np.floor((tm - times[0]) / dt + 1e-9), len(times) - 2))
                s = (tm - times[k]) / dt
                c = (1 - s) * base[k] + s * base[k + 1]
                yaw = c[5]
                rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
                xy = c[0:2] + x1[6:8] * max(t_mid - t_end, 0.0) + rot @ nominal_xy[slot.leg]
                lbx, ubx = self.bounds(initial, target)
                xy = np.clip(xy, lbx[self.n_base : self.n_base + 2], ubx[self.n_base : self.n_base + 2])
                found = np.array([xy[0], xy[1], float(self.height_map.height(xy))])
            feet.append(found)
        return np.concatenate([base.reshape(-1), np.array(feet).reshape(-1)])

    def solve(
        self,
        initial: BaseState,
        target: BaseState,
        initial_footholds: np.ndarray,
        previous: Plan | None = None,
        guess: np.ndarray | None = None,
    ) -> Plan:
        """Optimise the horizon from ``initial`` to ``target`` with the legs starting on ``initial_footholds``."""
        par = self.parameters(initial_footholds, target.velocity[:2])
        lbx, ubx = self.bounds(initial, target)
        x0 = self.initial_guess(initial, target, initial_footholds, previous) if guess is None else np.asarray(guess)
        x0 = np.clip(x0, lbx, ubx)
        start = time.perf_counter()
        sol = self.solver(x0=x0, p=par, lbx=lbx, ubx=ubx, lbg=self.lbg, ubg=self.ubg)
        seconds = time.perf_counter() - start
        stats = self.solver.stats()
        z = np.array(sol["x"]).ravel()
        return self._plan(z, par, stats.get("return_status", "unknown"), int(stats.get("iter_count", 0)), seconds)

    def _plan(self, z: np.ndarray, par: np.ndarray, status: str, iterations: int, seconds: float) -> Plan:
        n_nodes = self.schedule.n_nodes
        lams = np.array(self.lambda_function(z, par)).T
        margins = np.full(n_nodes, np.nan)
        if self.margin_model is not None:
            margins = np.asarray(self.margin_model(lams), dtype=float)
        return Plan(
            schedule=self.schedule,
            base=z[: self.n_base].reshape(n_nodes, BASE_DIM),
            initial_footholds=par[:12].reshape(4, 3),
            footholds=z[self.n_base :].reshape(-1, 3),
            learned_margins=margins,
            margin_bound=self.margin_bound,
            status=status,
            iterations=iterations,
            solve_seconds=seconds,
            decision=z,
        )

    def plan_lambdas(self, plan: Plan) -> np.ndarray:
        """(N + 1, 47) lambda of a plan at its nodes, from the same CasADi expression the solver used."""
        par = self.parameters(plan.initial_footholds, np.zeros(2))
        return np.array(self.lambda_function(plan.decision, par)).T


def _contact_points(P0, Q, sched: HorizonSchedule, leg: int) -> list:
    """Contact points (not centres) of ``leg`` in sequence order, for the stance normal (centre - q) / r."""
    return [P0[:, leg]] + [Q[:, k] for k in sched.slot_indices(leg)]


def _terrain_function(height_map: HeightMap):
    """CasADi ``xy -> (h, dh/dxy)`` of the map (gradient as a (1, 2) row)."""
    import casadi as ca

    xy = ca.MX.sym("xy", 2)
    h = height_map.casadi_function(xy)
    return ca.Function("terrain", [xy], [h, ca.jacobian(h, xy)])


def with_margin(config: PlannerConfig, margin: str) -> PlannerConfig:
    """``config`` with another margin kind (the contrast plans)."""
    return replace(config, margin=margin)
