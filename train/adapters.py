"""Thin learner adapters over the environments: the batched ANYmal core, or any registered Gymnasium id.

ANYmal ids (registered with the batched ``vector_entry_point`` :data:`VECTOR_ENTRY_POINT`) run on the one batched
simulation, :class:`margin_rl.envs.core.AnymalCore`:

* :class:`Sb3VecEnv`: a Stable-Baselines3 ``VecEnv`` (numpy observations, ``dones``, a list of info dicts
  with ``terminal_observation``, ``TimeLimit.truncated``, ``episode`` = {r, l, t} and ``episode_metrics``
  on the step that ends an episode). Same-step autoreset, as SB3 expects.
* :class:`RslVecEnv`: an rsl-rl 5.x ``VecEnv`` (``TensorDict`` observation groups ``"policy"`` and, when the
  environment has privileged observations, ``"critic"``; ``num_envs``, ``num_actions``,
  ``max_episode_length``, a writable ``episode_length_buf`` shared with the core, ``device``, ``cfg``;
  ``step`` returns ``(obs, rewards, dones, extras)`` with ``extras["time_outs"]`` and ``extras["log"]``).

Both record per-episode metrics with :class:`margin_rl.train.metrics.EpisodeStatistics`, so the two
backends log the same TensorBoard tags (:func:`margin_rl.train.metrics.tensorboard_tags`).

Every other registered id (e.g. ``margin_rl/SLIPHopper-v0``) takes the generic path, SB3 only:
:func:`make_gym_vec_env` builds SB3's ``DummyVecEnv`` of ``gymnasium.make(id, **env_kwargs)`` environments,
each wrapped in SB3's ``Monitor`` and seeded ``seed + index`` at the first reset, inside :class:`Sb3GymVecEnv`,
which records :class:`InfoEpisodeStatistics` (return, length, ``reward/<term>`` sums of the
``info["reward_<term>"]`` the environment reports, means of its other numeric ``info`` values). Environment
keywords are checked against the constructor's (:func:`env_kwargs_for`) and must be JSON, since the run's
``config.json`` stores them for ``--resume`` and ``evaluate``. The generic path trains continuous control:
flat ``Box`` observations and ``Box`` actions (:func:`check_gym_env`).
"""

from __future__ import annotations

import functools
import inspect
import json
import math
import os
import time
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import gymnasium
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv as _Sb3VecEnvBase
from stable_baselines3.common.vec_env import VecEnvWrapper

from margin_rl.envs.anymal import make_config
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.train.config import apply_overrides, to_dict
from margin_rl.train.metrics import EpisodeStatistics, split_episodes, step_tags, tensorboard_tags

os.environ.setdefault("GIT_PYTHON_REFRESH", "quiet")  # rsl_rl imports GitPython, which needs this without git

import torch
from rsl_rl.env import VecEnv as _RslVecEnvBase
from tensordict import TensorDict

ACTION_SIZE = 12
VECTOR_ENTRY_POINT = "margin_rl.envs.vector:AnymalVectorEnv"
NAMESPACE = "margin_rl/"
MARGIN_WEIGHT_KEYWORD = "margin_weight"
"""Keyword of an environment's margin-reward weight: ``--margin-weight`` sets it where the constructor takes it."""
MAKE_KEYWORDS: tuple[str, ...] = ("max_episode_steps",)
"""``gymnasium.make`` keywords accepted as environment options besides the constructor's (episode length)."""
RESERVED_KEYWORDS: tuple[str, ...] = ("render_mode",)
"""Constructor keywords that training and evaluation set themselves."""
SB3_INFO_KEYS: frozenset[str] = frozenset({"episode", "terminal_observation", "TimeLimit.truncated"})
"""``info`` keys added by SB3's ``Monitor`` and ``DummyVecEnv``, not by the environment."""
GENERIC_STEP_LIMIT = 100_000
"""Steps after which an evaluation episode of an environment without a time limit is cut."""


# ---------------------------------------------------------------------------------------------------------------------
# registered ids
# ---------------------------------------------------------------------------------------------------------------------
def margin_rl_ids() -> list[str]:
    """Every registered ``margin_rl/`` id, sorted."""
    import margin_rl  # noqa: F401  (registers the ids)

    return sorted(k for k in gymnasium.registry if k.startswith(NAMESPACE))


