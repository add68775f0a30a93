"""Where a reset starts an episode: the standing keyframe placed on a spawn point, its joints and base velocity with
uniform noise, the friction and the command drawn (:class:`StandingStart`). Every uniform draw of a reset is made in
one call (:func:`~margin_rl.arrays.uniform_columns`): numpy's one after another, as they always were, so the host's
random stream is unchanged; one (n, columns) draw on a device. The state is built in a few operations (on a device
each is a kernel launched from Python)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from array_api_compat import device as device_of

from margin_rl.arrays import namespace, uniform_columns
from margin_rl.envs.config import EnvConfig
from margin_rl.robot import mjcf_names as names

SPAWN_CLEARANCE = 0.02
"""[m] the base starts this much higher than the keyframe's height above the spawn point's ground."""


@dataclass(frozen=True)
class ResetDraws:
    """A reset's uniform draws for n environments (arrays of the generator's kind)."""

    joint_noise: Any  # (n, 12) in [-1, 1), scaled by RandomizationConfig.reset_joint_noise
    velocity_noise: Any  # (n, 6) in [-1, 1), scaled by RandomizationConfig.reset_velocity_noise
    friction: Any  # (n,) the floor's friction coefficient; None without friction randomisation
    command: Any  # (n, 3) (v_x [m/s], v_y [m/s], yaw rate [rad/s])


@dataclass(frozen=True)
class StandingStart:
    """The standing keyframe's parts a reset builds qpos from, in the core's kind (views, made once)."""

    base_height: float  # [m] the keyframe's base z
    quat: Any  # (4,) base orientation (w, x, y, z)
    joint_pos: Any  # (12,) [rad]
    nv: int  # qvel entries

    @classmethod
    def of(cls, key_qpos: Any, nv: int) -> StandingStart:
        """From the keyframe's qpos (an array of the core's kind) and the model's nv."""
        base_height = float(key_qpos[names.BASE_POSITION_QPOS][2])
        return cls(base_height, key_qpos[names.BASE_QUATERNION_QPOS], key_qpos[names.JOINT_QPOS], int(nv))

    def state(self, spawn: Any, draws: ResetDraws, config: EnvConfig) -> tuple[Any, Any]:
        """qpos (n, nq) and qvel (n, nv), float64: the base above ``spawn`` (n, 3) (a point on the ground [m]) in
        the keyframe's orientation, the keyframe's joint angles plus noise, every velocity 0 but the base's noise
        (the qpos layout: position, quaternion, joints, :mod:`margin_rl.robot.mjcf_names`)."""
        xp, rnd, n = namespace(spawn), config.randomization, int(spawn.shape[0])
        spawn_z = spawn[:, 2:3] + self.base_height + SPAWN_CLEARANCE
        orientation = xp.broadcast_to(self.quat, (n, 4))
        joint_pos = self.joint_pos + draws.joint_noise * rnd.reset_joint_noise
        qpos = xp.concat([spawn[:, :2], spawn_z, orientation, joint_pos], axis=1)
        qvel = xp.zeros((n, self.nv), dtype=xp.float64, device=device_of(spawn))
        qvel[:, names.BASE_QVEL] = draws.velocity_noise * rnd.reset_velocity_noise
        return qpos, qvel


def draw_reset(rng: Any, n: int, config: EnvConfig) -> ResetDraws:
    """The uniform draws of a reset of n environments under ``config`` (its randomisation and command ranges), in
    numpy's order: joint noise, base velocity noise, friction (if randomised), the three commands."""
    rnd, c = config.randomization, config.command
    friction = () if rnd.friction is None else ((*rnd.friction, None),)
    velocities = (c.forward_velocity, c.lateral_velocity, c.yaw_rate)
    commands = (tuple(low for low, _ in velocities), tuple(high for _, high in velocities), 3)  # a column each
    joint_noise, velocity_noise, *drawn = uniform_columns(rng, n, ((-1, 1, 12), (-1, 1, 6), *friction, commands))
    mu = drawn[0] if friction else None
    return ResetDraws(joint_noise, velocity_noise, mu, drawn[-1])
