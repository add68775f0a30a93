r"""A quasi-static whole-body controller for the crawl, on the MJCF's joint position servos.

Each control step (the physics step, 5 ms) it

1. asks for the *base wrench* that tracks the planned CoM and a level base: about the CoM, world frame,

   .. math:: F = m(g e_z + \ddot c_d) + K_p (c_d - c) + K_d (\dot c_d - \dot c) - f_{ext},\qquad
             \tau = -K_\theta\, \theta - D_\theta\, \omega - \tau_{ext},

   with :math:`\theta` the base's rotation vector and :math:`(f_{ext}, \tau_{ext})` the known external
   wrench (a carried load, or a test's disturbance: the controller is given it, as an estimator would
   give it, so that a test measures the configuration and not the tracking);
2. distributes it over the stance feet with the smallest joint torques relative to their limits (a
   Clarabel QP, below), the contact forces respecting the friction pyramid inscribed in the cone, a
   non-negative normal force and every torque limit,

   .. math:: \min_{f}\ \sum_{i,j} \Big(\frac{\tau_{ij}}{\tau^{lim}_{ij}}\Big)^2 + \epsilon \|f\|^2
             \quad \text{s.t.}\quad \sum_i (f_i, r_i \times f_i) = (F, \tau),\quad |\tau_i| \le \tau^{lim}_i,
             \quad f_i \in \text{pyramid}_i,
             \qquad \tau_i = \delta_i - J_i^T f_i,

   where :math:`\delta_i` are the leg's bias torques and :math:`J_i` the Jacobian of its contact point
   (the bottom of the foot sphere, where the ground force acts: at the sphere's centre a 50 N
   tangential force would be off by 1.5 N m) at the measured configuration, both from MuJoCo. The
   cost is smooth, so the forces change smoothly (a min-max objective made them jump between
   solutions and shook the legs); the hard limits make the QP infeasible exactly when no distribution
   within friction and torque limits exists, i.e. when the wrench leaves the FWP. The step is then
   flagged and solved without the torque limits (the servos saturate);
3. turns the stance torques :math:`\tau_i = \delta_i - J_i^T f_i` and the swing leg's gravity torques
   into servo targets: the MJCF's actuators are position servos, :math:`u = k_p (q^* - q) - k_d \dot q`,
   so ``ctrl = q_ik + tau / k_p`` with :math:`q_{ik}` the IK of the desired feet relative to the desired
   base pose (the servo adds stiffness around the feed-forward; the joint-angle error is small).

Whether a joint is *at its torque limit* is read from the servo itself: the unclipped
:math:`k_p(u - q) - k_d \dot q` against the actuator's force range (MuJoCo clips it there).
"""

from __future__ import annotations

from dataclasses import dataclass

import clarabel
import mujoco
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from margin_rl.robot import Robot

FloatArray = NDArray[np.float64]

_SETTINGS = clarabel.DefaultSettings()
_SETTINGS.verbose = False
_SETTINGS.max_iter = 60


@dataclass(frozen=True)
class ControllerGains:
    """Base tracking gains (world frame, about the CoM) and the force distribution's settings."""

    position_kp: tuple[float, float, float] = (3000.0, 3000.0, 6000.0)  # [N/m]
    position_kd: tuple[float, float, float] = (500.0, 500.0, 700.0)  # [N s/m]
    orientation_kp: tuple[float, float, float] = (1500.0, 1500.0, 800.0)  # [N m/rad]
    orientation_kd: tuple[float, float, float] = (100.0, 100.0, 60.0)  # [N m s/rad]
    force_regularisation: float = 1e-6  # epsilon [1/N^2]: keeps the QP strictly convex
    swing_stiffness: float = 400.0  # extra joint stiffness of a swing leg [N m/rad] (the servo's 80 lags)
    friction_margin: float = 0.6  # the pyramid's half-width is friction_margin * mu / sqrt(2): inside the cone, and
    # well inside it, because a foot whose planned force sits at the friction limit slips in MuJoCo (seen at 0.9)


