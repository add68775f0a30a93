"""The environment interface of training and evaluation, chosen once per id: batched ANYmal or generic Gymnasium.

ANYmal ids (registered with the batched ``vector_entry_point`` :data:`VECTOR_ENTRY_POINT`) run on the one batched
simulation, :class:`margin_rl.envs.core.AnymalCore`, configured by an :class:`~margin_rl.envs.config.EnvConfig`:
:class:`AnymalTarget`. Every other registered id (e.g. ``margin_rl/SLIPHopper-v0``) takes the generic path:
``gymnasium.make(id, **env_kwargs)``, SB3 only: :class:`GymTarget`. :func:`env_target` picks the kind from the
id's registration; :func:`margin_rl.train.commands.train.make_spec`, ``evaluate`` and the backends work on the target.

Ids are looked up through :func:`margin_rl.registration.current_env_id`: a retired ANYmal ``-v0`` id (stored in
older run directories and policy bundles) is read as its ``-v1`` id, which has the same dynamics.

Generic environment keywords are checked against the constructor's (:func:`env_kwargs_for`) and must be JSON,
since the run's ``config.json`` stores them for ``--resume`` and ``evaluate``. The generic path trains
continuous control: flat ``Box`` observations and ``Box`` actions (:func:`check_gym_env`).
"""

from __future__ import annotations

import dataclasses
import inspect
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from margin_rl.envs.anymal import make_config
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.registration import current_env_id
from margin_rl.stability.learned.model import LearnedMargin, WeightsError
from margin_rl.train.config import apply_overrides, to_dict

DEFAULT_ENV = "margin_rl/AnymalB-v1"
ACTION_SIZE = 12
VECTOR_ENTRY_POINT = "margin_rl.envs.vector:AnymalVectorEnv"
NAMESPACE = "margin_rl/"
MARGIN_WEIGHT_KEYWORD = "margin_weight"
"""Keyword of an environment's margin-reward weight: ``--margin-weight`` sets it where the constructor takes it."""
MAKE_KEYWORDS: tuple[str, ...] = ("max_episode_steps",)
"""``gymnasium.make`` keywords accepted as environment options besides the constructor's (episode length)."""
RESERVED_KEYWORDS: tuple[str, ...] = ("render_mode",)
"""Constructor keywords that training and evaluation set themselves."""
GENERIC_STEP_LIMIT = 100_000
"""Steps after which an evaluation episode of an environment without a time limit is cut."""


# ---------------------------------------------------------------------------------------------------------------------
# registered ids (margin_rl registers its ids on import: the parent package of this one)
# ---------------------------------------------------------------------------------------------------------------------
def margin_rl_ids() -> list[str]:
    """Every registered ``margin_rl/`` id, sorted."""
    return sorted(k for k in gymnasium.registry if k.startswith(NAMESPACE))


def registered_spec(env_id: str) -> gymnasium.envs.registration.EnvSpec:
    """Gymnasium's registration of ``env_id`` (of its ``-v1`` id for a retired ANYmal ``-v0`` one).

    Raises:
        ValueError: the id is not registered (the message lists the margin_rl ids).
    """
    try:
        return gymnasium.spec(current_env_id(env_id))
    except gymnasium.error.Error as exc:
        raise ValueError(
            f"unknown environment id {env_id!r}; margin_rl ids: {', '.join(margin_rl_ids())} "
            "(any other registered Gymnasium id works too, with --backend sb3)"
        ) from exc


def is_batched_anymal(env_id: str) -> bool:
    """True for the ids that run on the batched ANYmal core (``env_config``), False for the generic path.

    Raises:
        ValueError: the id is not registered.
    """
    return registered_spec(env_id).vector_entry_point == VECTOR_ENTRY_POINT


# ---------------------------------------------------------------------------------------------------------------------
# batched ANYmal ids
# ---------------------------------------------------------------------------------------------------------------------
def env_config_for(env_id: str, overrides: dict[str, Any] | None = None) -> EnvConfig:
    """The :class:`EnvConfig` of a registered margin_rl ANYmal id with keyword overrides (EnvConfig fields).

    Raises:
        ValueError: the id is not registered, or is not a margin_rl ANYmal environment (see :func:`env_kwargs_for`).
    """
    spec = registered_spec(env_id)
    if spec.vector_entry_point != VECTOR_ENTRY_POINT:
        raise ValueError(
            f"{env_id!r} is not a margin_rl ANYmal environment (its vector entry point is not "
            f"{VECTOR_ENTRY_POINT}); it has no EnvConfig: build it with env_kwargs_for (generic Gymnasium path)"
        )
    kwargs = dict(spec.kwargs)
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


def make_core(config: EnvConfig, num_envs: int, seed: int | None) -> AnymalCore:
    """The batched simulation of ``num_envs`` environments (reset by the adapters)."""
    return AnymalCore(config, num_envs=num_envs, seed=seed)


