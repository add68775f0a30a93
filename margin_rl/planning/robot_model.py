"""What the planner needs to know about a robot, read from its MJCF through :func:`margin_rl.load_robot`.

Frames: base frame B (x forward, y left, z up, origin at the base body); positions in B are relative
to the base origin [m]. The planner's base position variable is the whole-body CoM c, so the base
origin is c - R c_B, with c_B the CoM in B at the *planning pose*.

The planning pose is the standing keyframe with the feet raised by ``crouch`` in B (the base lowered):
ANYmal's standing keyframe has nearly straight legs, from which a foot can barely move down or
forward (measured: 2 cm below the standing foot, forward reach under 15 cm), so a range of motion
centred there would be lopsided. Crouched by 12 cm, a box of +-(20, 10, 8) cm around each foot lies
inside the leg's workspace and joint limits for both robots (:func:`range_of_motion_reachable`, tested).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from margin_rl.robot import Robot


@dataclass(frozen=True, eq=False)
class PlanningRobot:
    """Robot facts of the planner (all read from the MJCF through ``robot``)."""

    robot: Robot
    crouch: float  # [m] feet raised in B relative to the standing keyframe
    rom_half_extents: np.ndarray  # (3,) [m] range of motion of each foot around its nominal position, in B
    nominal_feet_base: np.ndarray  # (4, 3) foot-sphere centres in B at the planning pose [m]
    com_offset_base: np.ndarray  # (3,) whole-body CoM in B at the planning pose [m]
    nominal_com_height: float  # CoM height above flat ground at the planning pose [m]

    @property
    def name(self) -> str:
        return self.robot.name

    @property
    def foot_radius(self) -> float:
        return self.robot.foot_radius

    @property
    def nominal_feet_com(self) -> np.ndarray:
        """(4, 3) foot-sphere centres relative to the CoM at the planning pose with a level base [m]."""
        return self.nominal_feet_base - self.com_offset_base

    @property
    def hip_positions_base(self) -> np.ndarray:
        """(4, 3) HAA joint positions in B [m] (figures; the range of motion is centred below them)."""
        return np.stack([g.haa_origin for g in self.robot.legs])


def planning_robot(
    robot: Robot, crouch: float = 0.12, rom_half_extents: tuple[float, float, float] = (0.2, 0.1, 0.08)
) -> PlanningRobot:
    """Planner facts of ``robot`` (see the module docstring for the planning pose).

    Raises:
        ValueError: negative crouch or half-extents, or a planning pose the legs cannot reach.
    """
    half = np.asarray(rom_half_extents, dtype=float)
    if half.shape != (3,) or not np.all(half >= 0):
        raise ValueError(f"rom_half_extents must be three non-negative lengths [m], got {rom_half_extents!r}")
    if not crouch >= 0:
        raise ValueError(f"crouch must be a non-negative length [m], got {crouch!r}")
    standing_feet = robot.foot_positions(robot.standing_joint_pos)
    feet = standing_feet + np.array([0.0, 0.0, crouch])
    ik = robot.inverse_kinematics(feet)
    if not ik.reachable.all():
        raise ValueError(
            f"{robot.name}: the planning pose with crouch {crouch} m is not reachable; use a smaller crouch"
        )
    com = robot.com_position(ik.joint_pos)
    # Height of the CoM above the ground when the feet (sphere centres r above the ground) are at `feet`.
    height = float(com[2] - feet[:, 2].mean() + robot.foot_radius)
    return PlanningRobot(
        robot=robot,
        crouch=float(crouch),
        rom_half_extents=half,
        nominal_feet_base=feet,
        com_offset_base=com,
        nominal_com_height=height,
    )


def range_of_motion_reachable(model: PlanningRobot, points_per_axis: int = 7) -> np.ndarray:
    """Per leg (4,): whether every point of a grid over its range-of-motion box is reachable by IK."""
    g = np.linspace(-1.0, 1.0, points_per_axis)
    cube = np.array(list(itertools.product(g, g, g))) * model.rom_half_extents
    feet = model.nominal_feet_base[None] + cube[:, None, :]
    return model.robot.inverse_kinematics(feet).reachable.all(axis=0)
