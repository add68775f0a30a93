"""The :class:`Robot` and its loading: one MJCF read by MuJoCo and Pinocchio, checked against the conventions.

:func:`load_robot` / :func:`load_robot_from_xml` build a :class:`Robot` (facts read from the MJCF; its
kinematics and dynamics methods come from :class:`~margin_rl.robot.kinematics.RobotKinematics` and
:class:`~margin_rl.robot.dynamics.RobotDynamics`); :func:`standing_equilibrium_ctrl` is the keyframe's
static-equilibrium servo target.
"""

from __future__ import annotations

import functools
import importlib.resources
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from margin_rl.robot.dynamics import PinocchioModel, RobotDynamics, pinocchio
from margin_rl.robot.kinematics import LegGeometry, RobotKinematics, with_standing_knee_branch

LEGS: tuple[str, ...] = ("LF", "RF", "LH", "RH")
"""Leg order used everywhere in margin_rl (and in the MJCF's joint and actuator order)."""

LEG_JOINTS: tuple[str, ...] = ("HAA", "HFE", "KFE")
"""Joint order within a leg: hip abduction/adduction, hip flexion/extension, knee flexion/extension."""

STANDING_KEYFRAME = "standing"

_ROBOT_FILE_PREFIX = "anymal_"


class RobotModelError(ValueError):
    """A robot name, file or model does not satisfy what margin_rl needs."""


def assets_dir() -> Path:
    """Directory holding the installed MJCF files (``margin_rl/assets/anymal``)."""
    return Path(str(importlib.resources.files("margin_rl.assets").joinpath("anymal")))


def available_robots() -> tuple[str, ...]:
    """Names of the robots shipped with the package, e.g. ``("anymal_b", "anymal_c")``."""
    names = sorted(p.stem for p in assets_dir().glob(f"{_ROBOT_FILE_PREFIX}*.xml"))
    return tuple(names)


def robot_xml_path(name: str) -> Path:
    """Path of the robot MJCF for ``name``; raises :class:`RobotModelError` listing known robots."""
    robots = available_robots()
    if name not in robots:
        raise RobotModelError(f"unknown robot {name!r}; available robots: {', '.join(robots)}")
    return assets_dir() / f"{name}.xml"


def scene_xml_path(name: str) -> Path:
    """Path of the flat-ground scene (robot + floor) for ``name``."""
    robot_xml_path(name)
    return assets_dir() / f"scene_{name}.xml"


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Robot(RobotKinematics, RobotDynamics):
    """One robot, as MuJoCo and Pinocchio models built from the same MJCF (Pinocchio's on first use of a dynamics
    method or :attr:`pin_model`: :class:`~margin_rl.robot.dynamics.PinocchioModel`).

    Build it with :func:`load_robot`. Arrays are read-only; joint-indexed arrays have 12 entries in
    :attr:`joint_names` order (LF, RF, LH, RH x HAA, HFE, KFE).
    """

    name: str
    xml_path: Path
    scene_path: Path
    mj_model: mujoco.MjModel
    joint_names: tuple[str, ...]
    total_mass: float  # [kg]
    gravity: float  # [m/s^2], magnitude of the MJCF's gravity
    joint_lower: np.ndarray  # (12,) [rad]
    joint_upper: np.ndarray  # (12,) [rad]
    torque_limits: np.ndarray  # (12,) symmetric actuator force limits [N m]
    velocity_limits: np.ndarray  # (12,) [rad/s]
    kp: np.ndarray  # (12,) position-actuator stiffness [N m/rad]
    kd: np.ndarray  # (12,) position-actuator damping [N m s/rad]
    foot_radius: float  # [m]
    standing_qpos: np.ndarray  # (19,) MuJoCo qpos of the 'standing' keyframe
    legs: tuple[LegGeometry, ...]

    # ----------------------------------------------------------------- Pinocchio, built on first use
    @functools.cached_property
    def _pinocchio(self) -> PinocchioModel:
        return build_pinocchio_model(self.xml_path, self.mj_model, self.joint_names)

    @property
    def pin_model(self) -> Any:
        """The Pinocchio model (``pinocchio.Model``) of the same MJCF, gravity from the MJCF."""
        return self._pinocchio.model

    @property
    def _pin_data(self) -> Any:
        return self._pinocchio.data

    @property
    def _pin_foot_frames(self) -> tuple[int, ...]:
        return self._pinocchio.foot_frames

    @property
    def _pin_leg_v_idx(self) -> tuple[tuple[int, ...], ...]:
        return self._pinocchio.leg_v_idx

    @property
    def _pin_joint_q_idx(self) -> np.ndarray:
        return self._pinocchio.joint_q_idx

    # ----------------------------------------------------------------- simple facts
    @property
    def leg_names(self) -> tuple[str, ...]:
        return tuple(g.leg for g in self.legs)

    @property
    def foot_names(self) -> tuple[str, ...]:
        return tuple(f"{leg}_FOOT" for leg in self.leg_names)

    @property
    def standing_joint_pos(self) -> np.ndarray:
        """(12,) joint angles of the standing keyframe [rad]."""
        return self.standing_qpos[7:]

    @property
    def standing_height(self) -> float:
        """Base height above flat ground in the standing keyframe [m]."""
        return float(self.standing_qpos[2])

    def leg_slice(self, leg: str) -> slice:
        """Indices of ``leg``'s three joints in the 12-vector."""
        i = self.leg_names.index(leg)
        return slice(3 * i, 3 * i + 3)

    # ----------------------------------------------------------------- helpers
    def _check_joint_pos(self, joint_pos: np.ndarray) -> np.ndarray:
        q = np.asarray(joint_pos, dtype=float)
        if q.shape[-1:] != (len(self.joint_names),):
            raise ValueError(f"joint_pos must have shape (..., {len(self.joint_names)}), got {q.shape}")
        return q

    def summary(self) -> dict[str, object]:
        """Plain-data description of the robot (for reports and model cards)."""
        feet = self.foot_positions(self.standing_joint_pos)
        return {
            "name": self.name,
            "total_mass_kg": self.total_mass,
            "standing_height_m": self.standing_height,
            "joint_names": list(self.joint_names),
            "joint_lower_rad": self.joint_lower.tolist(),
            "joint_upper_rad": self.joint_upper.tolist(),
            "torque_limits_Nm": self.torque_limits.tolist(),
            "velocity_limits_rad_s": self.velocity_limits.tolist(),
            "kp": self.kp.tolist(),
            "kd": self.kd.tolist(),
            "foot_radius_m": self.foot_radius,
            "standing_joint_pos_rad": self.standing_joint_pos.tolist(),
            "standing_feet_base_frame_m": {leg: feet[i].tolist() for i, leg in enumerate(self.leg_names)},
        }


