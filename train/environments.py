"""The one environment interface of training and evaluation: the batched margin_rl ANYmal ids.

Every id that ``margin_rl.train`` trains and evaluates is one of :data:`margin_rl.registration.ANYMAL_ENV_IDS`
and runs on the one batched simulation, :class:`margin_rl.envs.core.AnymalCore`,
configured by an :class:`~margin_rl.envs.config.EnvConfig`: :class:`AnymalTarget`, built by :func:`env_target`;
:func:`margin_rl.train.commands.train.make_spec`, ``evaluate`` and the backends work on the target.

Any other id, unknown or registered, is refused with one clear error (:func:`anymal_id`) that names the ANYmal
ids: other Gymnasium environments, e.g. the SLIP hopper ``margin_rl/SLIPHopper-v0``, are trained with plain
Stable-Baselines3 (:data:`SB3_EXAMPLE`).

Ids are looked up through :func:`margin_rl.registration.current_env_id`: a retired ANYmal ``-v0`` id (stored in
older run directories and policy bundles) is read as its ``-v1`` id, which has the same dynamics.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium

from margin_rl.envs.anymal import ACTION_SIZE as ACTION_SIZE  # re-exported: the backends and analyses take it from here
from margin_rl.envs.anymal import make_config
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.registration import ANYMAL_ENV_IDS, current_env_id
from margin_rl.stability.learned.model import LearnedMargin, WeightsError
from margin_rl.train.config import apply_overrides

DEFAULT_ENV = "margin_rl/AnymalB-v1"
SB3_EXAMPLE = "examples/train_slip_hopper.py"
"""The repository's example of plain Stable-Baselines3 on another Gymnasium environment (the SLIP hopper)."""


# ---------------------------------------------------------------------------------------------------------------------
# the ids: the batched ANYmal ones, and one error for every other
# ---------------------------------------------------------------------------------------------------------------------
def _anymal_only(caller: str) -> str:
    return (
        f"{caller} runs the batched margin_rl ANYmal ids only ({', '.join(ANYMAL_ENV_IDS)}); other Gymnasium "
        "environments, e.g. the SLIP hopper margin_rl/SLIPHopper-v0, are trained with plain Stable-Baselines3: "
        f"see {SB3_EXAMPLE}"
    )


def registered_spec(env_id: str, caller: str = "margin_rl.train") -> gymnasium.envs.registration.EnvSpec:
    """Gymnasium's registration of ``env_id`` (of its ``-v1`` id for a retired ANYmal ``-v0`` one).

    Raises:
        ValueError: the id is not registered (the message names the ANYmal ids).
    """
    try:
        return gymnasium.spec(current_env_id(env_id))
    except gymnasium.error.Error as exc:
        raise ValueError(f"unknown environment id {env_id!r}: {_anymal_only(caller)}") from exc


def _anymal_spec(env_id: str, caller: str) -> gymnasium.envs.registration.EnvSpec:
    spec = registered_spec(env_id, caller)
    if spec.id not in ANYMAL_ENV_IDS:
        raise ValueError(f"{env_id!r} is not a margin_rl ANYmal environment: {_anymal_only(caller)}")
    return spec


def anymal_id(env_id: str, caller: str = "margin_rl.train") -> str:
    """The registered id of a batched ANYmal id (the ``-v1`` id of a retired ``-v0`` one).

    ``caller`` names what refuses another id, in the error message.

    Raises:
        ValueError: the id is unknown, or is not a batched ANYmal id (the message names the ANYmal ids and
            points at plain Stable-Baselines3 for other Gymnasium environments).
    """
    return _anymal_spec(env_id, caller).id


# ---------------------------------------------------------------------------------------------------------------------
# configuration and simulation
# ---------------------------------------------------------------------------------------------------------------------
def env_config_for(env_id: str, overrides: dict[str, Any] | None = None) -> EnvConfig:
    """The :class:`EnvConfig` of a registered margin_rl ANYmal id with keyword overrides (EnvConfig fields).

    Raises:
        ValueError: the id is not a batched ANYmal id (:func:`anymal_id`).
    """
    kwargs = dict(_anymal_spec(env_id, "margin_rl.train").kwargs)
    base = make_config(None, kwargs.get("robot", "anymal_c"), kwargs.get("terrain", "flat"), {})
    return apply_overrides(base, dict(overrides or {}))


