"""Gymnasium environments of margin_rl, installed as ``margin_rl.envs``; registered on ``import margin_rl``.

Ids: ``margin_rl/AnymalB-v0``, ``margin_rl/AnymalC-v0`` (flat ground), ``margin_rl/AnymalB-Rough-v0``,
``margin_rl/AnymalC-Rough-v0`` (rough terrain), usable with ``gymnasium.make`` and
``gymnasium.make_vec`` (native batched vector env); ``margin_rl/SLIPHopper-v0``: the actuated SLIP hopper
of seed 001, one apex-to-apex hop per step, with an optional learned failure-margin reward term.
This package never imports SB3 or rsl-rl.
"""

from __future__ import annotations

import gymnasium

EPISODE_STEPS = 1000
"""20 s at the 50 Hz policy rate (EnvConfig.episode_length_s / (MJCF timestep x decimation); tested)."""

ANYMAL_ENV_IDS: dict[str, dict[str, str]] = {
    "margin_rl/AnymalB-v0": {"robot": "anymal_b", "terrain": "flat"},
    "margin_rl/AnymalC-v0": {"robot": "anymal_c", "terrain": "flat"},
    "margin_rl/AnymalB-Rough-v0": {"robot": "anymal_b", "terrain": "rough"},
    "margin_rl/AnymalC-Rough-v0": {"robot": "anymal_c", "terrain": "rough"},
}


def register_envs() -> None:
    """Register the environment ids (idempotent)."""
    for env_id, kwargs in ANYMAL_ENV_IDS.items():
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point="margin_rl.envs.anymal:AnymalEnv",
            vector_entry_point="margin_rl.envs.vector:AnymalVectorEnv",
            max_episode_steps=EPISODE_STEPS,
            kwargs=dict(kwargs),
        )


register_envs()

SLIP_HOPPER_ENV_ID = "margin_rl/SLIPHopper-v0"
SLIP_HOPPER_EPISODE_HOPS = 50
"""Episode length of ``margin_rl/SLIPHopper-v0`` in hops (one step = one apex-to-apex hop)."""


def register_slip_envs() -> None:
    """Register ``margin_rl/SLIPHopper-v0`` (aSLIP apex velocity tracking, :mod:`margin_rl.envs.slip_hopper`)."""
    if SLIP_HOPPER_ENV_ID in gymnasium.registry:
        return
    gymnasium.register(
        id=SLIP_HOPPER_ENV_ID,
        entry_point="margin_rl.envs.slip_hopper:SlipHopperEnv",
        max_episode_steps=SLIP_HOPPER_EPISODE_HOPS,
    )


register_slip_envs()