def standing_equilibrium_ctrl(robot: Robot) -> np.ndarray:
    """Position-servo targets that hold the standing keyframe pose in static equilibrium on flat ground.

    A P(D) servo needs a position error to produce torque, so commanding the standing angles
    themselves makes the robot sag (ANYmal C: about 12 cm at kp = 80). Instead the keyframe's ctrl
    is the static solution: with the standing joint angles q, the minimum-norm contact forces f
    (feet-sphere contact points) that balance gravity, sum f = m g e_z and sum (p_i - c) x f_i = 0,
    the joint torques tau_i = g_i(q) - J_i^T f_i and the servo law tau = kp (ctrl - q) give

        ctrl = q + tau / kp.

    Returns:
        (12,) servo targets [rad]; ``robot.mj_model.key_ctrl`` of the ``standing`` keyframe holds these
        (rounded to 1e-4 rad; a test checks it).
    """
    q = robot.standing_joint_pos
    contact = robot.foot_positions(q) - np.array([0.0, 0.0, robot.foot_radius])
    rel = contact - robot.com_position(q)
    # Grasp map G (6 x 12): force and moment about the CoM of the four contact forces.
    G = np.zeros((6, 3 * len(robot.legs)))
    for i, r in enumerate(rel):
        G[0:3, 3 * i : 3 * i + 3] = np.eye(3)
        G[3:6, 3 * i : 3 * i + 3] = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    wrench = np.concatenate([[0.0, 0.0, robot.total_mass * robot.gravity], np.zeros(3)])
    forces = (np.linalg.pinv(G) @ wrench).reshape(len(robot.legs), 3)
    J = robot.leg_jacobians(q)
    tau = robot.bias_torques(q) - np.einsum("lij,li->lj", J, forces)
    return q + tau.reshape(-1) / robot.kp


def _require(condition: bool, path: Path, message: str) -> None:
    if not condition:
        raise RobotModelError(f"{path}: {message}")


def _leg_geometry(model: mujoco.MjModel, path: Path, leg: str) -> LegGeometry:
    def body(suffix: str) -> Any:  # a MuJoCo named-access view
        name = f"{leg}_{suffix}"
        _require(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) >= 0, path, f"missing body {name}")
        b = model.body(name)
        _require(
            np.allclose(b.quat, [1, 0, 0, 0]),
            path,
            f"body {name} is rotated; margin_rl's analytic IK needs base-aligned leg frames",
        )
        return b

    axes = {"HAA": (1.0, 0.0, 0.0), "HFE": (0.0, 1.0, 0.0), "KFE": (0.0, 1.0, 0.0)}
    lower, upper = [], []
    for joint in LEG_JOINTS:
        name = f"{leg}_{joint}"
        _require(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name) >= 0, path, f"missing joint {name}")
        j = model.joint(name)
        _require(np.allclose(j.axis, axes[joint]), path, f"joint {name} axis must be {axes[joint]}")
        if model.jnt_limited[j.id]:
            lower.append(float(j.range[0]))
            upper.append(float(j.range[1]))
        else:
            lower.append(-np.inf)
            upper.append(np.inf)
    foot = f"{leg}_FOOT"
    _require(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, foot) >= 0, path, f"missing site {foot}")
    _require(model.site(foot).bodyid[0] == body("SHANK").id, path, f"site {foot} must belong to {leg}_SHANK")
    geometry = LegGeometry(
        leg=leg,
        haa_origin=_readonly(body("HIP").pos),
        hfe_offset=_readonly(body("THIGH").pos),
        kfe_offset=_readonly(body("SHANK").pos),
        foot_offset=_readonly(model.site(foot).pos),
        lower=_readonly(lower),
        upper=_readonly(upper),
        knee_sign=1.0,
    )
    return geometry