def check_margin_available(config: EnvConfig) -> None:
    """Fail early, with a hint, when the learned margin's weights cannot be loaded.

    Raises:
        ValueError: (``margin_rl.stability.learned.model.WeightsError``) missing, corrupted or mismatched weights.
    """
    if config.margin != "learned":
        return
    try:
        LearnedMargin.load(config.margin_weights or config.robot)
    except WeightsError as exc:
        raise WeightsError(
            f"{exc}. Pass learned-margin weights with --margin-weights PATH.npz (margin_weights=...), "
            "or train without the margin model with --margin none"
        ) from exc


def margin_identity(config: EnvConfig) -> dict[str, Any] | None:
    """Which learned margin an environment of ``config`` computes: ``{"source": robot name or weights path,
    "sha256": of the weights}``, or None without a learned margin. A run records it when it starts, so that a
    resumed run, a bundle or an evaluation can tell when the robot's default weights changed since."""
    if config.margin != "learned":
        return None
    return weights_identity(config.margin_weights or config.robot)


def weights_identity(source: str) -> dict[str, Any]:
    """``{"source": source, "sha256": ...}`` of the learned-margin weights ``source`` (a robot name or an .npz
    path) loads now."""
    return {"source": source, "sha256": LearnedMargin.load(source).card.get("sha256")}


def make_core(
    config: EnvConfig,
    num_envs: int,
    seed: int | None,
    physics: str = "mujoco",
    physics_device: str | None = None,
    physics_options: dict[str, Any] | None = None,
) -> AnymalCore:
    """The batched simulation of ``num_envs`` environments (reset by the adapters) on backend ``physics`` at
    ``physics_device`` with its ``physics_options`` (:func:`margin_rl.envs.backends.make_physics`)."""
    return AnymalCore(
        config, num_envs, seed, physics=physics, physics_device=physics_device, physics_options=physics_options
    )


def observation_size(core: AnymalCore) -> int:
    """Size of the policy observation of a core."""
    return int(core.observation_size)


@dataclass(frozen=True)
class AnymalTarget:
    """The environment of a run or an evaluation: a batched ANYmal id and its :class:`EnvConfig`."""

    env_id: str
    config: EnvConfig

    @property
    def margin_weight(self) -> float:
        """Weight of the margin reward term."""
        return self.config.margin_weight


def env_target(env_id: str, overrides: Mapping[str, Any] | None = None) -> AnymalTarget:
    """The environment of ``env_id`` (its current id) with EnvConfig field ``overrides``, checked by name and type.

    Raises:
        ValueError: not a batched ANYmal id (:func:`anymal_id`). TypeError: unknown fields or badly typed values.
    """
    env_id = anymal_id(env_id)  # a new run records the current id
    return AnymalTarget(env_id, env_config_for(env_id, dict(overrides or {})))


def anymal_config(env_id: str, options: Mapping[str, Any], caller: str) -> EnvConfig:
    """The checked :class:`EnvConfig` of a batched ANYmal id for the vector-environment factories.

    ``caller`` names the factory in the error messages.

    Raises:
        ValueError: ``env_id`` is not a batched ANYmal id (:func:`anymal_id`); the learned margin's weights are
            missing.
        TypeError: an option that is not an EnvConfig field (the message lists the fields), or a bad value.
    """
    anymal_id(env_id, caller)
    fields = sorted(f.name for f in dataclasses.fields(EnvConfig))
    unknown = sorted(set(options) - set(fields))
    if unknown:
        raise TypeError(f"{caller}: unknown environment option(s) {unknown} for {env_id}; the options are the "
                        f"EnvConfig fields: {', '.join(fields)}{EnvConfig.unknown_field_hint(unknown)}")  # fmt: skip
    config = env_config_for(env_id, dict(options))
    check_margin_available(config)
    return config
