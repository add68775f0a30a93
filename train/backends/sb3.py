"""Stable-Baselines3: the ``VecEnv`` adapter and PPO training, with atomic checkpoints, exact resume, stop at a
rollout boundary.

:class:`Sb3VecEnv` is a ``VecEnv`` over the batched ANYmal core :class:`margin_rl.envs.core.AnymalCore` (numpy
observations, ``dones``, a list of info dicts with ``terminal_observation``, ``TimeLimit.truncated``, ``episode``
= {r, l, t} and ``episode_metrics`` on the step that ends an episode; same-step autoreset, as SB3 expects),
recording :class:`~margin_rl.train.metrics.EpisodeStatistics`; :func:`sb3_vec_env` builds one for an
:class:`~margin_rl.train.environments.AnymalTarget`, :func:`make_sb3_env` from a registered id for plain SB3 use.

PPO itself is SB3's; :class:`TrainingCallback` logs those metrics (the same TensorBoard tags as the rsl-rl
backend), throughput, drives the progress bar, writes ``<run>/checkpoints/ckpt_<steps>.zip`` every
``checkpoint_every`` steps at the start of a rollout (after the previous update, a consistent state) and, when a
stop is requested, writes one there and ends ``learn`` before any new data is collected.

Warm start (``init_from``): a new model begins with the policy weights of a trained one of the same shapes (its
optimizer, step count and schedules are the new run's).

Resume: ``PPO.load`` restores the policy, optimizer and ``num_timesteps``; ``learn(reset_num_timesteps=False)``
continues the step count, and the TensorBoard logger appends to the same folder; on a terrain curriculum each
environment's row travels in the checkpoint (``ThreadedPPO.curriculum_levels``). SB3 does not save its random
generators, and episodes running at the stop are lost (the environments start fresh, on their rows).

The TorchScript export is the deterministic actor: the Gaussian mean clipped to the action box, as SB3's
``predict(deterministic=True)`` returns it.
"""

from __future__ import annotations

import copy
import io
import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.vec_env import VecEnv

from margin_rl.arrays import to_numpy
from margin_rl.atomic import atomic_write
from margin_rl.envs.core import ACTION_BOUND, AnymalCore
from margin_rl.train.config import Sb3PPOConfig
from margin_rl.train.environments import (
    ACTION_SIZE,
    AnymalTarget,
    anymal_config,
    make_core,
    observation_size,
)
from margin_rl.train.exploration import ExplorationMonitor
from margin_rl.train.metrics import EpisodeStatistics, split_episodes, step_tags, tensorboard_tags
from margin_rl.train.runs import (
    TENSORBOARD_DIR,
    TORCHSCRIPT_FILE,
    RunHooks,
    checkpoint_path,
    torch_threads,
    torchscript_export,
)

LOG = logging.getLogger("margin_rl.train")

UNPICKLE_WARNING = (
    "{path}: Stable-Baselines3 .zip files are loaded with pickle (which can run arbitrary code); "
    "only load policies from a source you trust"
)


class Sb3VecEnv(VecEnv):
    """Stable-Baselines3 ``VecEnv`` over an :class:`AnymalCore` (see the module docstring)."""

    def __init__(self, core: AnymalCore) -> None:
        self.core = core
        self.render_mode: str | None = None  # read by VecEnv.__init__ through get_attr
        obs_space = spaces.Box(-np.inf, np.inf, (observation_size(core),), np.float32)
        act_space = spaces.Box(-ACTION_BOUND, ACTION_BOUND, (ACTION_SIZE,), np.float32)
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
        return to_numpy(self.core.observe_all())

    def curriculum_levels(self) -> list[int] | None:
        """The terrain curriculum's row of each environment; None without a curriculum."""
        if not self.core.terrain.levels:
            return None
        return [int(level) for level in to_numpy(self.core.terrain_level)]

    def step_summary(self) -> dict[str, float]:
        """Per-step statistics of the last step (:func:`margin_rl.train.metrics.step_tags`); empty before it."""
        return step_tags(self.last_info) if self.last_info else {}

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        out = self.core.step(self._actions).to_numpy()
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


def sb3_vec_env(
    target: AnymalTarget,
    num_envs: int,
    seed: int | None,
    physics: str = "mujoco",
    physics_device: str | None = None,
    physics_options: dict[str, Any] | None = None,
) -> Sb3VecEnv:
    """The training ``VecEnv`` of an environment target: :class:`Sb3VecEnv` over the batched core (on backend
    ``physics`` at ``physics_device`` with ``physics_options``)."""
    return Sb3VecEnv(make_core(target.config, num_envs, seed, physics, physics_device, physics_options))


