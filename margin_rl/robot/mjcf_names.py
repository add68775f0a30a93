"""The names by which the environments read the robot's MJCF: bodies, sensors, the keyframe, the floor geom, and
the slices of ``qpos`` and ``qvel`` that hold the floating base and the joints.

Robot facts (masses, limits, gains, the standing pose) stay in the MJCF; this module holds only the names
that find them, declared once, so that an environment never spells a body, sensor or index itself. The
scene files (``scene_<robot>.xml``) and the rough-terrain scene (:mod:`margin_rl.envs.scene`) provide the
floor geom; the robot files provide everything else (checked when a robot is loaded, see
:func:`margin_rl.robot.load_robot`, and by the environments when they look each name up).

Layout of the state vectors (MuJoCo's, with the free joint first)::

    qpos = [base position (3), base quaternion w, x, y, z (4), joint angles (12)]
    qvel = [base linear velocity, world frame (3), base angular velocity, base frame (3), joint velocities (12)]
"""

from __future__ import annotations

from margin_rl.robot.model import LEGS, STANDING_KEYFRAME

__all__ = [
    "BASE_ANGULAR_VELOCITY_QVEL",
    "BASE_BODY",
    "BASE_CONTACT_SENSOR",
    "BASE_LINEAR_VELOCITY_QVEL",
    "BASE_POSITION_QPOS",
    "BASE_QUATERNION_QPOS",
    "BASE_QVEL",
    "COM_SENSOR",
    "COM_VELOCITY_SENSOR",
    "FLOOR_GEOM",
    "JOINT_QPOS",
    "JOINT_QVEL",
    "STANDING_KEYFRAME",
    "foot_contact_sensor",
    "foot_geom",
    "shank_body",
    "thigh_contact_sensor",
]

BASE_BODY = "base"
"""The floating base's body (pushes act at its origin)."""

FLOOR_GEOM = "floor"
"""The ground geom, a plane or the rough terrain's heightfield (its friction is randomised per environment)."""

COM_SENSOR = "com"
"""Subtree centre of mass of the base (the whole robot) [m], world frame."""

COM_VELOCITY_SENSOR = "com_vel"
"""Subtree linear velocity of the base (the whole robot's CoM velocity) [m/s], world frame."""

BASE_CONTACT_SENSOR = "base_contact"
"""Contact sensor of the base with the terrain (its first entry, "found", is > 0 on contact)."""

BASE_POSITION_QPOS = slice(0, 3)
"""qpos entries of the base position [m], world frame."""

BASE_QUATERNION_QPOS = slice(3, 7)
"""qpos entries of the base orientation, a (w, x, y, z) quaternion R_WB."""

JOINT_QPOS = slice(7, None)
"""qpos entries of the joint angles [rad], in the robot's joint order (legs LF, RF, LH, RH; HAA, HFE, KFE)."""

BASE_LINEAR_VELOCITY_QVEL = slice(0, 3)
"""qvel entries of the base linear velocity [m/s], world frame (MuJoCo's free joint)."""

BASE_ANGULAR_VELOCITY_QVEL = slice(3, 6)
"""qvel entries of the base angular velocity [rad/s], base frame (MuJoCo's free joint)."""

BASE_QVEL = slice(0, 6)
"""qvel entries of the free joint (the base's linear and angular velocity)."""

JOINT_QVEL = slice(6, None)
"""qvel entries of the joint velocities [rad/s], in the joint order of :data:`JOINT_QPOS`."""


def _check_leg(leg: str) -> None:
    if leg not in LEGS:
        raise ValueError(f"unknown leg {leg!r}; the legs are {', '.join(LEGS)}")


def shank_body(leg: str) -> str:
    """The shank body of ``leg`` (``LF``, ``RF``, ``LH``, ``RH``); its origin is the knee (KFE) joint."""
    _check_leg(leg)
    return f"{leg}_SHANK"


def foot_geom(leg: str) -> str:
    """The collision sphere of ``leg``'s foot (its centre is the ``<leg>_FOOT`` site)."""
    _check_leg(leg)
    return f"{leg}_foot"


def foot_contact_sensor(leg: str) -> str:
    """The contact sensor of ``leg``'s foot with the terrain (first entry > 0 on contact)."""
    _check_leg(leg)
    return f"{leg}_foot_contact"


def thigh_contact_sensor(leg: str) -> str:
    """The contact sensor of ``leg``'s thigh with the terrain (a thigh contact ends an episode)."""
    _check_leg(leg)
    return f"{leg}_THIGH_contact"
