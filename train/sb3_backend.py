"""PPO through Stable-Baselines3, with atomic checkpoints, exact resume, stop at a rollout boundary.

PPO itself is SB3's, on any SB3 ``VecEnv`` that also reports episode metrics
(:class:`margin_rl.train.adapters.EpisodeMetricsSource`): :class:`~margin_rl.train.adapters.Sb3VecEnv` over the
ANYmal core, or :class:`~margin_rl.train.adapters.Sb3GymVecEnv` over Gymnasium environments (generic path).
:class:`TrainingCallback` logs those metrics (for ANYmal the same TensorBoard tags as the rsl-rl backend; for a
generic environment ``Episode_Metrics/return``, ``/length``, the means of its numeric ``info`` values and
``Episode_Reward/<term>`` for its ``info["reward_<term>"]``), throughput, drives the progress bar, writes
``<run>/checkpoints/ckpt_<steps>.zip`` every ``checkpoint_every`` steps at the start of a rollout (after the
previous update, a consistent state) and, when a stop is requested, writes one there and ends ``learn`` before
any new data is collected.

Resume: ``PPO.load`` restores the policy, optimizer and ``num_timesteps``; ``learn(reset_num_timesteps=False)``
continues the step count, and the TensorBoard logger appends to the same folder. SB3 does not save its random
generators, and episodes running at the stop are lost (the environments start fresh).

The TorchScript export is the deterministic actor: the Gaussian mean clipped to the action box, as SB3's
``predict(deterministic=True)`` returns it.
"""

from __future__ import annotations

import copy
import io
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecEnv

from margin_rl.atomic import atomic_write
from margin_rl.train.adapters import EpisodeMetricsSource
from margin_rl.train.config import Sb3PPOConfig
from margin_rl.train.metrics import tensorboard_tags
from margin_rl.train.runs import (
    TENSORBOARD_DIR,
    TORCHSCRIPT_FILE,
    RunHooks,
    checkpoint_path,
    torchscript_export,
)

LOG = logging.getLogger("margin_rl.train")

UNPICKLE_WARNING = (
    "{path}: Stable-Baselines3 .zip files are loaded with pickle (which can run arbitrary code); "
    "only load policies from a source you trust"
)


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

    def __init__(self, venv: EpisodeMetricsSource, run_dir: Path, checkpoint_every: int, hooks: RunHooks) -> None:
        super().__init__(verbose=0)
        self.venv, self.run_dir, self.every, self.hooks = venv, run_dir, max(1, int(checkpoint_every)), hooks
        self.stopped = False
        self.last_saved = -1
        self._next = 0
        self._clock = time.perf_counter()
        self._clock_steps = 0
        self._collect_start = self._clock
        self._recent: float | None = None

    def _on_training_start(self) -> None:
        steps = self.model.num_timesteps
        self.last_saved = steps
        self._next = (steps // self.every + 1) * self.every
        self._clock, self._clock_steps = time.perf_counter(), steps

    def save_checkpoint(self) -> Path:
        """Write ``ckpt_<num_timesteps>.zip`` (the state after the last update)."""
        steps = int(self.model.num_timesteps)
        path = save_model(self.model, checkpoint_path(self.run_dir, steps, "sb3"))
        self.last_saved = steps
        self.hooks.checkpointed(path, steps)
        return path

    def _on_rollout_start(self) -> None:
        steps = self.model.num_timesteps
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


def make_model(venv: VecEnv, ppo: Sb3PPOConfig, seed: int, device: str) -> PPO:
    """A new SB3 PPO on the vector environment."""
    return PPO("MlpPolicy", venv, seed=seed, device=device, verbose=0, **ppo.ppo_kwargs(venv.num_envs))


class _DeterministicActor(torch.nn.Module):
    """SB3 MlpPolicy's deterministic action (the Gaussian mean, clipped to the action box) for TorchScript.

    The bounds are those of the model's ``Box`` action space ([-1, 1] for ANYmal), as in SB3's ``predict``.
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
    """Trace the deterministic actor into a TorchScript file (input: (N, obs) float32; output: (N, actions)).

    Raises:
        ValueError: the model's action space is not a ``Box`` (no Gaussian mean to export).
    """
    if not isinstance(model.action_space, spaces.Box):
        raise ValueError(f"TorchScript export needs a Box action space, the model has {model.action_space}")
    actor = _DeterministicActor(model.policy, model.action_space).eval()
    example = torch.zeros(1, int(model.observation_space.shape[0]))
    buffer = io.BytesIO()
    with torch.no_grad(), torchscript_export():
        traced = torch.jit.trace(actor, example)
        torch.jit.save(traced, buffer)
    data = buffer.getvalue()
    return atomic_write(path, lambda f: f.write(data))


def train_sb3(
    venv: VecEnv,
    ppo: Sb3PPOConfig,
    run_dir: Path,
    seed: int,
    device: str,
    total_steps: int,
    checkpoint_every: int,
    checkpoint: Path | None,
    hooks: RunHooks,
    final_model: Path,
) -> tuple[int, bool, Path | None]:
    """Run (or continue) SB3 PPO up to ``total_steps``; returns (env steps, stopped, TorchScript path).

    ``venv`` must also be an :class:`~margin_rl.train.adapters.EpisodeMetricsSource` (read by the callback).
    """
    if checkpoint is not None:
        warn_unpickling(checkpoint)
        model = PPO.load(checkpoint, env=venv, device=device)
    else:
        model = make_model(venv, ppo, seed, device)
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