def make_sb3_env(
    env_id: str,
    num_envs: int,
    seed: int | None = None,
    physics: str = "mujoco",
    physics_device: str | None = None,
    physics_options: dict[str, Any] | None = None,
    **env_options: Any,
) -> Sb3VecEnv:
    """A Stable-Baselines3 ``VecEnv`` of ``num_envs`` environments of a margin_rl ANYmal id, over the native
    batched simulation (much faster than SB3's ``DummyVecEnv`` of single environments).

    ``env_options``: any :class:`~margin_rl.envs.config.EnvConfig` field (e.g. ``margin_weight=0.2``,
    ``reward_params={"alive_bonus": 0.1}``, ``margin="analytic"``); ``seed`` seeds the initial states; ``physics``,
    ``physics_device`` and ``physics_options``: the simulator (see :func:`~margin_rl.train.backends.rsl.make_rsl_env`).
    Example::

        from stable_baselines3 import PPO
        from margin_rl.train import make_sb3_env

        env = make_sb3_env(
            "margin_rl/AnymalB-v1", num_envs=64, seed=0, margin_weight=0.2, reward_params={"alive_bonus": 0.1}
        )
        PPO("MlpPolicy", env, n_steps=24).learn(100_000)

    Raises:
        ValueError: ``env_id`` is not a batched margin_rl ANYmal id (other Gymnasium environments: plain SB3, see
            ``examples/train_slip_hopper.py``); the learned margin's weights cannot be loaded.
        TypeError: an option that is not an EnvConfig field, or a badly typed value.
    """
    config = anymal_config(env_id, env_options, "make_sb3_env")
    return Sb3VecEnv(make_core(config, num_envs, seed, physics, physics_device, physics_options))


def warn_unpickling(path: str | Path) -> None:
    """Log that an SB3 zip is about to be unpickled."""
    LOG.warning(UNPICKLE_WARNING.format(path=path))


def save_model(model: PPO, path: Path) -> Path:
    """``model.save`` into ``path`` atomically."""
    buffer = io.BytesIO()
    model.save(buffer)
    data = buffer.getvalue()
    return atomic_write(path, lambda f: f.write(data))