def registered_spec(env_id: str) -> gymnasium.envs.registration.EnvSpec:
    """Gymnasium's registration of ``env_id``.

    Raises:
        ValueError: the id is not registered (the message lists the margin_rl ids).
    """
    import margin_rl  # noqa: F401  (registers the ids)

    try:
        return gymnasium.spec(env_id)
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
# building the core from a registered id
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
        ValueError: (``margin_rl.stability.learned.WeightsError``) missing, corrupted or mismatched weights.
    """
    if config.margin != "learned":
        return
    from margin_rl.stability.learned import LearnedMargin, WeightsError

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
# Stable-Baselines3
# ---------------------------------------------------------------------------------------------------------------------
class EpisodeMetricsSource(Protocol):
    """What :class:`margin_rl.train.sb3_backend.TrainingCallback` reads from the SB3 ``VecEnv`` after each step."""

    num_envs: int
    stats_finished: dict[str, np.ndarray]  # metrics of the episodes that ended at the last step (arrays, "env")

    def step_summary(self) -> dict[str, float]:
        """TensorBoard tag -> value of per-step statistics over the batch of the last step."""
        ...


class Sb3VecEnv(_Sb3VecEnvBase):
    """Stable-Baselines3 ``VecEnv`` over an :class:`AnymalCore` (see the module docstring)."""

    def __init__(self, core: AnymalCore) -> None:
        self.core = core
        self.render_mode: str | None = None  # read by VecEnv.__init__ through get_attr
        obs_space = spaces.Box(-np.inf, np.inf, (observation_size(core),), np.float32)
        act_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), np.float32)
        self.stats = EpisodeStatistics(core.num_envs, core.dt)
        self.last_info: dict[str, np.ndarray] = {}
        self.stats_finished: dict[str, np.ndarray] = {}  # metrics of the episodes that ended at the last step
        self._actions: np.ndarray | None = None
        self._t0 = time.time()
        super().__init__(core.num_envs, obs_space, act_space)

    @property
    def dt(self) -> float:
        """Policy step [s]."""
        return self.core.dt

    def reset(self) -> np.ndarray:
        """Reset every environment; a seed set with :meth:`seed` reseeds the core's generator first."""
        seed = self._seeds[0]
        self._reset_seeds()
        self._reset_options()
        self.core.reset(seed=seed)
        self.stats.reset()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return self.core.observe_all()

    def step_summary(self) -> dict[str, float]:
        """Per-step statistics of the last step (:func:`margin_rl.train.metrics.step_tags`); empty before it."""
        return step_tags(self.last_info) if self.last_info else {}

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        out = self.core.step(self._actions)
        self._actions = None
        self.last_info = out.info
        done = out.terminated | out.truncated
        finished = self.stats.update(out.reward, out.info, out.terminated, out.truncated)
        self.stats_finished = finished
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        elapsed = round(time.time() - self._t0, 6)
        for episode in split_episodes(finished):
            i = int(episode.pop("env"))
            infos[i] = {
                "terminal_observation": out.final_observation[i],
                "TimeLimit.truncated": bool(out.truncated[i] and not out.terminated[i]),
                "episode": {"r": episode["return"], "l": int(episode["length"]), "t": elapsed},
                "episode_metrics": episode,
            }
        return out.observation, out.reward.astype(np.float32), done, infos

    def close(self) -> None:
        pass

    def _indices(self, indices: int | Sequence[int] | None) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

    def get_attr(self, attr_name: str, indices: int | Sequence[int] | None = None) -> list[Any]:
        """An attribute of the adapter (or, failing that, of the core), once per requested environment."""
        target = self if hasattr(self, attr_name) else self.core
        return [getattr(target, attr_name) for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: int | Sequence[int] | None = None) -> None:
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: int | Sequence[int] | None = None, **method_kwargs: Any
    ) -> list[Any]:
        method = getattr(self, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: int | Sequence[int] | None = None) -> list[bool]:
        return [False for _ in self._indices(indices)]