def observation_size(core: AnymalCore) -> int:
    """Size of the policy observation of a core."""
    return int(core.observation_size)


# ---------------------------------------------------------------------------------------------------------------------
# any other registered Gymnasium id
# ---------------------------------------------------------------------------------------------------------------------
def _creator(spec: gymnasium.envs.registration.EnvSpec) -> Any:
    creator = spec.entry_point
    return gymnasium.envs.registration.load_env_creator(creator) if isinstance(creator, str) else creator


def env_keywords(env_id: str) -> tuple[str, ...] | None:
    """The keyword options of a registered id: its constructor's keywords (less :data:`RESERVED_KEYWORDS`) and
    :data:`MAKE_KEYWORDS`, sorted; None when the constructor takes ``**kwargs`` (any name is accepted).

    Raises:
        ValueError: the id is not registered.
    """
    parameters = inspect.signature(_creator(registered_spec(env_id))).parameters.values()
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return None
    named = {
        p.name
        for p in parameters
        if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
        and p.name not in RESERVED_KEYWORDS
    }
    return tuple(sorted(named | set(MAKE_KEYWORDS)))


def takes_keyword(env_id: str, name: str) -> bool:
    """Whether the id's constructor takes the keyword ``name`` (explicitly, not through ``**kwargs``)."""
    known = env_keywords(env_id)
    return known is not None and name in known


