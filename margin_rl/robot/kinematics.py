"""Closed-form kinematics of the ANYmal legs: forward kinematics, the analytic IK and its tables.

* :class:`LegGeometry` (one leg's constants from the MJCF), :func:`leg_frames`, :func:`leg_forward_kinematics`
  and :func:`leg_inverse_kinematics` (one leg, batched), :class:`IKSolution`;
* :class:`RobotKinematics`, the kinematics methods of :class:`~margin_rl.robot.Robot` (foot and CoM
  positions, the four-leg IK, the IK for feet given relative to the CoM, one leg's IK);
* :func:`quat_wxyz_to_matrix`.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from margin_rl.arrays import constant, namespace, take_last


class UnreachableFootError(ValueError):
    """A foot target lies outside the leg workspace or needs a joint beyond its limits."""


def _rotation_factors() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The factors of R's entries (row-major) as products of a unit quaternion's components (w, x, y, z), for
    :func:`quat_wxyz_to_matrix`: entry k is built from f_k + g_k, f_k = q[left[k]] q[right[k]] and g_k =
    sign[9 + k] q[left[9 + k]] q[right[9 + k]] (the sign on the left factor); returns (left, right, sign), (18,) each.
    """
    left, right, sign = np.zeros(18, dtype=np.int64), np.zeros(18, dtype=np.int64), np.ones(18)
    for i in range(3):  # v_i = q[1 + i]; v' and v'' the vector turned once and twice
        v, v1, v2 = 1 + i, 1 + (i + 1) % 3, 1 + (i + 2) % 3
        diagonal, above, below = 4 * i, 3 * i + (i + 1) % 3, 3 * ((i + 1) % 3) + i
        left[diagonal], right[diagonal], left[9 + diagonal], right[9 + diagonal] = v1, v1, v2, v2
        for k, turn_sign in ((above, -1.0), (below, 1.0)):
            left[k], right[k], left[9 + k], right[9 + k], sign[9 + k] = v, v1, 0, v2, turn_sign
    return left, right, sign


_ROTATION_LEFT, _ROTATION_RIGHT, _ROTATION_SIGN = _rotation_factors()
_DIAGONAL = np.eye(3, dtype=bool).reshape(9)


