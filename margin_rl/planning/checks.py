"""Independent checks of a plan: lambda recomputed in numpy, the analytic margin, IK reachability.

The planner's lambda comes from CasADi expressions (:mod:`margin_rl.planning.lambda_map`); here it is
recomputed along the executed trajectory by a second route, so the checks do not inherit a mistake
of the first:

* the base from SciPy's ``CubicHermiteSpline`` through the plan's node values and rates;
* the angular acceleration from rotation matrices instead of Euler-rate formulas: with
  R = Rz(psi) Ry(theta) Rx(phi), R_dot and R_ddot by the product rule, [omega]x = R_dot R^T and
  [omega_dot]x = R_ddot R^T + R_dot R_dot^T (world frame), then rotated into H by Rz(psi)^T;
* normals from the numpy height map, contact flags from the gait.

Then the *analytic* margin (seed 000 §III, not the network) of every sampled state, the learned
margin for comparison, and IK reachability of all four feet (the analytic margin's own IK with its
CoM fixed point: status "unreachable").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from margin_rl.planning.gait import contact_flags
from margin_rl.planning.problem import Plan
from margin_rl.planning.receding import CourseResult
from margin_rl.planning.terrain import HeightMap
from margin_rl.robot import Robot
from margin_rl.stability import StabilityState, analytic_margin

TOLERANCE = 0.01  # [m] the slack: analytic margin >= m_min - 1 cm


def _axis_matrices(angle: float, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotation about a coordinate axis and its first and second derivatives w.r.t. the angle."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R, dR = np.eye(3), np.zeros((3, 3))
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    dR[i, i], dR[i, j], dR[j, i], dR[j, j] = -s, -c, c, -s
    ddR = np.zeros((3, 3))
    ddR[i, i], ddR[i, j], ddR[j, i], ddR[j, j] = -c, s, -s, -c
    return R, dR, ddR


def _vee(S: np.ndarray) -> np.ndarray:
    return 0.5 * np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


def rotation_kinematics(
    rpy: np.ndarray, rate: np.ndarray, acc: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R_WB, omega_W, omega_dot_W) of Z-Y-X angles with their first and second derivatives (matrix route)."""
    factors = [_axis_matrices(rpy[2], 2), _axis_matrices(rpy[1], 1), _axis_matrices(rpy[0], 0)]  # Rz, Ry, Rx
    d1 = [rate[2], rate[1], rate[0]]
    d2 = [acc[2], acc[1], acc[0]]
    M = [f[0] for f in factors]
    dM = [f[1] * d1[n] for n, f in enumerate(factors)]
    ddM = [f[2] * d1[n] ** 2 + f[1] * d2[n] for n, f in enumerate(factors)]
    R = M[0] @ M[1] @ M[2]
    R_dot = dM[0] @ M[1] @ M[2] + M[0] @ dM[1] @ M[2] + M[0] @ M[1] @ dM[2]
    R_ddot = (
        ddM[0] @ M[1] @ M[2]
        + M[0] @ ddM[1] @ M[2]
        + M[0] @ M[1] @ ddM[2]
        + 2 * (dM[0] @ dM[1] @ M[2] + dM[0] @ M[1] @ dM[2] + M[0] @ dM[1] @ dM[2])
    )
    return R, _vee(R_dot @ R.T), _vee(R_ddot @ R.T + R_dot @ R_dot.T)


def plan_lambda(plan: Plan, height_map: HeightMap, robot: Robot, mu: float, t: float) -> np.ndarray:
    """lambda (47,) of the plan at time t, by the numpy route of the module docstring."""
    times = plan.schedule.node_times
    pos = CubicHermiteSpline(times, plan.base[:, 0:3], plan.base[:, 6:9])
    ang = CubicHermiteSpline(times, plan.base[:, 3:6], plan.base[:, 9:12])
    c, v, a = pos(t), pos(t, 1), pos(t, 2)
    rpy, rate, rpy_acc = ang(t), ang(t, 1), ang(t, 2)
    R, _, omega_dot = rotation_kinematics(rpy, rate, rpy_acc)
    Rz = _axis_matrices(rpy[2], 2)[0]
    contacts = contact_flags(plan.schedule.gait, t)
    feet = plan.foot_centres(height_map, robot.foot_radius, t)
    stance_holds = plan.current_footholds(t)
    normals = np.where(contacts[:, None] > 0, height_map.normal(stance_holds[:, 0:2]), np.array([0.0, 0.0, 1.0]))
    state = StabilityState(
        gravity_axis=R[2],
        com_vel=Rz.T @ v,
        com_acc=Rz.T @ a,
        base_ang_acc=Rz.T @ omega_dot,
        ext_force=np.zeros(3),
        ext_torque=np.zeros(3),
        feet=(feet - c) @ Rz,
        mu=np.array(mu),
        contacts=contacts,
        normals=normals @ Rz,
    )
    return state.to_lambda()


