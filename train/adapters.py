"""Thin learner adapters over the one batched simulation, :class:`margin_rl.envs.core.AnymalCore`.

* :class:`Sb3VecEnv`: a Stable-Baselines3 ``VecEnv`` (numpy observations, ``dones``, a list of info dicts
  with ``terminal_observation``, ``TimeLimit.truncated``, ``episode`` = {r, l, t} and ``episode_metrics``
  on the step that ends an episode). Same-step autoreset, as SB3 expects.
* :class:`RslVecEnv`: an rsl-rl 5.x ``VecEnv`` (``TensorDict`` observation groups ``"policy"`` and, when the
  environment has privileged observations, ``"critic"``; ``num_envs``, ``num_actions``,
  ``max_episode_length``, a writable ``episode_length_buf`` shared with the core, ``device``, ``cfg``;
  ``step`` returns ``(obs, rewards, dones, extras)`` with ``extras["time_outs"]`` and ``extras["log"]``).

Both record per-episode metrics with :class:`margin_rl.train.metrics.EpisodeStatistics`, so the two
backends log the same TensorBoard tags (:func:`margin_rl.train.metrics.tensorboard_tags`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv as _Sb3VecEnvBase

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


# ---------------------------------------------------------------------------------------------------------------------
# building the core from a registered id
# ---------------------------------------------------------------------------------------------------------------------
def env_config_for(env_id: str, overrides: dict[str, Any] | None = None) -> EnvConfig:
    """The :class:`EnvConfig` of a registered margin_rl id with keyword overrides (EnvConfig fields).

    Raises:
        ValueError: the id is not registered, or is not a margin_rl ANYmal environment.
    """
    import margin_rl  # noqa: F401  (registers the ids)

    try:
        spec = gymnasium.spec(env_id)
    except gymnasium.error.Error as exc:
        known = sorted(k for k, s in gymnasium.registry.items() if s.vector_entry_point == VECTOR_ENTRY_POINT)
        raise ValueError(f"unknown environment id {env_id!r}; margin_rl ids: {', '.join(known)}") from exc
    if spec.vector_entry_point != VECTOR_ENTRY_POINT:
        raise ValueError(
            f"{env_id!r} is not a margin_rl ANYmal environment (its vector entry point is not "
            f"{VECTOR_ENTRY_POINT}); training runs on the batched ANYmal core only"
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