# ---------------------------------------------------------------------------------------------------------------------
# rsl-rl
# ---------------------------------------------------------------------------------------------------------------------
class RslVecEnv(_RslVecEnvBase):
    """rsl-rl 5.x ``VecEnv`` over an :class:`AnymalCore` (see the module docstring); reset on construction."""

    def __init__(self, core: AnymalCore, device: str | torch.device = "cpu") -> None:
        self.core = core
        self.num_envs = core.num_envs
        self.num_actions = ACTION_SIZE
        self.max_episode_length = int(core.max_episode_steps)
        self.device = torch.device(device)
        self.cfg: dict[str, Any] = to_dict(core.config)
        self.privileged = bool(core.config.privileged_observations)
        self.stats = EpisodeStatistics(core.num_envs, core.dt)
        self.core.reset()
        self._obs = self._observations(core.observe_all())

    @property
    def dt(self) -> float:
        """Policy step [s]."""
        return self.core.dt

    @property
    def episode_length_buf(self) -> torch.Tensor:
        """Steps taken in the current episodes (N,), int64: a view of the core's counter, which decides time-outs."""
        return torch.from_numpy(self.core.episode_step).to(self.device)

    @episode_length_buf.setter
    def episode_length_buf(self, value: torch.Tensor) -> None:
        steps = np.asarray(torch.as_tensor(value).detach().cpu().numpy(), dtype=np.int64).reshape(self.num_envs)
        self.core.episode_step[:] = steps

    def _observations(self, policy: np.ndarray) -> TensorDict:
        groups = {"policy": torch.from_numpy(np.ascontiguousarray(policy, dtype=np.float32))}
        if self.privileged:
            groups["critic"] = torch.from_numpy(self.core.privileged_observation().astype(np.float32))
        return TensorDict(groups, batch_size=[self.num_envs]).to(self.device)

    def get_observations(self) -> TensorDict:
        return self._obs

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict[str, Any]]:
        out = self.core.step(actions.detach().to("cpu", torch.float64).numpy())
        obs = {"policy": torch.from_numpy(out.observation)}
        if self.privileged and out.privileged is not None:
            obs["critic"] = torch.from_numpy(out.privileged.astype(np.float32))
        self._obs = TensorDict(obs, batch_size=[self.num_envs]).to(self.device)
        rewards = torch.as_tensor(out.reward, dtype=torch.float32, device=self.device)
        dones = torch.as_tensor(out.terminated | out.truncated, device=self.device)
        finished = self.stats.update(out.reward, out.info, out.terminated, out.truncated)
        log: dict[str, float | torch.Tensor] = dict(step_tags(out.info))
        for tag, values in tensorboard_tags(finished).items():
            finite = values[np.isfinite(values)]
            if finite.size:
                log[tag] = torch.as_tensor(finite, dtype=torch.float32)
        extras = {"time_outs": torch.as_tensor(out.truncated, device=self.device), "log": log}
        return self._obs, rewards, dones, extras


# ---------------------------------------------------------------------------------------------------------------------
# any other registered Gymnasium id (Stable-Baselines3 only)
# ---------------------------------------------------------------------------------------------------------------------
def env_keywords(env_id: str) -> tuple[str, ...] | None:
    """The keyword options of a registered id: its constructor's keywords (less :data:`RESERVED_KEYWORDS`) and
    :data:`MAKE_KEYWORDS`, sorted; None when the constructor takes ``**kwargs`` (any name is accepted).

    Raises:
        ValueError: the id is not registered.
    """
    spec = registered_spec(env_id)
    creator = spec.entry_point
    if isinstance(creator, str):
        creator = gymnasium.envs.registration.load_env_creator(creator)
    parameters = inspect.signature(creator).parameters.values()
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
    creator = spec.entry_point
    if isinstance(creator, str):
        creator = gymnasium.envs.registration.load_env_creator(creator)
    parameter = inspect.signature(creator).parameters.get(name)
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


def _numeric_scalars(info: Mapping[str, Any]) -> dict[str, float]:
    """The numeric scalar values of an environment's ``info`` (booleans as 0/1), less SB3's own keys."""
    found: dict[str, float] = {}
    for key, value in info.items():
        if key in SB3_INFO_KEYS:
            continue
        if isinstance(value, (bool, int, float, np.bool_, np.integer, np.floating)) or (
            isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "biuf"
        ):
            found[key] = float(value)
    return found