@dataclass(frozen=True, eq=False)
class CourseCheck:
    """Margins along the executed trajectory of a course (sampled every ``dt``)."""

    times: np.ndarray  # (n,) [s]
    at_node: np.ndarray  # (n,) bool: the instant is a base node of its plan
    lambdas: np.ndarray  # (n, 47)
    analytic: np.ndarray  # (n,) m_a [m], NaN where the state has no margin
    status: tuple[str, ...]  # analytic statuses
    learned: np.ndarray  # (n,) m_l [m] (NaN without a network)
    out_of_distribution: np.ndarray  # (n,) bool, lambda outside the network's training ranges
    min_margin: float  # m_min [m]

    @property
    def reachable(self) -> np.ndarray:
        return np.array([s != "unreachable" for s in self.status])

    def share_above(self, slack: float = TOLERANCE, where: np.ndarray | None = None) -> float:
        """Share of sampled instants with m_a >= m_min - slack (NaN margins count as failures)."""
        mask = np.ones(len(self.times), bool) if where is None else where
        ok = np.nan_to_num(self.analytic[mask], nan=-np.inf) >= self.min_margin - slack
        return float(ok.mean()) if ok.size else float("nan")

    def summary(self) -> dict[str, float]:
        return {
            "samples": len(self.times),
            "share_analytic_ok": self.share_above(),
            "share_analytic_ok_nodes": self.share_above(where=self.at_node),
            "share_analytic_ok_between": self.share_above(where=~self.at_node),
            "share_analytic_ge_min_margin": self.share_above(slack=0.0),
            "share_reachable": float(self.reachable.mean()),
            "analytic_min": float(np.nanmin(self.analytic)) if np.isfinite(self.analytic).any() else float("nan"),
            "learned_minus_analytic_rmse": float(np.sqrt(np.nanmean((self.learned - self.analytic) ** 2))),
            "share_out_of_distribution": float(self.out_of_distribution.mean()),
        }


def check_course(
    result: CourseResult, robot: Robot, margin_model: object | None = None, dt: float = 0.05
) -> CourseCheck:
    """Sample the executed trajectory (plan i over [t_i, t_i + period)) every ``dt`` and check it."""
    n = round(result.duration / dt)
    times = np.arange(n) * dt
    lams, analytic, status, at_node = [], [], [], []
    for t in times:
        plan = result.plan_at(float(t))
        lam = plan_lambda(plan, result.scenario.height_map, robot, result.config.mu, float(t))
        r = analytic_margin(robot, lam)
        lams.append(lam)
        analytic.append(r.margin)
        status.append(r.status)
        offset = (t - plan.t0) / result.config.node_dt
        at_node.append(abs(offset - round(offset)) < 1e-6)
    lams_arr = np.array(lams)
    learned = np.full(n, np.nan)
    ood = np.zeros(n, bool)
    if margin_model is not None:
        learned = np.asarray(margin_model(lams_arr), dtype=float)
        ood = np.asarray(margin_model.out_of_distribution(lams_arr), dtype=bool)
    return CourseCheck(
        times=times,
        at_node=np.array(at_node),
        lambdas=lams_arr,
        analytic=np.array(analytic),
        status=tuple(status),
        learned=learned,
        out_of_distribution=ood,
        min_margin=result.gait.min_margin,
    )


def lateral_com_offset(check: CourseCheck, where: np.ndarray | None = None) -> float:
    """Mean lateral (H frame y) offset of the CoM from the centroid of the four feet [m]; positive = left.

    From lambda: the feet are relative to the CoM, so the CoM relative to their centroid is -mean(p_i).
    """
    feet = check.lambdas[:, 18:30].reshape(-1, 4, 3)
    offset = -feet[:, :, 1].mean(axis=1)
    mask = np.ones(len(offset), bool) if where is None else where
    return float(offset[mask].mean())
