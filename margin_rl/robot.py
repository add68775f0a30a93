"""The robot layer: ANYmal B and C from one MJCF each, in MuJoCo and Pinocchio.

``load_robot("anymal_b" | "anymal_c")`` parses ``assets/anymal/<name>.xml`` twice, with MuJoCo
(``mujoco.MjModel.from_xml_path``) and with Pinocchio (``pinocchio.buildModelFromMJCF``), and exposes the
facts every other layer needs by name: leg and joint order, joint/torque/velocity limits, PD gains,
feet, total mass, the ``standing`` keyframe, analytic leg inverse kinematics, 3x3 leg Jacobians and
per-leg bias torques. No physical number is typed in Python: they are all read from the MJCF.

Conventions
-----------
* Legs ``LF, RF, LH, RH``; each leg has joints ``<leg>_HAA, <leg>_HFE, <leg>_KFE`` (the actuator and qpos
  order of the MJCF), bodies ``<leg>_HIP, <leg>_THIGH, <leg>_SHANK`` and a site ``<leg>_FOOT`` at the
  centre of the foot sphere. "Foot position" always means that site.
* Base frame B: x forward, y left, z up, origin at the base body origin. Foot positions handed to the
  kinematics are expressed in B relative to that origin [m].
* Quaternions are (w, x, y, z) at this API, as in MuJoCo. Pinocchio's (x, y, z, w) order stays inside.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import importlib.resources
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import mujoco
import numpy as np
import pinocchio as pin

LEGS: tuple[str, ...] = ("LF", "RF", "LH", "RH")
"""Leg order used everywhere in margin_rl (and in the MJCF's joint and actuator order)."""

LEG_JOINTS: tuple[str, ...] = ("HAA", "HFE", "KFE")
"""Joint order within a leg: hip abduction/adduction, hip flexion/extension, knee flexion/extension."""

STANDING_KEYFRAME = "standing"

_ROBOT_FILE_PREFIX = "anymal_"


class RobotModelError(ValueError):
    """A robot name, file or model does not satisfy what margin_rl needs."""


class UnreachableFootError(ValueError):
    """A foot target lies outside the leg workspace or needs a joint beyond its limits."""


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


def quat_wxyz_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) given as (w, x, y, z) (normalised here)."""
    q = np.asarray(quat_wxyz, dtype=float)
    w, x, y, z = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class LegGeometry:
    """Kinematic constants of one leg, read from the MJCF (base-aligned frames at q = 0) [m].

    Foot position in the base frame::

        p = haa_origin + Rx(q_HAA) (hfe_offset + Ry(q_HFE) (kfe_offset + Ry(q_KFE) foot_offset))
    """

    leg: str
    haa_origin: np.ndarray  # (3,) HAA joint in the base frame
    hfe_offset: np.ndarray  # (3,) HFE joint in the HIP frame
    kfe_offset: np.ndarray  # (3,) KFE joint in the THIGH frame
    foot_offset: np.ndarray  # (3,) foot-sphere centre in the SHANK frame
    lower: np.ndarray  # (3,) joint lower limits [rad]
    upper: np.ndarray  # (3,) joint upper limits [rad]
    knee_sign: float  # +1 or -1: which of the two knee solutions the standing pose uses

    @property
    def lateral_offset(self) -> float:
        """Distance of the foot from the HAA axis's sagittal plane, constant for this leg [m]."""
        return float(self.hfe_offset[1] + self.kfe_offset[1] + self.foot_offset[1])


@dataclass(frozen=True)
class RigidBodyDynamics:
    """Whole-body quantities of :meth:`Robot.rigid_body_dynamics` (frozen joints, zero velocities)."""

    bias_torques: np.ndarray  # (4, 3) delta_i [N m]
    ang_momentum_rate: np.ndarray  # (3,) rate of angular momentum about the CoM [N m]
    com: np.ndarray  # (3,) CoM relative to the base origin [m]


@dataclass(frozen=True)
class IKSolution:
    """Batched leg inverse kinematics result.

    ``joint_pos`` has shape (..., 12) in the robot's joint order, ``reachable`` shape (..., 4) per leg.
    Where a leg is unreachable its three angles are NaN, never silently wrong values.
    """

    joint_pos: np.ndarray
    reachable: np.ndarray


def _rot_x(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    one, zero = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([one, zero, zero], -1), np.stack([zero, c, -s], -1), np.stack([zero, s, c], -1)], -2)