def quat_wxyz_to_matrix(quat_wxyz: Any) -> Any:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) given as (w, x, y, z) (normalised here); numpy arrays
    (and array-likes) or torch tensors (:mod:`margin_rl.arrays`), answered in the same kind.

    With v = (x, y, z) and v', v'' the vector turned cyclically once and twice ((y, z, x), (z, x, y)), the entries
    are, for i = 0, 1, 2 (indices mod 3)::

        R_ii       = 1 - 2 (v'_i^2 + v''_i^2)
        R_i,i+1    = 2 (v_i v'_i - w v''_i)
        R_i+1,i    = 2 (v_i v'_i + w v''_i)

    the textbook entries (e.g. R_01 = 2 (xy - wz)), all nine computed at once from two gathers of q: a few
    operations whatever the batch (each one a kernel launch on a device).
    """
    xp = namespace(quat_wxyz)
    q = xp.astype(xp.asarray(quat_wxyz), xp.float64, copy=False)
    q = q / xp.linalg.vector_norm(q, axis=-1, keepdims=True)
    # the 18 products in R's row-major order, f_k then g_k (_rotation_factors): v'_i^2 and v''_i^2 on the diagonal,
    # v_i v'_i and -+w v''_i off it (a sign on a factor is exact), so each f_k + g_k is the textbook sum, bit for bit
    products = take_last(q, constant(_ROTATION_LEFT, q)) * constant(_ROTATION_SIGN, q)
    products = products * take_last(q, constant(_ROTATION_RIGHT, q))
    twice = 2 * (products[..., :9] + products[..., 9:])
    entries = xp.where(constant(_DIAGONAL, q), 1 - twice, twice)
    return xp.reshape(entries, (*entries.shape[:-1], 3, 3))


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
class IKSolution:
    """Batched leg inverse kinematics result.

    ``joint_pos`` has shape (..., 12) in the robot's joint order, ``reachable`` shape (..., 4) per leg.
    Where a leg is unreachable its three angles are NaN, never silently wrong values.
    """

    joint_pos: np.ndarray
    reachable: np.ndarray


def _rot_x(angle: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations about x. Written entry by entry: nested np.stack calls cost ~10x more per
    call, which dominates one state's CoM fixed point."""
    c, s = np.cos(angle), np.sin(angle)
    r = np.zeros((*np.shape(c), 3, 3))
    r[..., 0, 0] = 1.0
    r[..., 1, 1], r[..., 1, 2] = c, -s
    r[..., 2, 1], r[..., 2, 2] = s, c
    return r


def _rot_y(angle: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations about y (entry by entry, as :func:`_rot_x`)."""
    c, s = np.cos(angle), np.sin(angle)
    r = np.zeros((*np.shape(c), 3, 3))
    r[..., 0, 0], r[..., 0, 2] = c, s
    r[..., 1, 1] = 1.0
    r[..., 2, 0], r[..., 2, 2] = -s, c
    return r


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
    o_shank = o_thigh + R_thigh kfe_offset. ``geometry`` may hold several legs stacked ((L, 3) vectors, with
    ``joint_pos`` (..., L, 3)): the frames of all of them at once.
    """
    q = np.asarray(joint_pos, dtype=float)
    r_hip = _rot_x(q[..., 0])
    r_thigh = r_hip @ _rot_y(q[..., 1])
    r_shank = r_thigh @ _rot_y(q[..., 2])
    o_hip = np.broadcast_to(geometry.haa_origin, (*q.shape[:-1], 3))
    o_thigh = o_hip + np.einsum("...ij,...j->...i", r_hip, geometry.hfe_offset)
    o_shank = o_thigh + np.einsum("...ij,...j->...i", r_thigh, geometry.kfe_offset)
    return [(o_hip, r_hip), (o_thigh, r_thigh), (o_shank, r_shank)]


def _wrap_angle(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def with_standing_knee_branch(geometry: LegGeometry, standing: np.ndarray) -> LegGeometry:
    """Choose the knee branch (sign of q_KFE - psi) that reproduces the standing pose."""
    a = geometry.kfe_offset[[0, 2]]
    b = geometry.foot_offset[[0, 2]]
    psi = np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)
    sign = 1.0 if _wrap_angle(standing[2] - psi) >= 0 else -1.0
    return dataclasses.replace(geometry, knee_sign=sign)


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


JOINT_LIMIT_SLACK = 0.05
"""Slack of the IK's joint-limit test [rad]: a solution this far outside a limit still counts as reachable.

MuJoCo's joint limits are soft constraints, and walking policies press against them: rollouts of an ANYmal C
policy held its HAA joints up to ~0.05 rad past their limits in 51 % of the visited states (B: none). Those
are states the simulator produced and the reward rated, so lambda's IK accepts them (learned margin v2;
BENCHMARKS "Extended margin"); with a 1e-9 rad slack they had no margin at all."""
_LIMIT_TOL = JOINT_LIMIT_SLACK


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


class RobotKinematics:
    """The kinematics methods of :class:`~margin_rl.robot.Robot` (mixed into it; see its attributes).

    Closed form and batched, from the legs' :class:`LegGeometry`; the CoM fixed point of
    :meth:`inverse_kinematics_com_relative` also uses the Pinocchio CoM of
    :class:`~margin_rl.robot.dynamics.RobotDynamics`.
    """

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
        base_moment, leg_bodies = self._com_bodies
        total = base_moment + np.zeros((*q.shape[:-1], 3))
        # The frames of the four legs at once (numpy's per-call overhead, not arithmetic, is the cost).
        frames = leg_frames(self._stacked_legs, q.reshape(*q.shape[:-1], len(self.legs), 3))
        for i, bodies in enumerate(leg_bodies):
            for (mass, ipos), (o, R) in zip(bodies, frames, strict=True):
                total = total + mass * (o[..., i, :] + R[..., i, :, :] @ ipos)
        return total / self.total_mass

    @functools.cached_property
    def _stacked_legs(self) -> LegGeometry:
        """The legs' geometry stacked along a leading leg axis ((4, 3) vectors), for :func:`leg_frames`."""
        legs = self.legs
        return LegGeometry(
            leg="all",
            **{
                name: np.stack([getattr(g, name) for g in legs])
                for name in ("haa_origin", "hfe_offset", "kfe_offset", "foot_offset", "lower", "upper")
            },
            knee_sign=float("nan"),  # unused by the frames
        )

    @functools.cached_property
    def _com_bodies(self) -> tuple[np.ndarray, tuple[tuple[tuple[float, np.ndarray], ...], ...]]:
        """The MJCF's mass moment of the base (m c, (3,)) and, per leg, (mass, inertial position) of its HIP,
        THIGH and SHANK bodies, read by name once (named access costs more than the arithmetic)."""
        model = self.mj_model
        base = model.body("base").id
        legs = tuple(
            tuple(
                (model.body_mass[b], model.body_ipos[b].copy())
                for b in (model.body(f"{g.leg}_{suffix}").id for suffix in ("HIP", "THIGH", "SHANK"))
            )
            for g in self.legs
        )
        return model.body_mass[base] * model.body_ipos[base], legs

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
        newton, sensitivity, offset = self.com_fixed_point_linearisation
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
    def com_fixed_point_linearisation(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
