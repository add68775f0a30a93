"""Gymnasium environments of margin_rl, installed as ``margin_rl.envs`` (a layer above the stability layer).

Ids (registered by :mod:`margin_rl.registration` on ``import margin_rl``): ``margin_rl/AnymalB-v1``,
``margin_rl/AnymalC-v1`` (flat ground), ``margin_rl/AnymalB-Rough-v1``, ``margin_rl/AnymalC-Rough-v1``
(rough terrain), usable with ``gymnasium.make`` and ``gymnasium.make_vec`` (native batched vector env);
``margin_rl/SLIPHopper-v0``: the actuated SLIP hopper of seed 001, one apex-to-apex hop per step, with an
optional learned failure-margin reward term. This package never imports SB3 or rsl-rl.

Map::

    anymal.py, vector.py     the single and the batched Gymnasium env (the public surface)
    core.py                  AnymalCore: the batched simulation and its step, stage by stage
    physics.py               the seam: PhysicsBackend (the contract) and MujocoBatchPhysics (mujoco.batch)
    physics_warp.py          WarpPhysics: MuJoCo Warp behind the same seam (the optional gpu extra)
    backends.py              the backends by name (physics="mujoco" | "warp") and make_physics
    step_data.py             the core's per-step records (state read, accelerations, step output)
    config.py                EnvConfig and its parts (frozen), reward presets and parameters
    margin_kinds.py          the margin kinds of the reward term, declared once
    terminations.py          the termination causes, declared once
    stability_input.py       lambda (seed 000 eq. 4) from the simulator's state
    rewards.py, observations.py, terrain.py, scene.py
    slip_hopper.py           margin_rl/SLIPHopper-v0

The robot's MJCF names (bodies, sensors, keyframe, floor, qpos/qvel layout) come from
:mod:`margin_rl.robot.mjcf_names`.
"""

from __future__ import annotations

from margin_rl.registration import (
    ANYMAL_ENV_IDS,
    EPISODE_STEPS,
    LEGACY_ANYMAL_IDS,
    SLIP_HOPPER_ENV_ID,
    SLIP_HOPPER_EPISODE_HOPS,
    current_env_id,
    register_envs,
    register_slip_envs,
)

register_envs()
register_slip_envs()

__all__ = [
    "ANYMAL_ENV_IDS",
    "EPISODE_STEPS",
    "LEGACY_ANYMAL_IDS",
    "SLIP_HOPPER_ENV_ID",
    "SLIP_HOPPER_EPISODE_HOPS",
    "current_env_id",
    "register_envs",
    "register_slip_envs",
]