def _rot_y(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    one, zero = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([c, zero, s], -1), np.stack([zero, one, zero], -1), np.stack([-s, zero, c], -1)], -2)


def leg_forward_kinematics(geometry: LegGeometry, joint_pos: np.ndarray) -> np.ndarray:
    """Closed-form foot position(s) of one leg in the base frame.

    Args:
        geometry: the leg's constants.
        joint_pos: (..., 3) angles (HAA, HFE, KFE) [rad].

    Returns:
        (..., 3) foot-sphere centre in the base frame [m].
    """
    o_shank, r_shank = leg_frames(geometry, joint_pos)[-1]
    return o_shank + np.einsum("...ij,j->...i", r_shank, geometry.foot_offset)


def leg_frames(geometry: LegGeometry, joint_pos: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Origins (..., 3) [m] and orientations (..., 3, 3) of the HIP, THIGH and SHANK bodies, base frame.

    The leg chain of :class:`LegGeometry`: R_hip = Rx(q_HAA), R_thigh = R_hip Ry(q_HFE),
    R_shank = R_thigh Ry(q_KFE); o_hip = haa_origin, o_thigh = o_hip + R_hip hfe_offset,
    o_shank = o_thigh + R_thigh kfe_offset.
    """
    q = np.asarray(joint_pos, dtype=float)
    r_hip = _rot_x(q[..., 0])
    r_thigh = r_hip @ _rot_y(q[..., 1])
    r_shank = r_thigh @ _rot_y(q[..., 2])
    o_hip = np.broadcast_to(geometry.haa_origin, (*q.shape[:-1], 3))
    o_thigh = o_hip + np.einsum("...ij,j->...i", r_hip, geometry.hfe_offset)
    o_shank = o_thigh + np.einsum("...ij,j->...i", r_thigh, geometry.kfe_offset)
    return [(o_hip, r_hip), (o_thigh, r_thigh), (o_shank, r_shank)]


def _wrap_angle(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def leg_inverse_kinematics(geometry: LegGeometry, foot_pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Analytic inverse kinematics of one 3-DoF leg, on the standing pose's knee branch.

    Maths: with r = p - haa_origin, the HFE/KFE rotations leave the HIP-frame y coordinate at the
    constant lateral offset L_y, so the HAA angle solves  cos(q1) r_y + sin(q1) r_z = L_y  on the branch
    with the foot below the hip: q1 = atan2(r_z, r_y) + acos(L_y / |r_yz|). In the HIP frame the
    remaining planar 2-link problem (thigh a = kfe_offset_xz, shank b = foot_offset_xz) gives
    |t|^2 = |a|^2 + |b|^2 + 2 |a||b| cos(q3 - psi) with psi = atan2(a x b, a . b), so
    q3 = psi + knee_sign acos(...), and q2 = angle(a + Ry(q3) b) - angle(t) in the x-z plane.

    Args:
        geometry: the leg's constants.
        foot_pos: (..., 3) foot-sphere centre targets in the base frame [m].

    Returns:
        ``(joint_pos, reachable)``: (..., 3) angles [rad] (NaN where unreachable) and (...,) bool. A
        target is unreachable when it is outside the workspace (distance conditions) or a solution
        angle is outside the joint limits.
    """
    table = _IKTable.of(
        geometry.haa_origin,
        geometry.hfe_offset,
        geometry.kfe_offset,
        geometry.foot_offset,
        geometry.lower,
        geometry.upper,
        np.asarray(geometry.knee_sign),
    )
    return _ik(table, np.asarray(foot_pos, dtype=float))


# Slack of the joint-limit test of the IK [rad]: a solution this close outside a limit still counts.
_LIMIT_TOL = 1e-9


class _IKTable(NamedTuple):
    """The target-independent terms of :func:`_ik` for one leg (scalars) or stacked legs ((n,) arrays,
    (n, 3) for the vectors and limits) [m, rad]; see :func:`leg_inverse_kinematics` for the maths.

    Computed once per robot rather than in every IK call: for a single state the IK's time is numpy's
    per-call overhead (~0.3 us a call), not arithmetic, and these terms were ~20 of its ~80 calls.
    """

    haa: np.ndarray  # HAA joint in the base frame
    hfe_x: np.ndarray  # HFE joint in the HIP frame, x and z
    hfe_z: np.ndarray
    lateral: np.ndarray  # L_y
    ax: np.ndarray  # thigh a = kfe_offset_xz
    az: np.ndarray
    bx: np.ndarray  # shank b = foot_offset_xz
    bz: np.ndarray
    norm_a_sq: np.ndarray  # |a|^2
    norm_b_sq: np.ndarray  # |b|^2
    knee_den: np.ndarray  # 2 |a| |b|
    psi: np.ndarray  # angle from a to b
    knee_sign: np.ndarray
    lower: np.ndarray  # joint limits
    upper: np.ndarray
    lower_tol: np.ndarray  # joint limits widened by _LIMIT_TOL
    upper_tol: np.ndarray

    @classmethod
    def of(
        cls,
        haa: np.ndarray,
        hfe: np.ndarray,
        kfe: np.ndarray,
        foot: np.ndarray,
        lower: np.ndarray,
        upper: np.ndarray,
        knee_sign: np.ndarray,
    ) -> _IKTable:
        """From the :class:`LegGeometry` arrays of one leg, or stacked along a leading leg axis."""
        ax, az = kfe[..., 0], kfe[..., 2]
        bx, bz = foot[..., 0], foot[..., 2]
        norm_a, norm_b = np.hypot(ax, az), np.hypot(bx, bz)
        return cls(
            haa=haa,
            hfe_x=hfe[..., 0],
            hfe_z=hfe[..., 2],
            lateral=hfe[..., 1] + kfe[..., 1] + foot[..., 1],
            ax=ax,
            az=az,
            bx=bx,
            bz=bz,
            norm_a_sq=norm_a**2,
            norm_b_sq=norm_b**2,
            knee_den=2.0 * norm_a * norm_b,
            psi=np.arctan2(ax * bz - az * bx, ax * bx + az * bz),
            knee_sign=knee_sign,
            lower=lower,
            upper=upper,
            lower_tol=lower - _LIMIT_TOL,
            upper_tol=upper + _LIMIT_TOL,
        )


def _unit_clip(x: np.ndarray) -> np.ndarray:
    """np.clip(x, -1, 1) (the same values, NaN included) without np.clip's Python-level overhead."""
    return np.minimum(np.maximum(x, -1.0), 1.0)


def _ik(t: _IKTable, p: np.ndarray, clip: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised IK core (see :func:`leg_inverse_kinematics`); the table broadcasts against p (..., 3).

    With ``clip`` an unreachable leg gets the nearest boundary solution (acos arguments and joint
    angles clipped) instead of NaN; ``reachable`` is the same either way.

    Keep the operations, their order and numpy's functions (not the math module's: its acos and atan2
    round differently in the last bit): the analytic margin's focused projection turns last-bit changes
    of the joint angles into margin changes up to its focus_tol (0.26 mm measured on 1000 states), so
    margins, and the datasets labelled with them, are reproducible only bit for bit.
    """
    r = p - t.haa
    rx, ry, rz = r[..., 0], r[..., 1], r[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_haa = t.lateral / np.hypot(ry, rz)
        q1 = _wrap_angle(np.arctan2(rz, ry) + np.arccos(_unit_clip(cos_haa)))
        # Target in the HIP frame (undo the HAA rotation), relative to the HFE joint, in the x-z plane.
        c1, s1 = np.cos(q1), np.sin(q1)
        tx = rx - t.hfe_x
        tz = -s1 * ry + c1 * rz - t.hfe_z
        cos_knee = (tx * tx + tz * tz - t.norm_a_sq - t.norm_b_sq) / t.knee_den
        q3 = _wrap_angle(t.psi + t.knee_sign * np.arccos(_unit_clip(cos_knee)))
        # Ry(q) acts on (x, z) as a rotation by -q, so q2 = angle(c) - angle(t).
        c3, s3 = np.cos(q3), np.sin(q3)
        cx = t.ax + c3 * t.bx + s3 * t.bz
        cz = t.az - s3 * t.bx + c3 * t.bz
        q2 = _wrap_angle(np.arctan2(cz, cx) - np.arctan2(tz, tx))
    q = np.empty(r.shape)
    q[..., 0], q[..., 1], q[..., 2] = q1, q2, q3
    ok = (np.abs(cos_haa) <= 1.0) & (np.abs(cos_knee) <= 1.0)
    ok &= ((q >= t.lower_tol) & (q <= t.upper_tol)).all(axis=-1)
    ok &= np.isfinite(p).all(axis=-1)
    q = np.minimum(np.maximum(q, t.lower), t.upper) if clip else np.where(ok[..., None], q, np.nan)
    return q, ok


@dataclass(frozen=True, eq=False)
class Robot:
    """One robot, as MuJoCo and Pinocchio models built from the same MJCF.

    Build it with :func:`load_robot`. Arrays are read-only; joint-indexed arrays have 12 entries in
    :attr:`joint_names` order (LF, RF, LH, RH x HAA, HFE, KFE).
    """

    name: str
    xml_path: Path
    scene_path: Path
    mj_model: mujoco.MjModel
    pin_model: pin.Model
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
    _pin_data: pin.Data = field(repr=False)
    _pin_foot_frames: tuple[int, ...] = field(repr=False)
    _pin_leg_v_idx: tuple[tuple[int, ...], ...] = field(repr=False)
    _pin_joint_q_idx: np.ndarray = field(repr=False)

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

    # ----------------------------------------------------------------- kinematics
    def foot_positions(self, joint_pos: np.ndarray) -> np.ndarray:
        """Foot-sphere centres in the base frame (closed form, batched).

        Args:
            joint_pos: (..., 12) joint angles [rad].

        Returns:
            (..., 4, 3) positions [m].
        """
        q = self._check_joint_pos(joint_pos)
        return np.stack(
            [leg_forward_kinematics(g, q[..., 3 * i : 3 * i + 3]) for i, g in enumerate(self.legs)], axis=-2
        )

    def com_positions(self, joint_pos: np.ndarray) -> np.ndarray:
        """Whole-body CoM in the base frame, closed form and batched (for sampling millions of states).

        com = (m_base c_base + sum_b m_b (o_b + R_b c_b)) / M over the HIP, THIGH and SHANK bodies, with
        the body origins o_b and orientations R_b of the leg chain (:func:`leg_frames`) and the
        body masses m_b and inertial positions c_b of the MJCF. Matches Pinocchio's ``centerOfMass``.

        Args:
            joint_pos: (..., 12) joint angles [rad].

        Returns:
            (..., 3) CoM relative to the base origin [m].
        """
        q = self._check_joint_pos(joint_pos)
        model = self.mj_model
        base = model.body("base").id
        total = model.body_mass[base] * model.body_ipos[base] + np.zeros((*q.shape[:-1], 3))
        for i, g in enumerate(self.legs):
            frames = leg_frames(g, q[..., 3 * i : 3 * i + 3])
            for suffix, (o, R) in zip(("HIP", "THIGH", "SHANK"), frames, strict=True):
                b = model.body(f"{g.leg}_{suffix}").id
                total = total + model.body_mass[b] * (o + R @ model.body_ipos[b])
        return total / self.total_mass

    def inverse_kinematics(self, foot_pos: np.ndarray, clip: bool = False) -> IKSolution:
        """Batched analytic IK of all four legs, with an explicit per-leg reachability status.

        Args:
            foot_pos: (..., 4, 3) foot-sphere centres in the base frame [m].
            clip: give unreachable legs their nearest boundary configuration instead of NaN (for
                iterative schemes; ``reachable`` still reports the truth).

        Returns:
            :class:`IKSolution`; unreachable legs have NaN angles (unless ``clip``) and ``reachable`` False.
        """
        p = np.asarray(foot_pos, dtype=float)
        if p.shape[-2:] != (len(self.legs), 3):
            raise ValueError(f"foot_pos must have shape (..., {len(self.legs)}, 3), got {p.shape}")
        q, reachable = _ik(self._ik_table, p, clip=clip)
        return IKSolution(joint_pos=q.reshape(*q.shape[:-2], 3 * len(self.legs)), reachable=reachable)

    @functools.cached_property
    def _ik_table(self) -> _IKTable:
        """IK constants of the legs stacked along a leading leg axis, for the vectorised IK."""
        fields = ("haa_origin", "hfe_offset", "kfe_offset", "foot_offset", "lower", "upper")
        arrays = [np.stack([getattr(g, f) for g in self.legs]) for f in fields]
        return _IKTable.of(*arrays, np.array([g.knee_sign for g in self.legs]))

    def inverse_kinematics_com_relative(
        self, feet_rel_com: np.ndarray, iterations: int = 10, tol: float = 3e-5
    ) -> tuple[IKSolution, np.ndarray]:
        """IK for feet given relative to the whole-body CoM (in base axes), as lambda describes them.

        The kinematics need feet relative to the base origin, p_B = p_rel + c_B(q), and the CoM offset
        c_B depends on the joint angles q, so this solves the fixed point c_B = F(c_B) = CoM(IK(p_rel + c_B))
        from the standing pose's CoM with Newton steps whose Jacobian is frozen at the standing pose
        (the map is smooth and nearly linear: the legs move the CoM by 10-20 % of their own
        displacement; measured contraction ~0.07 per step, 3-4 iterations to 3e-5 m). An
        intermediate iterate with a foot out of reach uses that leg's nearest boundary configuration
        (clipped IK) so the map stays continuous; only the final configuration is judged.

        Args:
            feet_rel_com: (..., 4, 3) foot-sphere centres minus the CoM, in base axes [m].
            iterations: maximum fixed-point iterations.
            tol: stop when the fixed-point residual |F(c) - c| is below this [m] (max over the batch).

        Returns:
            ``(solution, com)``: the IK solution at the converged CoM and the CoM offsets (..., 3) [m].
        """
        p = np.asarray(feet_rel_com, dtype=float)
        if p.shape[-2:] != (len(self.legs), 3):
            raise ValueError(f"feet_rel_com must have shape (..., {len(self.legs)}, 3), got {p.shape}")
        single = p.ndim == 2
        newton, sensitivity, offset = self._com_fixed_point_newton
        # First-order initial guess: CoM linear in the feet positions about the standing pose,
        # c0 = (I - sum_i G_i)^-1 (c_s + sum_i G_i (p_i - f_i,s)), so the first residual is second order.
        com = (offset + np.einsum("fij,...fj->...i", sensitivity, p)) @ newton.T
        if single:
            com = np.asarray(com)
        for _ in range(iterations):
            q, reachable = _ik(self._ik_table, p + com[..., None, :], clip=True)
            q = q.reshape(*q.shape[:-2], 3 * len(self.legs))
            # Pinocchio is faster for one state, the closed form for batches; both agree to 1e-16.
            residual = (self._pin_com(q) if single else self.com_positions(q)) - com
            if residual.size == 0 or float(np.abs(residual).max()) < tol:
                # Converged: this iterate's configuration is within tol of the fixed point.
                return IKSolution(np.where(np.repeat(reachable, 3, axis=-1), q, np.nan), reachable), com
            # Newton step on c = F(c) with the map's Jacobian frozen at the standing pose:
            # c <- c + (I - dF/dc)^-1 (F(c) - c), instead of the linear rate of c <- F(c).
            com = com + residual @ newton.T
        return self.inverse_kinematics(p + com[..., None, :]), com

    @functools.cached_property
    def _com_fixed_point_newton(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Linearisation of the CoM in the feet positions at the standing pose (central differences).

        Returns ``((I - G)^-1, G_i, c_s - sum_i G_i f_i,s)`` with G_i = dCoM/d(foot i) (3 x 3 each),
        G = sum_i G_i = dF/dc of the fixed-point map, c_s and f_i,s the standing CoM and feet.
        """
        q0 = self.standing_joint_pos
        feet = self.foot_positions(q0)
        eps = 1e-4
        sensitivity = np.zeros((len(self.legs), 3, 3))
        for i in range(len(self.legs)):
            for j in range(3):
                plus, minus = feet.copy(), feet.copy()
                plus[i, j] += eps
                minus[i, j] -= eps
                com_plus = self.com_position(self.inverse_kinematics(plus).joint_pos)
                com_minus = self.com_position(self.inverse_kinematics(minus).joint_pos)
                sensitivity[i][:, j] = (com_plus - com_minus) / (2 * eps)
        jac = sensitivity.sum(axis=0)
        offset = self.com_position(q0) - np.einsum("fij,fj->i", sensitivity, feet)
        return np.linalg.inv(np.eye(3) - jac), sensitivity, offset

    def leg_ik(self, leg: str, foot_pos: np.ndarray) -> np.ndarray:
        """IK of one leg for one target; raises :class:`UnreachableFootError` if it cannot be reached.

        Args:
            leg: leg name, e.g. ``"LF"``.
            foot_pos: (3,) foot-sphere centre in the base frame [m].

        Returns:
            (3,) joint angles (HAA, HFE, KFE) [rad].
        """
        if leg not in self.leg_names:
            raise ValueError(f"unknown leg {leg!r}; legs are {', '.join(self.leg_names)}")
        p = np.asarray(foot_pos, dtype=float)
        if p.shape != (3,):
            raise ValueError(f"foot_pos must have shape (3,), got {p.shape}")
        geometry = self.legs[self.leg_names.index(leg)]
        q, ok = leg_inverse_kinematics(geometry, p)
        if not ok:
            raise UnreachableFootError(
                f"foot target {p.round(4).tolist()} [m, base frame] is unreachable for leg {leg} of "
                f"{self.name}: outside the leg workspace or beyond a joint limit "
                f"(HAA limits {geometry.lower[0]:.3f}..{geometry.upper[0]:.3f} rad)"
            )
        return q

    # ----------------------------------------------------------------- Pinocchio quantities
    def pin_configuration(
        self, joint_pos: np.ndarray, base_pos: np.ndarray | None = None, base_quat_wxyz: np.ndarray | None = None
    ) -> np.ndarray:
        """Pinocchio configuration vector from joint angles and an optional base pose (w, x, y, z)."""
        quat = (1.0, 0.0, 0.0, 0.0) if base_quat_wxyz is None else base_quat_wxyz
        q = self._pin_q(self._check_joint_pos(joint_pos), quat)
        if base_pos is not None:
            q[0:3] = base_pos
        return q

    def _pin_q(self, joint_pos: np.ndarray, base_quat_wxyz: Any = (1.0, 0.0, 0.0, 0.0)) -> np.ndarray:
        """:meth:`pin_configuration` with the base at the origin, without argument checks."""
        q = np.zeros(self.pin_model.nq)
        w, x, y, z = base_quat_wxyz
        q[3:7] = (x, y, z, w)
        q[self._pin_joint_q_idx] = joint_pos
        return q

    def leg_jacobians(self, joint_pos: np.ndarray, base_rotation: np.ndarray | None = None) -> np.ndarray:
        """Translational foot Jacobians of every leg w.r.t. that leg's own three joints.

        Args:
            joint_pos: (12,) joint angles [rad].
            base_rotation: (3, 3) orientation of the base in the frame the Jacobians should be expressed
                in (e.g. the horizontal frame); identity (base frame) if omitted.

        Returns:
            (4, 3, 3): J[i] maps leg i's joint velocities [rad/s] to its foot velocity [m/s].
        """
        R = np.eye(3) if base_rotation is None else np.asarray(base_rotation, dtype=float)
        return self._leg_jacobians_at(self._rotated_configuration(joint_pos, R))

    def bias_torques(
        self,
        joint_pos: np.ndarray,
        base_rotation: np.ndarray | None = None,
        com_acc: np.ndarray | None = None,
        base_ang_acc: np.ndarray | None = None,
    ) -> np.ndarray:
        """Per-leg bias torques delta_i of seed 000 eq. (2) at zero joint velocity and acceleration.

        delta_i = M_{b,i}^T nu_dot_b + g_i(q): the joint torques that hold leg i's own weight and inertia
        while the base accelerates, so that the actuator torques under a contact force f_i are
        tau_i = delta_i - J_i^T f_i. See :meth:`rigid_body_dynamics` for the arguments.

        Returns:
            (4, 3) bias torques [N m], leg order :attr:`leg_names`.
        """
        return self.rigid_body_dynamics(joint_pos, base_rotation, com_acc, base_ang_acc).bias_torques

    def rigid_body_dynamics(
        self,
        joint_pos: np.ndarray,
        base_rotation: np.ndarray | None = None,
        com_acc: np.ndarray | None = None,
        base_ang_acc: np.ndarray | None = None,
    ) -> RigidBodyDynamics:
        """Bias torques and centroidal angular-momentum rate with frozen joints and zero velocities.

        The whole robot moves as one rigid body (v = 0, q_ddot = 0) with the given CoM and base
        accelerations; Pinocchio's RNEA gives the joint torques delta_i = M_{b,i}^T nu_dot_b + g_i(q),
        and its centroidal dynamics the rate of angular momentum about the CoM, L_dot = I_c(q) w_dot.

        Args:
            joint_pos: (12,) joint angles [rad].
            base_rotation: (3, 3) base orientation in a gravity-aligned frame W (z up); identity if omitted.
            com_acc: (3,) CoM linear acceleration in W [m/s^2]; zero if omitted. The base-origin
                acceleration is recovered exactly as com_acc - base_ang_acc x (c - base origin), since
                the legs do not move relative to the base.
            base_ang_acc: (3,) base angular acceleration in W [rad/s^2]; zero if omitted.

        Returns:
            :class:`RigidBodyDynamics` with quantities expressed in W.
        """
        R = np.eye(3) if base_rotation is None else np.asarray(base_rotation, dtype=float)
        return self._rigid_body_dynamics_at(self._rotated_configuration(joint_pos, R), R, com_acc, base_ang_acc)

    def jacobians_and_dynamics(
        self,
        joint_pos: np.ndarray,
        base_rotation: np.ndarray | None = None,
        com_acc: np.ndarray | None = None,
        base_ang_acc: np.ndarray | None = None,
    ) -> tuple[np.ndarray, RigidBodyDynamics]:
        """``(leg_jacobians(...), rigid_body_dynamics(...))`` of one state, sharing their configuration.

        Arguments as in :meth:`rigid_body_dynamics`; the results are those of the two methods.
        """
        R = np.eye(3) if base_rotation is None else np.asarray(base_rotation, dtype=float)
        config = self._rotated_configuration(joint_pos, R)
        return self._leg_jacobians_at(config), self._rigid_body_dynamics_at(config, R, com_acc, base_ang_acc)

    def _rotated_configuration(self, joint_pos: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Pinocchio configuration with the base at the origin of W, rotated by R (3, 3)."""
        return self._pin_q(self._check_joint_pos(joint_pos), _matrix_to_quat_wxyz(R))

    @functools.cached_property
    def _pin_leg_v_array(self) -> np.ndarray:
        """(4, 3) velocity indices of each leg's joints in Pinocchio's tangent vector."""
        return np.array(self._pin_leg_v_idx)

    def _leg_jacobians_at(self, config: np.ndarray) -> np.ndarray:
        """:meth:`leg_jacobians` at a Pinocchio configuration (its base orientation sets the frame)."""
        model, data = self.pin_model, self._pin_data
        pin.computeJointJacobians(model, data, config)
        pin.updateFramePlacements(model, data)
        out = np.empty((len(self.legs), 3, 3))
        for i, (frame, v_idx) in enumerate(zip(self._pin_foot_frames, self._pin_leg_v_array, strict=True)):
            J = pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
            out[i] = J[:3, v_idx]
        return out

    def _rigid_body_dynamics_at(
        self, config: np.ndarray, R: np.ndarray, com_acc: np.ndarray | None, base_ang_acc: np.ndarray | None
    ) -> RigidBodyDynamics:
        """:meth:`rigid_body_dynamics` at a Pinocchio configuration whose base orientation is R."""
        c_ddot = np.zeros(3) if com_acc is None else np.asarray(com_acc, dtype=float)
        w_dot = np.zeros(3) if base_ang_acc is None else np.asarray(base_ang_acc, dtype=float)
        model, data = self.pin_model, self._pin_data
        v = np.zeros(model.nv)
        com = np.array(pin.centerOfMass(model, data, config))  # base origin at 0, axes of W
        # w_dot x com, written out (np.cross has a large fixed overhead on 3-vectors).
        (wx, wy, wz), (cx, cy, cz) = w_dot.tolist(), com.tolist()
        w_cross_c = np.array([wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx])
        a = np.zeros(model.nv)
        # Pinocchio's free-flyer acceleration is expressed in the base frame.
        a[0:3] = R.T @ (c_ddot - w_cross_c)
        a[3:6] = R.T @ w_dot
        tau = pin.rnea(model, data, config, v, a)
        dhg = pin.computeCentroidalMomentumTimeVariation(model, data, config, v, a)
        return RigidBodyDynamics(
            bias_torques=tau[self._pin_leg_v_array],
            ang_momentum_rate=np.array(dhg.angular),
            com=com,
        )

    def com_position(self, joint_pos: np.ndarray) -> np.ndarray:
        """Whole-body CoM in the base frame [m] (Pinocchio)."""
        return self._pin_com(self._check_joint_pos(joint_pos))

    def _pin_com(self, joint_pos: np.ndarray) -> np.ndarray:
        """:meth:`com_position` without the argument check."""
        return np.array(pin.centerOfMass(self.pin_model, self._pin_data, self._pin_q(joint_pos)))

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


def _matrix_to_quat_wxyz(R: np.ndarray) -> np.ndarray:
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(R, dtype=float).reshape(9))
    return quat


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


def _with_standing_knee_branch(geometry: LegGeometry, standing: np.ndarray) -> LegGeometry:
    """Choose the knee branch (sign of q_KFE - psi) that reproduces the standing pose."""
    a = geometry.kfe_offset[[0, 2]]
    b = geometry.foot_offset[[0, 2]]
    psi = np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)
    sign = 1.0 if _wrap_angle(standing[2] - psi) >= 0 else -1.0
    return dataclasses.replace(geometry, knee_sign=sign)


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
    try:
        pin_model = pin.buildModelFromMJCF(str(path))
    except Exception as exc:  # Pinocchio raises bare RuntimeErrors from C++
        raise RobotModelError(f"{path}: Pinocchio could not load this model: {exc}") from exc

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
    legs = [_with_standing_knee_branch(g, standing_qpos[7 + 3 * i : 10 + 3 * i]) for i, g in enumerate(legs)]

    def numeric(name_: str) -> np.ndarray:
        _require(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name_) >= 0, path, f"missing numeric {name_}")
        return model.numeric(name_).data

    velocity_limits = np.broadcast_to(numeric("joint_velocity_limit"), (len(joint_names),))
    forcerange = model.actuator_forcerange[: len(joint_names)]
    _require(np.allclose(forcerange[:, 0], -forcerange[:, 1]), path, "actuator force ranges must be symmetric")

    # The MJCF is the source of truth for gravity too.
    pin_model.gravity = pin.Motion(np.concatenate([model.opt.gravity, np.zeros(3)]))
    pin_data = pin_model.createData()
    foot_frames = []
    for leg in LEGS:
        fid = pin_model.getFrameId(f"{leg}_FOOT")
        _require(fid < len(pin_model.frames), path, f"Pinocchio sees no frame {leg}_FOOT")
        foot_frames.append(fid)
    leg_v_idx = tuple(
        tuple(pin_model.joints[pin_model.getJointId(f"{leg}_{j}")].idx_v for j in LEG_JOINTS) for leg in LEGS
    )
    joint_q_idx = np.array([pin_model.joints[pin_model.getJointId(n)].idx_q for n in joint_names])

    return Robot(
        name=name or path.stem,
        xml_path=path,
        scene_path=Path(scene_path) if scene_path is not None else path,
        mj_model=model,
        pin_model=pin_model,
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
        _pin_data=pin_data,
        _pin_foot_frames=tuple(foot_frames),
        _pin_leg_v_idx=leg_v_idx,
        _pin_joint_q_idx=joint_q_idx,
    )


def format_report(robot: Robot) -> str:
    """Human-readable summary: mass, standing height, joint and torque limits, standing feet."""
    s = robot.summary()
    lines = [
        f"{robot.name}: {s['total_mass_kg']:.3f} kg, standing base height {s['standing_height_m']:.4f} m, "
        f"foot radius {s['foot_radius_m']:.3f} m, PD kp {robot.kp[0]:g} N m/rad, kd {robot.kd[0]:g} N m s/rad",
        f"  {'joint':<8} {'lower':>8} {'upper':>8} {'|tau|max':>9} {'|qd|max':>8} {'standing':>9}",
    ]
    for i, jn in enumerate(robot.joint_names):
        lines.append(
            f"  {jn:<8} {robot.joint_lower[i]:>8.3f} {robot.joint_upper[i]:>8.3f} {robot.torque_limits[i]:>9.1f}"
            f" {robot.velocity_limits[i]:>8.1f} {robot.standing_joint_pos[i]:>9.3f}"
        )
    lines.append("  feet at the standing pose (base frame) [m]:")
    for leg, p in s["standing_feet_base_frame_m"].items():  # type: ignore[union-attr]
        lines.append(f"    {leg}: x {p[0]:+.4f}  y {p[1]:+.4f}  z {p[2]:+.4f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Print a short report of the shipped robots (``margin-rl-robots``)."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("robots", nargs="*", help=f"robot names (default: all of {', '.join(available_robots())})")
    parser.add_argument(
        "--keyframe", action="store_true", help="print the equilibrium 'standing' keyframe ctrl for the MJCF"
    )
    args = parser.parse_args(argv)
    for name in args.robots or available_robots():
        robot = load_robot(name)
        if args.keyframe:
            ctrl = standing_equilibrium_ctrl(robot)
            print(
                f"{name} standing ctrl: "
                + "  ".join(" ".join(f"{c:.4f}" for c in ctrl[i : i + 3]) for i in range(0, 12, 3))
            )
        else:
            print(format_report(robot))
            print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