class InfoEpisodeStatistics:
    """Per-environment sums over the running episode of the reward and of the numeric scalars in ``info``.

    :meth:`update` returns, for the episodes that ended, arrays (in environment order, plus ``"env"``: their
    indices) of ``return`` (sum of the rewards), ``length`` (steps), ``reward/<term>`` (sum of
    ``info["reward_<term>"]``), ``<key>_mean`` (mean over the episode's steps of every other numeric scalar
    ``info[key]``, booleans as 0/1; NaN for an episode that never reported it), ``terminated`` and ``timed_out``
    (1 or 0). Names follow :mod:`margin_rl.train.metrics`, so :func:`~margin_rl.train.metrics.tensorboard_tags`
    gives their TensorBoard tags.
    """

    def __init__(self, num_envs: int) -> None:
        self.num_envs = int(num_envs)
        self._return = np.zeros(self.num_envs)
        self._length = np.zeros(self.num_envs, dtype=np.int64)
        self._sums: list[dict[str, float]] = [{} for _ in range(self.num_envs)]
        self._counts: list[dict[str, int]] = [{} for _ in range(self.num_envs)]

    def reset(self, ids: Sequence[int] | np.ndarray | None = None) -> None:
        """Start new episodes in environments ``ids`` (all if None)."""
        for i in range(self.num_envs) if ids is None else (int(k) for k in ids):
            self._return[i], self._length[i] = 0.0, 0
            self._sums[i], self._counts[i] = {}, {}

    def update(
        self,
        reward: np.ndarray,
        infos: Sequence[Mapping[str, Any]],
        terminated: np.ndarray,
        truncated: np.ndarray,
    ) -> dict[str, np.ndarray]:
        """Add one step of every environment; the metrics of the episodes that ended (empty when none did)."""
        self._return += np.asarray(reward, dtype=np.float64)
        self._length += 1
        for sums, counts, info in zip(self._sums, self._counts, infos, strict=True):
            for key, value in _numeric_scalars(info).items():
                sums[key] = sums.get(key, 0.0) + value
                counts[key] = counts.get(key, 0) + 1
        terminated, truncated = np.asarray(terminated, dtype=bool), np.asarray(truncated, dtype=bool)
        ids = np.flatnonzero(terminated | truncated)
        return self._finish(ids, terminated & ~truncated)

    def close(self, ids: Sequence[int] | np.ndarray) -> dict[str, np.ndarray]:
        """End the running episodes of ``ids`` without another step (counted as time-outs); their metrics."""
        return self._finish(np.asarray(ids, dtype=np.int64), np.zeros(self.num_envs, dtype=bool))

    def _episode(self, i: int, terminated: bool) -> dict[str, float]:
        metrics = {"return": float(self._return[i]), "length": float(self._length[i])}
        sums, counts = self._sums[i], self._counts[i]
        for key in sums:  # reward terms are summed like the return; other values averaged over the steps
            if key.startswith("reward_"):
                metrics[f"reward/{key.removeprefix('reward_')}"] = sums[key]
            else:
                metrics[f"{key}_mean"] = sums[key] / counts[key]
        metrics["terminated"] = float(terminated)
        metrics["timed_out"] = float(not terminated)
        return metrics

    def _finish(self, ids: np.ndarray, terminated: np.ndarray) -> dict[str, np.ndarray]:
        if ids.size == 0:
            return {}
        episodes = [self._episode(int(i), bool(terminated[i])) for i in ids]
        self.reset(ids)
        keys = list(dict.fromkeys(k for episode in episodes for k in episode))
        metrics = {"env": ids.copy()}
        for key in keys:
            metrics[key] = np.array([episode.get(key, math.nan) for episode in episodes])
        return metrics


class Sb3GymVecEnv(VecEnvWrapper):
    """SB3 ``VecEnv`` wrapper recording :class:`InfoEpisodeStatistics` over ``venv`` (SB3 ``Monitor``-wrapped
    Gymnasium environments, see :func:`make_gym_vec_env`); steps, observations and infos pass unchanged."""

    def __init__(self, venv: _Sb3VecEnvBase) -> None:
        super().__init__(venv)
        self.stats = InfoEpisodeStatistics(venv.num_envs)
        self.stats_finished: dict[str, np.ndarray] = {}

    def reset(self) -> np.ndarray:
        self.stats.reset()
        self.stats_finished = {}
        return self.venv.reset()

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, rewards, dones, infos = self.venv.step_wait()
        # SB3 marks time-limit ends (truncated and not terminated) in the info of the ending step
        truncated = np.array([bool(info.get("TimeLimit.truncated", False)) for info in infos])
        terminated = np.asarray(dones, dtype=bool) & ~truncated
        self.stats_finished = self.stats.update(rewards, infos, terminated, truncated)
        return obs, rewards, dones, infos

    def step_summary(self) -> dict[str, float]:
        """No per-step statistics: a generic environment's ``info`` has no known layout (episode metrics only)."""
        return {}


def make_gym_vec_env(env_id: str, kwargs: Mapping[str, Any], num_envs: int, seed: int | None) -> Sb3GymVecEnv:
    """``num_envs`` environments ``gymnasium.make(env_id, **kwargs)`` in SB3's ``DummyVecEnv``, each in a
    ``Monitor`` (episode returns for SB3's own ``rollout/`` logs), seeded ``seed + index`` at the first reset."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv

    make = functools.partial(make_gym_env, env_id, dict(kwargs))
    return Sb3GymVecEnv(make_vec_env(make, n_envs=num_envs, seed=seed, vec_env_cls=DummyVecEnv))
