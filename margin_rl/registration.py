"""The Gymnasium ids of margin_rl, registered by name only: nothing of ``margin_rl.envs`` is imported here.

``import margin_rl`` calls :func:`register_envs`; Gymnasium imports an environment's module the first time
it is made (the entry points are strings), so the package root stays below the environment layer. In a
fresh interpreter without ``import margin_rl``, ``gymnasium.make("margin_rl:margin_rl/AnymalB-v1")`` imports
the package through Gymnasium's ``module:id`` syntax (Gymnasium 1.x has no plugin entry points).

Ids: ``margin_rl/AnymalB-v1``, ``margin_rl/AnymalC-v1`` (flat ground), ``margin_rl/AnymalB-Rough-v1``,
``margin_rl/AnymalC-Rough-v1`` (rough terrain), each with a native batched vector entry point for
``gymnasium.make_vec``; ``margin_rl/SLIPHopper-v0`` (seed 001's actuated SLIP hopper, one hop per step).

The ANYmal ids ``-v0`` are not registered any more (the version history is in :mod:`margin_rl.envs.anymal`):
``gymnasium.make`` of one raises Gymnasium's own ``gymnasium.error.DeprecatedEnv`` naming the ``-v1`` id.
Stored runs and policy bundles that name a ``-v0`` id are read as its ``-v1`` id (the dynamics are the same):
:func:`current_env_id`, with the table :data:`LEGACY_ANYMAL_IDS`, is the one place that translation happens.
"""

from __future__ import annotations

import gymnasium

EPISODE_STEPS = 1000
"""Default episode length: 20 s at the 50 Hz policy rate (EnvConfig.episode_length_s / (MJCF timestep x
decimation); tested). The ANYmal ids register no ``max_episode_steps``: the environments truncate their
episodes at their config's ``episode_length_s`` themselves, so a changed length is never overridden by a
registered TimeLimit."""

ANYMAL_ENV_IDS: dict[str, dict[str, str]] = {
    "margin_rl/AnymalB-v1": {"robot": "anymal_b", "terrain": "flat"},
    "margin_rl/AnymalC-v1": {"robot": "anymal_c", "terrain": "flat"},
    "margin_rl/AnymalB-Rough-v1": {"robot": "anymal_b", "terrain": "rough"},
    "margin_rl/AnymalC-Rough-v1": {"robot": "anymal_c", "terrain": "rough"},
}
"""ANYmal ids and the constructor keywords that make each one."""

LEGACY_ANYMAL_IDS: dict[str, str] = {env_id.replace("-v1", "-v0"): env_id for env_id in ANYMAL_ENV_IDS}
"""Retired ANYmal ids -> the id that replaced them with the same dynamics (read by :func:`current_env_id`)."""

SLIP_HOPPER_ENV_ID = "margin_rl/SLIPHopper-v0"
SLIP_HOPPER_EPISODE_HOPS = 50
"""Episode length of ``margin_rl/SLIPHopper-v0`` in hops (one step = one apex-to-apex hop)."""


def current_env_id(env_id: str) -> str:
    """The registered id for ``env_id``: a retired ANYmal ``-v0`` id becomes its ``-v1`` id, any other id is
    returned unchanged. For ids read from stored runs and bundles (and the training commands' ``--env``)."""
    return LEGACY_ANYMAL_IDS.get(env_id, env_id)


def register_envs() -> None:
    """Register the ANYmal ids (idempotent)."""
    for env_id, kwargs in ANYMAL_ENV_IDS.items():
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point="margin_rl.envs.anymal:AnymalEnv",
            vector_entry_point="margin_rl.envs.vector:AnymalVectorEnv",
            kwargs=dict(kwargs),
        )


def register_slip_envs() -> None:
    """Register ``margin_rl/SLIPHopper-v0`` (aSLIP apex velocity tracking, :mod:`margin_rl.envs.slip_hopper`)."""
    if SLIP_HOPPER_ENV_ID in gymnasium.registry:
        return
    gymnasium.register(
        id=SLIP_HOPPER_ENV_ID,
        entry_point="margin_rl.envs.slip_hopper:SlipHopperEnv",
        max_episode_steps=SLIP_HOPPER_EPISODE_HOPS,
    )


def register_all() -> None:
    """Register every id of the package (idempotent)."""
    register_envs()
    register_slip_envs()