def _json_copy(kwargs: Mapping[str, Any], env_id: str) -> dict[str, Any]:
    """A deep copy of ``kwargs`` through JSON (tuples become lists), so that config.json holds them exactly."""
    try:
        return json.loads(json.dumps(dict(kwargs), allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"environment options of {env_id!r} must be finite JSON values (numbers, strings, booleans, null, "
            f"lists, mappings), since config.json keeps them for --resume and evaluate; got {dict(kwargs)!r} ({exc})"
        ) from exc


def env_kwargs_for(env_id: str, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The keyword overrides of a non-ANYmal registered id, checked and copied (JSON values).

    ``gymnasium.make(env_id, **result)`` builds the environment: its registered keywords with these on top.
    ``overrides`` itself is not modified.

    Raises:
        ValueError: the id is not registered, or is a batched ANYmal id (use :func:`env_config_for`).
        TypeError: an option the constructor does not take (the message lists those it takes), or a value
            that is not JSON.
    """
    if is_batched_anymal(env_id):
        raise ValueError(
            f"{env_id!r} runs on the batched ANYmal core: its options are EnvConfig fields (env_config_for)"
        )
    kwargs = _json_copy(overrides or {}, env_id)
    known = env_keywords(env_id)
    unknown = sorted(set(kwargs) - set(known)) if known is not None else []
    if unknown:
        hint = "; it has no margin weight: drop --margin-weight" if MARGIN_WEIGHT_KEYWORD in unknown else ""
        raise TypeError(
            f"{env_id}: unknown option(s) {unknown}; it takes {list(known)} (--env-option KEY=VALUE; "
            f"--margin, --margin-weights and --reward-preset are ANYmal options){hint}"
        )
    return kwargs


def env_keyword(env_id: str, kwargs: Mapping[str, Any], name: str) -> Any:
    """The value the environment gets for keyword ``name``: from ``kwargs``, else its registration, else the
    constructor's default (None when it has none)."""
    if name in kwargs:
        return kwargs[name]
    spec = registered_spec(env_id)
    if name in spec.kwargs:
        return spec.kwargs[name]
    parameter = inspect.signature(_creator(spec)).parameters.get(name)
    if parameter is None or parameter.default is inspect.Parameter.empty:
        return None
    return parameter.default


def margin_weight_of(env_id: str, kwargs: Mapping[str, Any]) -> float | None:
    """The margin-reward weight a generic environment gets, or None when it has no such keyword."""
    if not takes_keyword(env_id, MARGIN_WEIGHT_KEYWORD):
        return None
    value = env_keyword(env_id, kwargs, MARGIN_WEIGHT_KEYWORD)
    return float(value) if isinstance(value, (int, float)) else None


def make_gym_env(env_id: str, kwargs: Mapping[str, Any], render_mode: str | None = None) -> gymnasium.Env:
    """``gymnasium.make(env_id, **kwargs)`` (a copy of ``kwargs``), with ``render_mode`` when one is asked for."""
    options = dict(kwargs)
    if render_mode is not None:
        options["render_mode"] = render_mode
    return gymnasium.make(env_id, **options)


def check_gym_env(env_id: str, kwargs: Mapping[str, Any]) -> None:
    """Build the environment once, reset it and take one step (zero action, clipped into the box): it must accept
    ``kwargs`` and have flat ``Box`` observations and ``Box`` actions (what SB3's MLP policy and the TorchScript
    export of its deterministic actor handle). The step catches options that constructors keep unchecked.

    Raises:
        ValueError: the environment rejects the options, or its spaces are not supported.
    """
    try:
        env = make_gym_env(env_id, kwargs)
    except Exception as exc:  # a constructor fails on a bad option in any way (e.g. a mapping for an object)
        raise ValueError(f"{env_id} rejects the options {dict(kwargs)} ({type(exc).__name__}: {exc})") from exc
    try:
        obs_space, act_space = env.observation_space, env.action_space
        if not (isinstance(obs_space, spaces.Box) and len(obs_space.shape) == 1):
            raise ValueError(f"{env_id}: training needs a flat Box observation space, it has {obs_space}")
        if not isinstance(act_space, spaces.Box) or len(act_space.shape) != 1:
            raise ValueError(f"{env_id}: training needs a flat Box (continuous) action space, it has {act_space}")
        action = np.clip(np.zeros(act_space.shape), act_space.low, act_space.high).astype(act_space.dtype)
        try:
            env.reset(seed=0)
            env.step(action)
        except Exception as exc:  # an option only used while stepping (e.g. a mapping where an object is needed)
            raise ValueError(
                f"{env_id} fails to reset or step with the options {dict(kwargs)} ({type(exc).__name__}: {exc})"
            ) from exc
    finally:
        env.close()


# ---------------------------------------------------------------------------------------------------------------------
# the interface, chosen once per id
# ---------------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AnymalTarget:
    """A batched ANYmal environment: ``env_id`` and its :class:`EnvConfig`."""

    env_id: str
    config: EnvConfig

    is_anymal = True

    @property
    def margin_weight(self) -> float:
        """Weight of the margin reward term."""
        return self.config.margin_weight

    def check(self) -> None:
        """Fail early when the environment cannot be built as asked (:func:`check_margin_available`)."""
        check_margin_available(self.config)

    def to_json(self) -> dict[str, Any]:
        """``{"env_config": ...}``, as ``config.json`` and evaluation reports hold it."""
        return {"env_config": to_dict(self.config)}


@dataclass(frozen=True)
class GymTarget:
    """Any other registered Gymnasium id: ``env_id`` and the keywords of ``gymnasium.make`` (checked JSON)."""

    env_id: str
    kwargs: dict[str, Any] = field(default_factory=dict, hash=False)

    is_anymal = False

    @property
    def margin_weight(self) -> float | None:
        """The environment's ``margin_weight`` keyword, or None when it has none."""
        return margin_weight_of(self.env_id, self.kwargs)

    def check(self) -> None:
        """Fail early when the environment cannot be built as asked (:func:`check_gym_env`)."""
        check_gym_env(self.env_id, self.kwargs)

    def to_json(self) -> dict[str, Any]:
        """``{"env_kwargs": ...}``, as ``config.json`` and evaluation reports hold it."""
        return {"env_kwargs": dict(self.kwargs)}


EnvTarget = AnymalTarget | GymTarget
"""The environment of a run or an evaluation: batched ANYmal or generic Gymnasium."""


def env_target(env_id: str, overrides: Mapping[str, Any] | None = None) -> EnvTarget:
    """The environment of ``env_id`` with option ``overrides``: EnvConfig fields (ANYmal ids) or constructor
    keywords (other ids), checked by name and type.

    Raises:
        ValueError: unknown id. TypeError: unknown option names or badly typed values.
    """
    if is_batched_anymal(env_id):
        env_id = current_env_id(env_id)  # a new run records the current id
        return AnymalTarget(env_id, env_config_for(env_id, dict(overrides or {})))
    return GymTarget(env_id, env_kwargs_for(env_id, overrides))


def anymal_config(env_id: str, options: Mapping[str, Any], caller: str, instead: str) -> EnvConfig:
    """The checked :class:`EnvConfig` of a batched ANYmal id for the vector-environment factories.

    ``caller`` names the factory and ``instead`` what to use for the other ids, in the error messages.

    Raises:
        ValueError: ``env_id`` is unknown or not a batched ANYmal id; the learned margin's weights are missing.
        TypeError: an option that is not an EnvConfig field (the message lists the fields), or a bad value.
    """
    if not is_batched_anymal(env_id):
        anymal = [i for i in margin_rl_ids() if is_batched_anymal(i)]
        raise ValueError(f"{caller} builds the batched margin_rl ANYmal ids ({', '.join(anymal)}); {env_id!r} "
                         f"is not one of them: {instead}")  # fmt: skip
    fields = sorted(f.name for f in dataclasses.fields(EnvConfig))
    unknown = sorted(set(options) - set(fields))
    if unknown:
        raise TypeError(f"{caller}: unknown environment option(s) {unknown} for {env_id}; the options are the "
                        f"EnvConfig fields: {', '.join(fields)}{EnvConfig.unknown_field_hint(unknown)}")  # fmt: skip
    config = env_config_for(env_id, dict(options))
    check_margin_available(config)
    return config