class TrainingCallback(BaseCallback):
    """Metrics, progress, checkpoints and stop requests for SB3's PPO (see the module docstring)."""

    def __init__(self, venv: Sb3VecEnv, run_dir: Path, checkpoint_every: int, hooks: RunHooks) -> None:
        super().__init__(verbose=0)
        self.venv, self.run_dir, self.every, self.hooks = venv, run_dir, max(1, int(checkpoint_every)), hooks
        self.stopped = False
        self.last_saved = -1
        self._next = 0
        self._clock = time.perf_counter()
        self._clock_steps = 0
        self._collect_start = self._clock
        self._recent: float | None = None
        self.exploration = ExplorationMonitor()

    def _on_training_start(self) -> None:
        steps = self.model.num_timesteps
        self.last_saved = steps
        self._next = (steps // self.every + 1) * self.every
        self._clock, self._clock_steps = time.perf_counter(), steps

    def save_checkpoint(self) -> Path:
        """Write ``ckpt_<num_timesteps>.zip`` (the state after the last update)."""
        steps = int(self.model.num_timesteps)
        self.model.curriculum_levels = self.venv.curriculum_levels()
        path = save_model(self.model, checkpoint_path(self.run_dir, steps, "sb3"))
        self.last_saved = steps
        self.hooks.checkpointed(path, steps)
        return path

    def _on_rollout_start(self) -> None:
        steps = self.model.num_timesteps
        log_std = getattr(self.model.policy, "log_std", None)  # the Gaussian policy's state-independent log std
        if log_std is not None:
            self.exploration.update(float(log_std.detach().exp().mean()), steps)
        stop = self.hooks.stop_requested()
        if steps > self.last_saved and (steps >= self._next or stop):
            self.save_checkpoint()
            self._next = (steps // self.every + 1) * self.every
        self.stopped = stop
        self._collect_start = time.perf_counter()

    def _on_step(self) -> bool:
        if self.stopped:  # checkpoint written at the rollout start; this step is not trained on
            return False
        logger = self.logger
        for tag, value in self.venv.step_summary().items():
            logger.record_mean(tag, value)
        for tag, values in tensorboard_tags(self.venv.stats_finished).items():
            for value in values[np.isfinite(values)]:
                logger.record_mean(tag, float(value))
        if self.venv.stats_finished:
            self._recent = float(np.mean(self.venv.stats_finished["return"]))
        self.hooks.progress(int(self.model.num_timesteps), self._recent)
        return True

    def _on_rollout_end(self) -> None:
        now = time.perf_counter()
        steps = self.model.num_timesteps
        if now > self._clock and steps > self._clock_steps:
            self.logger.record("Perf/total_fps", (steps - self._clock_steps) / (now - self._clock))
            self.logger.record("Perf/collection_time", now - self._collect_start)
        self._clock, self._clock_steps = now, steps


class ThreadedPPO(PPO):
    """SB3's PPO with its update (``train``) run on ``update_threads`` torch threads (:func:`torch_threads`; None:
    the caller's setting), collection on the caller's. The saved zip is an ordinary PPO's (``PPO.load`` reads it);
    the thread count is a setting of this process, not saved. ``curriculum_levels`` (each environment's terrain
    curriculum row when a checkpoint was written; None without a curriculum) is saved with it for the resume."""

    update_threads: int | None = None
    curriculum_levels: list[int] | None = None

    def train(self) -> None:
        with torch_threads(self.update_threads):
            super().train()

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "update_threads"]


def make_model(venv: VecEnv, ppo: Sb3PPOConfig, seed: int, device: str) -> ThreadedPPO:
    """A new SB3 PPO on the vector environment."""
    return ThreadedPPO("MlpPolicy", venv, seed=seed, device=device, verbose=0, **ppo.ppo_kwargs(venv.num_envs))


class _DeterministicActor(torch.nn.Module):
    """SB3 MlpPolicy's deterministic action (the Gaussian mean, clipped to the action box) for TorchScript.

    The bounds are those of the model's ``Box`` action space ([-1, 1]), as in SB3's ``predict``.
    """

    def __init__(self, policy: Any, action_space: Any) -> None:
        super().__init__()
        self.features = copy.deepcopy(policy.pi_features_extractor).cpu()
        self.latent = copy.deepcopy(policy.mlp_extractor.policy_net).cpu()
        self.action_net = copy.deepcopy(policy.action_net).cpu()
        self.register_buffer("low", torch.as_tensor(action_space.low, dtype=torch.float32))
        self.register_buffer("high", torch.as_tensor(action_space.high, dtype=torch.float32))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.clamp(self.action_net(self.latent(self.features(obs))), self.low, self.high)


def export_torchscript(model: PPO, path: Path) -> Path:
    """Trace the deterministic actor into a TorchScript file (input: (N, obs) float32; output: (N, actions))."""
    actor = _DeterministicActor(model.policy, model.action_space).eval()
    example = torch.zeros(1, int(model.observation_space.shape[0]))
    buffer = io.BytesIO()
    with torch.no_grad(), torchscript_export():
        traced = torch.jit.trace(actor, example)
        torch.jit.save(traced, buffer)
    data = buffer.getvalue()
    return atomic_write(path, lambda f: f.write(data))


def warm_start(model: PPO, path: Path) -> None:
    """Give a new model the policy weights (actor, critic, log std) of a trained SB3 model of the same shapes.

    Only the policy's parameters are taken: the new model keeps its own optimizer, step count and schedules.

    Raises:
        ValueError: the file's observation or action space, or its network shapes, differ from the model's.
    """
    warn_unpickling(path)
    data, params, _ = load_from_zip_file(path, device=model.device)
    for name in ("observation_space", "action_space"):
        theirs, ours = (data or {}).get(name), getattr(model, name)
        if theirs is not None and getattr(theirs, "shape", None) != ours.shape:
            raise ValueError(
                f"--init-from {path}: its {name} has shape {theirs.shape}, this run's environment {ours.shape}; "
                "start from a model trained on the same robot and observation layout"
            )
    if not params or "policy" not in params:
        raise ValueError(f"--init-from {path}: no policy weights in it (not a Stable-Baselines3 model?)")
    try:
        model.policy.load_state_dict(params["policy"], strict=True)
    except RuntimeError as exc:  # the message lists the mismatched tensors
        raise ValueError(
            f"--init-from {path}: its networks differ from this run's (net_arch, activation): {exc}"
        ) from exc


def train_sb3(
    venv: Sb3VecEnv,
    ppo: Sb3PPOConfig,
    run_dir: Path,
    seed: int,
    device: str,
    total_steps: int,
    checkpoint_every: int,
    checkpoint: Path | None,
    hooks: RunHooks,
    final_model: Path,
    init_from: str | Path | None = None,
    update_threads: int | None = None,
) -> tuple[int, bool, Path | None]:
    """Run (or continue) SB3 PPO up to ``total_steps``; returns (env steps, stopped, TorchScript path).

    ``init_from``: a trained SB3 model whose weights a new run starts from (:func:`warm_start`); ignored when
    continuing a checkpoint. ``update_threads``: torch threads inside PPO's update (:class:`ThreadedPPO`).
    """
    if checkpoint is not None:
        warn_unpickling(checkpoint)
        model = ThreadedPPO.load(checkpoint, env=venv, device=device)
        if model.curriculum_levels is not None:  # learn's first reset keeps the rows (no episode has run)
            venv.core.restart_on_levels(model.curriculum_levels)
    else:
        model = make_model(venv, ppo, seed, device)
        if init_from is not None:
            warm_start(model, Path(init_from))
    model.update_threads = update_threads
    formats = ["tensorboard", "stdout"] if hooks.verbose else ["tensorboard"]
    model.set_logger(configure(str(run_dir / TENSORBOARD_DIR), formats))
    callback = TrainingCallback(venv, run_dir, checkpoint_every, hooks)
    remaining = total_steps - int(model.num_timesteps)
    try:
        if remaining > 0:
            model.learn(remaining, callback=callback, reset_num_timesteps=False, progress_bar=False)
    finally:
        model.logger.close()
    if callback.stopped:
        return int(callback.last_saved), True, None
    if int(model.num_timesteps) != callback.last_saved:
        callback.model = model
        callback.save_checkpoint()
    save_model(model, final_model)
    return int(model.num_timesteps), False, export_torchscript(model, run_dir / TORCHSCRIPT_FILE)