def load_robot(name: str) -> Robot:
    """Load a robot shipped with margin_rl.

    Args:
        name: ``"anymal_b"`` or ``"anymal_c"`` (see :func:`available_robots`).

    Returns:
        A fresh :class:`Robot` (its ``mj_model`` is yours to modify, e.g. for randomisation).

    Raises:
        RobotModelError: unknown name (the message lists the available robots), or a missing or
            malformed model file (the message names the file).
    """
    path = robot_xml_path(name)
    return load_robot_from_xml(path, name=name, scene_path=scene_xml_path(name))


def load_robot_from_xml(path: str | Path, name: str | None = None, scene_path: str | Path | None = None) -> Robot:
    """Load a robot from any MJCF that follows margin_rl's naming conventions (see the module doc)."""
    path = Path(path)
    if not path.is_file():
        raise RobotModelError(f"robot model file not found: {path}")
    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:  # MuJoCo reports XML and compile errors as ValueError
        raise RobotModelError(f"{path}: MuJoCo could not load this model: {exc}") from exc
    joint_names = tuple(f"{leg}_{j}" for leg in LEGS for j in LEG_JOINTS)
    legs = [_leg_geometry(model, path, leg) for leg in LEGS]
    for i, jname in enumerate(joint_names):
        _require(model.joint(jname).qposadr[0] == 7 + i, path, f"joint {jname} must be qpos index {7 + i}")
        act = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, jname)
        _require(act == i, path, f"actuator {i} must be a position actuator named {jname} on that joint")
        _require(bool(model.actuator_forcelimited[act]), path, f"actuator {jname} needs a forcerange")

    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, STANDING_KEYFRAME)
    _require(key >= 0, path, f"missing keyframe {STANDING_KEYFRAME!r}")
    standing_qpos = model.key_qpos[key].copy()
    legs = [with_standing_knee_branch(g, standing_qpos[7 + 3 * i : 10 + 3 * i]) for i, g in enumerate(legs)]

    def numeric(name_: str) -> np.ndarray:
        _require(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name_) >= 0, path, f"missing numeric {name_}")
        return model.numeric(name_).data

    velocity_limits = np.broadcast_to(numeric("joint_velocity_limit"), (len(joint_names),))
    forcerange = model.actuator_forcerange[: len(joint_names)]
    _require(np.allclose(forcerange[:, 0], -forcerange[:, 1]), path, "actuator force ranges must be symmetric")

    return Robot(
        name=name or path.stem,
        xml_path=path,
        scene_path=Path(scene_path) if scene_path is not None else path,
        mj_model=model,
        joint_names=joint_names,
        total_mass=float(model.body_subtreemass[model.body("base").id]),
        gravity=float(np.linalg.norm(model.opt.gravity)),
        joint_lower=_readonly(np.concatenate([g.lower for g in legs])),
        joint_upper=_readonly(np.concatenate([g.upper for g in legs])),
        torque_limits=_readonly(forcerange[:, 1]),
        velocity_limits=_readonly(velocity_limits),
        kp=_readonly(model.actuator_gainprm[: len(joint_names), 0]),
        kd=_readonly(-model.actuator_biasprm[: len(joint_names), 2]),
        foot_radius=float(numeric("foot_radius")[0]),
        standing_qpos=_readonly(standing_qpos),
        legs=tuple(legs),
    )


def build_pinocchio_model(path: Path, model: mujoco.MjModel, joint_names: tuple[str, ...]) -> PinocchioModel:
    """The Pinocchio model of the MJCF at ``path`` (``model``: MuJoCo's of the same file, for gravity), checked
    against the conventions; :class:`RobotModelError` naming the file where Pinocchio cannot load it."""
    pin = pinocchio()
    try:
        pin_model = pin.buildModelFromMJCF(str(path))
    except Exception as exc:  # Pinocchio raises bare RuntimeErrors from C++
        raise RobotModelError(f"{path}: Pinocchio could not load this model: {exc}") from exc
    # The MJCF is the source of truth for gravity too.
    pin_model.gravity = pin.Motion(np.concatenate([model.opt.gravity, np.zeros(3)]))
    foot_frames = []
    for leg in LEGS:
        fid = pin_model.getFrameId(f"{leg}_FOOT")
        _require(fid < len(pin_model.frames), path, f"Pinocchio sees no frame {leg}_FOOT")
        foot_frames.append(fid)
    leg_v_idx = tuple(
        tuple(pin_model.joints[pin_model.getJointId(f"{leg}_{j}")].idx_v for j in LEG_JOINTS) for leg in LEGS
    )
    joint_q_idx = np.array([pin_model.joints[pin_model.getJointId(n)].idx_q for n in joint_names])
    return PinocchioModel(pin_model, pin_model.createData(), tuple(foot_frames), leg_v_idx, joint_q_idx)
