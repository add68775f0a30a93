"""Shared, hand-solvable fixtures for the feasible-region tests and benchmark.

Everything is in the horizontal frame H (origin at the CoM, z up).  The quadruped is a generic
30 kg robot with hips at (+-0.3, +-0.2, 0) m and 3-DoF legs (HAA about x, HFE and KFE about y,
thigh and shank 0.3 m each); its foot Jacobians come from an analytic forward/inverse kinematics
written here, independently of the code under test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

G = 9.81
MASS = 30.0
HIP_X = 0.3
HIP_Y = 0.2
THIGH = 0.3
SHANK = 0.3
STANDING_HEIGHT = 0.45  # foot depth below the hips [m]
# Order used everywhere: LF, RF, LH, RH.
HIPS = np.array([[HIP_X, HIP_Y, 0.0], [HIP_X, -HIP_Y, 0.0], [-HIP_X, HIP_Y, 0.0], [-HIP_X, -HIP_Y, 0.0]])


def rect_feet(length: float = 0.6, width: float = 0.4, height: float = 0.5) -> FloatArray:
    """Four feet at (+-L/2, +-W/2, -h): LF, RF, LH, RH."""
    return np.array(
        [
            [length / 2, width / 2, -height],
            [length / 2, -width / 2, -height],
            [-length / 2, width / 2, -height],
            [-length / 2, -width / 2, -height],
        ]
    )


def flat_normals(n: int) -> FloatArray:
    return np.tile([0.0, 0.0, 1.0], (n, 1))


def unit_jacobians(n: int) -> FloatArray:
    """Jacobians J = I (k = 3): joint torques are minus the contact force components [N m]."""
    return np.tile(np.eye(3), (n, 1, 1))


def rot_x(a: float) -> FloatArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> FloatArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def leg_fk(hip: FloatArray, q: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Foot position and translational Jacobian (3, 3) of the 3-DoF leg at ``hip``.

    thigh = Rx(q0) Ry(q1) (0, 0, -l1), shank = Rx(q0) Ry(q1 + q2) (0, 0, -l2).  Columns of the
    Jacobian are axis_j x (foot - origin_j) for the revolute joints HAA (x at the hip), HFE
    (Rx(q0) y at the hip) and KFE (Rx(q0) y at the knee).
    """
    rx = rot_x(q[0])
    knee = hip + rx @ rot_y(q[1]) @ np.array([0.0, 0.0, -THIGH])
    foot = knee + rx @ rot_y(q[1] + q[2]) @ np.array([0.0, 0.0, -SHANK])
    ax_haa = np.array([1.0, 0.0, 0.0])
    ax_y = rx @ np.array([0.0, 1.0, 0.0])
    jac = np.column_stack([np.cross(ax_haa, foot - hip), np.cross(ax_y, foot - hip), np.cross(ax_y, foot - knee)])
    return foot, jac


def leg_ik(hip: FloatArray, foot: FloatArray, knee_sign: float = -1.0) -> FloatArray:
    """Joint angles placing the foot at ``foot`` (knee bent with sign ``knee_sign``)."""
    d = foot - hip
    q0 = math.atan2(d[1], -d[2])
    r = math.hypot(d[1], d[2])
    x, z = d[0], -r  # in the leg plane
    c3 = (x * x + z * z - THIGH**2 - SHANK**2) / (2.0 * THIGH * SHANK)
    if abs(c3) > 1.0:
        raise ValueError("foot out of reach")
    q2 = knee_sign * math.acos(c3)
    # -x = l1 sin q1 + l2 sin(q1 + q2), -z = l1 cos q1 + l2 cos(q1 + q2)
    q1 = math.atan2(-x, -z) - math.atan2(SHANK * math.sin(q2), THIGH + SHANK * math.cos(q2))
    return np.array([q0, q1, q2])


def quadruped_jacobians(feet: FloatArray) -> FloatArray:
    """(4, 3, 3) Jacobians from IK for feet given relative to the CoM (level base)."""
    jac = np.zeros((4, 3, 3))
    for i in range(4):
        q = leg_ik(HIPS[i], feet[i])
        foot, jac[i] = leg_fk(HIPS[i], q)
        assert np.allclose(foot, feet[i], atol=1e-9), "IK failed"
    return jac


def nominal_feet(dx: float = 0.0) -> FloatArray:
    """Feet under the hips, STANDING_HEIGHT below, pushed fore/aft by dx."""
    return HIPS + np.array([dx, 0.0, -STANDING_HEIGHT])


@dataclass
class Case:
    """Keyword arguments for ``feasible_region`` (plus a label)."""

    label: str
    kwargs: dict[str, Any] = field(default_factory=dict)


def quadruped_case(
    stance: tuple[bool, bool, bool, bool] = (True, True, True, True),
    torque_limit: float = 40.0,
    mu: float = 0.6,
    feet: FloatArray | None = None,
    normals: FloatArray | None = None,
    **extra: Any,
) -> dict[str, Any]:
    """A realistic standing quadruped: IK Jacobians, symmetric torque limits, flat ground."""
    feet = nominal_feet() if feet is None else feet
    return dict(
        feet=feet,
        normals=flat_normals(4) if normals is None else normals,
        stance=np.array(stance),
        mu=mu,
        mass=MASS,
        jacobians=quadruped_jacobians(feet),
        torque_limits=np.full((4, 3), torque_limit),
        **extra,
    )


def random_quadruped_case(rng: np.random.Generator, stance: tuple[bool, ...]) -> dict[str, Any]:
    """A perturbed quadruped with tilted normals, accelerations and an external wrench."""
    feet = nominal_feet() + rng.uniform([-0.1, -0.05, -0.05], [0.1, 0.05, 0.05], size=(4, 3))
    tilt = rng.normal(0.0, 0.15, size=(4, 2))
    normals = np.column_stack([np.sin(tilt[:, 0]), np.sin(tilt[:, 1]), np.ones(4)])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return quadruped_case(
        stance=tuple(stance),
        torque_limit=float(rng.uniform(35.0, 60.0)),
        mu=float(rng.uniform(0.4, 0.9)),
        feet=feet,
        normals=normals,
        com_acc=rng.uniform([-1.5, -1.5, -1.0], [1.5, 1.5, 1.0]),
        ang_momentum_rate=rng.normal(0.0, 0.5, size=3),
        ext_force=rng.normal(0.0, 10.0, size=3),
        ext_torque=rng.normal(0.0, 2.0, size=3),
    )


def support_rectangle(length: float, width: float, expand: float = 0.0) -> FloatArray:
    """CCW vertices of the rectangle [-L/2 - e, L/2 + e] x [-W/2 - e, W/2 + e]."""
    a, b = length / 2 + expand, width / 2 + expand
    return np.array([[a, b], [-a, b], [-a, -b], [a, -b]])