@dataclass(frozen=True)
class ControlCommand:
    """One step's output and what it decided."""

    ctrl: FloatArray  # (12,) servo targets [rad]
    torques: FloatArray  # (12,) feed-forward joint torques [N m]
    forces: FloatArray  # (4, 3) planned contact forces [N, W] (zero for swing feet)
    distributed: bool  # False: no distribution within friction and torque limits existed


def _skew(r: np.ndarray) -> FloatArray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def rotation_vector(rotation: np.ndarray) -> FloatArray:
    """Rotation vector (3,) of a rotation matrix (axis times angle) [rad]."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.asarray(rotation, dtype=float).ravel())
    vec = np.zeros(3)
    mujoco.mju_quat2Vel(vec, quat, 1.0)
    return vec


class QuasiStaticController:
    """Tracks a desired CoM and feet with the robot's servos; see the module docstring."""

    def __init__(self, robot: Robot, torque_limits: np.ndarray, mu: float, gains: ControllerGains | None = None):
        self.robot = robot  # IK and the servo gains
        self.gains = gains or ControllerGains()
        self.torque_limits = np.asarray(torque_limits, dtype=float).reshape(4, 3)
        if np.any(self.torque_limits <= 0):
            raise ValueError("torque_limits must be positive")
        self.mu = float(mu)
        self.mass = robot.total_mass
        self.kp = np.asarray(robot.kp, dtype=float)

    # ----------------------------------------------------------------- the wrench
    def base_wrench(
        self,
        com: np.ndarray,
        com_vel: np.ndarray,
        rotation: np.ndarray,
        ang_vel: np.ndarray,
        com_des: np.ndarray,
        com_vel_des: np.ndarray,
        com_acc_des: np.ndarray,
        ext_force: np.ndarray,
        ext_torque: np.ndarray,
    ) -> FloatArray:
        """(6,) force and moment about the CoM [N, N m, W] the feet should exert (step 1)."""
        g = self.gains
        force = (
            self.mass * (np.array([0.0, 0.0, self.robot.gravity]) + com_acc_des)
            + np.asarray(g.position_kp) * (com_des - com)
            + np.asarray(g.position_kd) * (com_vel_des - com_vel)
            - ext_force
        )
        moment = -np.asarray(g.orientation_kp) * rotation_vector(rotation) - np.asarray(g.orientation_kd) * ang_vel
        return np.concatenate([force, moment - ext_torque])

    # ----------------------------------------------------------------- the distribution
    def distribute(
        self,
        wrench: np.ndarray,
        contact_rel_com: np.ndarray,
        stance: np.ndarray,
        jacobians: np.ndarray,
        bias: np.ndarray,
        normal_caps: np.ndarray | None = None,
    ) -> tuple[FloatArray, bool]:
        """Contact forces (4, 3) [N, W] for ``wrench`` (step 2) and whether they respect every limit.

        The QP of the module docstring; if it has no solution (no distribution within friction and the
        torque limits exists), the torque limits are dropped and the flag is False. ``normal_caps`` (4,)
        [N] bounds each foot's normal force (a foot being loaded after touchdown or unloaded before
        lift-off; ``inf`` for none).
        """
        caps = np.full(4, np.inf) if normal_caps is None else np.asarray(normal_caps, dtype=float)
        legs = np.flatnonzero(stance)
        n = legs.size
        forces = np.zeros((4, 3))
        if n == 0:
            return forces, False
        grasp = np.zeros((6, 3 * n))
        hessian = np.zeros((3 * n, 3 * n))
        linear = np.zeros(3 * n)
        half_width = self.gains.friction_margin * self.mu / np.sqrt(2.0)
        friction, cap_rhs, torque, torque_rhs = [], [], [], []
        for j, leg in enumerate(legs):
            cols = slice(3 * j, 3 * j + 3)
            grasp[:3, cols] = np.eye(3)
            grasp[3:, cols] = _skew(contact_rel_com[leg])
            # (delta - J^T f) / limit, per joint: its square is the cost, its magnitude at most 1.
            scaled = jacobians[leg].T / self.torque_limits[leg][:, None]
            offset = bias[leg] / self.torque_limits[leg]
            hessian[cols, cols] = 2.0 * scaled.T @ scaled + 2.0 * self.gains.force_regularisation * np.eye(3)
            linear[cols] = -2.0 * scaled.T @ offset
            block = np.zeros((6, 3 * n))  # |f_x|, |f_y| <= half_width f_z (flat ground), 0 <= f_z <= cap
            block[:4, cols] = [(1, 0, -half_width), (-1, 0, -half_width), (0, 1, -half_width), (0, -1, -half_width)]
            block[4, 3 * j + 2] = -1.0
            block[5, 3 * j + 2] = 1.0
            friction.append(block)
            cap_rhs.append(np.array([0.0, 0.0, 0.0, 0.0, 0.0, min(caps[leg], 1e7)]))
            rows = np.zeros((6, 3 * n))
            rows[:3, cols], rows[3:, cols] = -scaled, scaled  # offset - scaled f <= 1 and >= -1
            torque.append(rows)
            torque_rhs.append(np.concatenate([1.0 - offset, 1.0 + offset]))
        p = sp.csc_matrix(hessian)
        for with_limits in (True, False):
            blocks = [grasp, *friction] + (torque if with_limits else [])
            rhs = [wrench, *cap_rhs] + (torque_rhs if with_limits else [])
            a = sp.csc_matrix(np.vstack(blocks))
            cones = [clarabel.ZeroConeT(6), clarabel.NonnegativeConeT(a.shape[0] - 6)]
            sol = clarabel.DefaultSolver(p, linear, a, np.concatenate(rhs), cones, _SETTINGS).solve()
            if sol.status in (clarabel.SolverStatus.Solved, clarabel.SolverStatus.AlmostSolved):
                forces[legs] = np.asarray(sol.x).reshape(n, 3)
                return forces, with_limits
        forces[legs] = (np.linalg.pinv(grasp) @ wrench).reshape(n, 3)
        return forces, False

    # ----------------------------------------------------------------- the servo targets
    def command(
        self,
        joint_pos: np.ndarray,
        rotation: np.ndarray,
        com: np.ndarray,
        com_vel: np.ndarray,
        ang_vel: np.ndarray,
        base_pos: np.ndarray,
        contacts: np.ndarray,
        jacobians: np.ndarray,
        bias: np.ndarray,
        feet_des: np.ndarray,
        stance: np.ndarray,
        com_des: np.ndarray,
        com_vel_des: np.ndarray,
        com_acc_des: np.ndarray,
        ext_force: np.ndarray,
        ext_torque: np.ndarray,
        normal_caps: np.ndarray | None = None,
    ) -> ControlCommand:
        """Servo targets for one step. Positions and velocities in W; ``contacts`` (4, 3) the feet's contact
        points, ``jacobians`` (4, 3, 3) theirs w.r.t. each leg's joints, ``bias`` (4, 3) the legs' bias
        torques [N m]; ``feet_des`` (4, 3) the desired foot-sphere centres; ``stance`` (4,) bool."""
        robot = self.robot
        wrench = self.base_wrench(
            com, com_vel, rotation, ang_vel, com_des, com_vel_des, com_acc_des, ext_force, ext_torque
        )
        forces, ok = self.distribute(wrench, contacts - com, stance, jacobians, bias, normal_caps)
        torques = (bias - np.einsum("lij,li->lj", jacobians, forces)).reshape(12)
        # Joint targets: the desired feet seen from the desired (level) base, which keeps the measured
        # CoM offset from the base origin.
        base_des = base_pos + (com_des - com)
        ik = robot.inverse_kinematics((feet_des - base_des)[None], clip=True)
        q_des = ik.joint_pos[0]
        # A swing leg follows its foot trajectory with extra stiffness, added through the servo target.
        swing = np.repeat(~np.asarray(stance, dtype=bool), 3)
        torques = torques + swing * self.gains.swing_stiffness * (q_des - joint_pos)
        return ControlCommand(q_des + torques / self.kp, torques, forces, ok)
