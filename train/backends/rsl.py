"""rsl-rl (rsl-rl-lib 5.x): the ``VecEnv`` adapter and PPO through ``OnPolicyRunner``, with atomic checkpoints,
exact resume and stop.

:class:`RslVecEnv` is an rsl-rl ``VecEnv`` over the batched ANYmal core :class:`margin_rl.envs.core.AnymalCore`
(``TensorDict`` observation groups ``"policy"`` and, when the environment has privileged observations,
``"critic"``; ``num_envs``, ``num_actions``, ``max_episode_length``, a writable ``episode_length_buf`` shared with
the core, ``device``, ``cfg``; ``step`` returns ``(obs, rewards, dones, extras)`` with ``extras["time_outs"]``
and ``extras["log"]``: the TensorBoard tags of :class:`~margin_rl.train.metrics.EpisodeStatistics`, the same as
the SB3 backend's, summed where the core computes and read once per rollout, on its last step:
:meth:`RslVecEnv.set_rollout_length`). :func:`make_rsl_env` builds one from a registered id.

PPO itself is rsl-rl's. :class:`CheckpointingRunner` only changes where and how checkpoints are written
(``<run>/checkpoints/ckpt_<steps>.pt`` via a temporary file, with the training config, the progress and the
random-number states inside), and hooks the runner's per-iteration logger call to advance the progress bar
and to stop at an iteration boundary when a stop is requested (SIGINT/SIGTERM). It also follows the policy's
mean action std (:class:`~margin_rl.train.exploration.ExplorationMonitor`: a warning on stderr the first time it
would clip more than half of the sampled actions) and records its last value in every checkpoint
(``infos["action_std"]``).

Warm start (``init_from``): a new run begins with the actor and critic (with their normalisers) of a trained model
of the same sizes; everything else is the new run's.

Resume: the checkpoint restores actor, critic (with their observation normalisers), optimizer and learning
rate (the adaptive schedule's), the iteration counter (the next iteration is numbered after the last completed
one, so TensorBoard's x axis continues), the torch/numpy generators and, on a terrain curriculum, each
environment's row. Episodes running at the stop are lost: the environments start fresh, on their rows.
"""

from __future__ import annotations

import copy
import os
import shutil
import statistics
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner  # needs GIT_PYTHON_REFRESH without git: set in margin_rl.train
from tensordict import TensorDict

from margin_rl.arrays import generator_state, like, set_generator_state, to_numpy
from margin_rl.atomic import atomic_write
from margin_rl.envs.core import AnymalCore
from margin_rl.train.config import to_dict
from margin_rl.train.environments import ACTION_SIZE, AnymalTarget, anymal_config, make_core
from margin_rl.train.exploration import ExplorationMonitor
from margin_rl.train.metrics import EpisodeStatistics, step_statistics, tensorboard_tags
from margin_rl.train.runs import (
    TENSORBOARD_DIR,
    TORCHSCRIPT_FILE,
    RunHooks,
    checkpoint_path,
    quiet_stdout,
    torchscript_export,
    with_torch_threads,
)

CHECKPOINT_FORMAT = "margin_rl/rsl-checkpoint-1"


class RslVecEnv(VecEnv):
    """rsl-rl 5.x ``VecEnv`` over an :class:`AnymalCore` (see the module docstring); reset on construction."""

    def __init__(self, core: AnymalCore, device: str | torch.device = "cpu") -> None:
        self.core = core
        self.num_envs = core.num_envs
        self.num_actions = ACTION_SIZE
        self.max_episode_length = int(core.max_episode_steps)
        self.device = torch.device(device)
        self.cfg: dict[str, Any] = to_dict(core.config)
        self.privileged = bool(core.config.privileged_observations)
        self.stats = EpisodeStatistics(core.num_envs, core.dt, reference=core.episode_step)  # sums where the core is
        self.log_every = 1
        """Steps between two reads of the episode and step statistics (and of the core's checks): 1, or the
        learner's rollout length (:meth:`set_rollout_length`)."""
        self._steps_logged = 0
        self._step_sums: Any = None  # the step statistics summed over the window, where the core computes
        self._step_tags: tuple[str, ...] = ()
        self.core.reset()
        self._obs = self._observations(core.observe_all())

    def set_rollout_length(self, steps: int) -> None:
        """Read the statistics and the core's checks once per ``steps`` steps (the learner's rollout), not every
        step: on a device every read waits for the step to finish. The statistics then reach ``extras["log"]`` on
        a rollout's last step (:meth:`_drain`); the other steps log nothing."""
        if not isinstance(steps, int) or isinstance(steps, bool) or steps < 1:
            raise ValueError(f"the rollout length must be a whole number of steps >= 1, got {steps!r}")
        self.log_every = steps
        self.core.check_every = steps

    @property
    def dt(self) -> float:
        """Policy step [s]."""
        return self.core.dt

    @property
    def episode_length_buf(self) -> torch.Tensor:
        """Steps taken in the current episodes (N,), int64: the core's counter, which decides time-outs (a view where
        the core computes on the learner's device or on the CPU)."""
        return torch.as_tensor(self.core.episode_step, device=self.device)

    @episode_length_buf.setter
    def episode_length_buf(self, value: torch.Tensor) -> None:
        steps = torch.as_tensor(value).detach().reshape(self.num_envs).to(torch.int64)
        self.core.episode_step[:] = like(steps, self.core.episode_step)

    def _tensor(self, value: Any, dtype: torch.dtype | None = None) -> torch.Tensor:
        """A core array (numpy, or a tensor on the physics' device) on the learner's device, copied only where it
        is elsewhere or of another dtype."""
        return torch.as_tensor(value, dtype=dtype, device=self.device)

    def _observations(self, policy: Any) -> TensorDict:
        groups = {"policy": self._tensor(policy, torch.float32)}
        if self.privileged:
            groups["critic"] = self._tensor(self.core.privileged_observation(), torch.float32)
        return TensorDict(groups, batch_size=[self.num_envs], device=self.device)

    def get_observations(self) -> TensorDict:
        return self._obs

    def curriculum_levels(self) -> torch.Tensor | None:
        """The terrain curriculum's row of each environment (N,) int64 on the CPU; None without a curriculum."""
        if not self.core.terrain.levels:
            return None
        return torch.as_tensor(to_numpy(self.core.terrain_level), dtype=torch.int64)

    def restart_on_levels(self, levels: torch.Tensor) -> None:
        """Start every environment afresh on its saved curriculum row (:meth:`AnymalCore.restart_on_levels`)."""
        self.core.restart_on_levels(levels)
        self._obs = self._observations(self.core.observe_all())

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict[str, Any]]:
        out = self.core.step(actions.detach())
        obs = {"policy": self._tensor(out.observation, torch.float32)}
        if self.privileged and out.privileged is not None:
            obs["critic"] = self._tensor(out.privileged, torch.float32)
        self._obs = TensorDict(obs, batch_size=[self.num_envs], device=self.device)
        rewards = self._tensor(out.reward, torch.float32)
        dones = self._tensor(out.terminated | out.truncated)
        time_outs = self._tensor(out.truncated)
        self.stats.accumulate(out.reward, out.info, out.terminated, out.truncated)
        self._step_tags, statistics = step_statistics(out.info)
        self._step_sums = statistics if self._step_sums is None else self._step_sums + statistics
        self._steps_logged += 1
        extras = {"time_outs": time_outs, "log": self._drain() if self._steps_logged >= self.log_every else {}}
        return self._obs, rewards, dones, extras

    def _drain(self) -> dict[str, float | torch.Tensor]:
        """The window's statistics, read once: the step statistics' means over its steps, and under their
        TensorBoard tags each episode metric's mean repeated once per episode that ended in the window (rsl-rl
        averages everything a rollout's steps logged: so each episode counts once, as when every step logged its
        own episodes)."""
        means = to_numpy(self._step_sums) / self._steps_logged
        log: dict[str, float | torch.Tensor] = dict(zip(self._step_tags, (float(m) for m in means), strict=True))
        episodes = self.stats.drain()
        for tag, (mean, count) in tensorboard_tags(episodes).items():
            log[tag] = torch.full((count,), mean, dtype=torch.float32)
        self._step_sums, self._steps_logged = None, 0
        return log


def rsl_vec_env(
    target: AnymalTarget,
    num_envs: int,
    seed: int | None,
    device: str = "cpu",
    physics: str = "mujoco",
    physics_device: str | None = None,
    physics_options: dict[str, Any] | None = None,
) -> RslVecEnv:
    """The training ``VecEnv`` of an environment target: :class:`RslVecEnv` over the batched core (on backend
    ``physics`` at ``physics_device`` with ``physics_options``; ``device``: where its tensors go, the learner's)."""
    return RslVecEnv(make_core(target.config, num_envs, seed, physics, physics_device, physics_options), device)


def make_rsl_env(
    env_id: str,
    num_envs: int,
    seed: int | None = None,
    device: str = "cpu",
    physics: str = "mujoco",
    physics_device: str | None = None,
    physics_options: dict[str, Any] | None = None,
    **env_options: Any,
) -> RslVecEnv:
    """An rsl-rl ``VecEnv`` of ``num_envs`` environments of a margin_rl ANYmal id, over the batched simulation
    (reset on construction; observations and rewards as torch tensors on ``device``).

    ``env_options``: any :class:`~margin_rl.envs.config.EnvConfig` field (e.g. ``margin_weight=0.2``,
    ``reward_params={"alive_bonus": 0.1}``); ``seed`` seeds the initial states; ``device`` is the learner's,
    ``physics`` and ``physics_device`` the simulator's (``"mujoco"``, or ``"warp"`` with ``"cuda:0"`` or ``"cpu"``:
    MuJoCo Warp, :mod:`margin_rl.envs.physics_warp`; with the learner on the physics' device the environment's tensors
    reach rsl-rl without a copy), ``physics_options`` its settings (Warp: ``nconmax``, ``njmax``). Example::

        from rsl_rl.runners import OnPolicyRunner
        from margin_rl.train import make_rsl_env
        from margin_rl.train.config import RslPPOConfig

        env = make_rsl_env(
            "margin_rl/AnymalB-v1", num_envs=64, seed=0, margin_weight=0.2, reward_params={"alive_bonus": 0.1}
        )
        OnPolicyRunner(env, RslPPOConfig().runner_cfg(False, 50), log_dir=None).learn(100)

    Raises:
        ValueError: ``env_id`` is not a batched margin_rl ANYmal id; the learned margin's weights cannot be loaded.
        TypeError: an option that is not an EnvConfig field, or a badly typed value.
    """
    config = anymal_config(env_id, env_options, "make_rsl_env")
    return RslVecEnv(make_core(config, num_envs, seed, physics, physics_device, physics_options), device)


class TrainingStopped(Exception):  # noqa: N818 - a control-flow signal, not an error
    """Raised at an iteration boundary after a stop request, once the checkpoint is written."""


def _load_checkpoint(path: Path, not_ours: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """(saved dict, its ``infos``) of a checkpoint written by :meth:`CheckpointingRunner.save` (``weights_only``).

    Raises:
        ValueError: ``not_ours`` with the format found, when the file is not such a checkpoint.
    """
    loaded = torch.load(path, map_location="cpu", weights_only=True)
    infos = loaded.get("infos") or {}
    if infos.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{not_ours} (format {infos.get('format')!r})")
    return loaded, infos


class CheckpointingRunner(OnPolicyRunner):
    """rsl-rl's OnPolicyRunner writing atomic, self-describing checkpoints (see the module docstring)."""

    def __init__(
        self,
        env: RslVecEnv,
        train_cfg: dict[str, Any],
        run_dir: Path,
        device: str,
        hooks: RunHooks,
        update_threads: int | None = None,
    ) -> None:
        """``update_threads``: torch threads inside PPO's update (:func:`~margin_rl.train.runs.with_torch_threads`);
        None: the caller's setting throughout."""
        with quiet_stdout(not hooks.verbose):
            super().__init__(env, copy.deepcopy(train_cfg), log_dir=str(run_dir / TENSORBOARD_DIR), device=device)
        if update_threads is not None:
            self.alg.update = with_torch_threads(self.alg.update, update_threads)
        self.adapter = env
        # statistics and the core's checks read once per rollout, on its last step (rsl-rl logs once per iteration)
        env.set_rollout_length(int(train_cfg["num_steps_per_env"]))
        self.run_dir = run_dir
        self.hooks = hooks
        self.completed_iterations = 0
        self.steps_per_iteration = env.num_envs * int(train_cfg["num_steps_per_env"])
        self._logger_log = self.logger.log
        self.logger.log = self._after_iteration  # the runner calls this once per iteration, after the update
        self.exploration = ExplorationMonitor()

    @property
    def obs_dim(self) -> int:
        """Size of the policy observation of this run's environment."""
        return int(self.adapter.get_observations()["policy"].shape[-1])

    @property
    def env_steps(self) -> int:
        """Environment steps in the completed iterations."""
        return self.completed_iterations * self.steps_per_iteration

    def _after_iteration(self, **kwargs: Any) -> None:
        with quiet_stdout(not self.hooks.verbose):
            self._logger_log(**kwargs)
        self.completed_iterations = int(kwargs["it"]) + 1
        self.exploration.update(float(kwargs["action_std"].detach().mean()), self.env_steps)
        rewards = self.logger.rewbuffer
        self.hooks.progress(self.env_steps, statistics.mean(rewards) if rewards else None)
        if self.hooks.stop_requested():
            self.save("")
            raise TrainingStopped

    # ------------------------------------------------------------------ checkpoints
    def checkpoint_dict(self) -> dict[str, Any]:
        """rsl-rl's saved dict plus our progress, config and generator states (all weights_only-loadable)."""
        saved = self.alg.save()
        saved["iter"] = self.completed_iterations - 1
        saved["infos"] = {
            "format": CHECKPOINT_FORMAT,
            "completed_iterations": self.completed_iterations,
            "env_steps": self.env_steps,
            "elapsed_s": float(self.logger.tot_time),
            "train_cfg": copy.deepcopy(self.cfg),
            "obs_dim": self.obs_dim,
            "num_actions": int(self.adapter.num_actions),
            "action_std": self.exploration.last_mean_std,  # mean over the actions, after the last update
            "torch_rng_state": torch.get_rng_state(),
            "env_rng_state": generator_state(self.adapter.core.rng),  # numpy's or the device generator's state
            "curriculum_levels": self.adapter.curriculum_levels(),  # None without a terrain curriculum
        }
        return saved

    @property
    def writes(self) -> bool:
        """Whether this process writes the run folder: always, but in a distributed run (torchrun) rank 0 alone."""
        return self.gpu_global_rank == 0

    def save(self, path: str, infos: dict | None = None) -> None:
        """Write ``<run>/checkpoints/ckpt_<steps>.pt`` atomically (the runner's own ``path`` is ignored); in a
        distributed run rank 0 writes it, the others only note where it is."""
        target = checkpoint_path(self.run_dir, self.env_steps, "rsl")
        if self.writes:
            state = self.checkpoint_dict()
            atomic_write(target, lambda f: torch.save(state, f))
        self.hooks.checkpointed(target, self.env_steps)

    def restore(self, path: Path) -> None:
        """Continue from a checkpoint of :meth:`save` (loaded with ``weights_only=True``)."""
        loaded, infos = _load_checkpoint(path, f"{path}: not a margin_rl rsl-rl training checkpoint")
        self.alg.load(loaded, None, strict=True)
        self.completed_iterations = int(infos["completed_iterations"])
        self.current_learning_iteration = self.completed_iterations
        self.logger.tot_timesteps = self.env_steps
        self.logger.tot_time = float(infos.get("elapsed_s", 0.0))
        torch.set_rng_state(infos["torch_rng_state"])
        env_rng = self.adapter.core.rng
        saved = infos["env_rng_state"] if "env_rng_state" in infos else infos["numpy_rng_state"]  # the older name
        if self.writes and isinstance(saved, dict) == isinstance(env_rng, np.random.Generator):
            set_generator_state(env_rng, saved)
        # else the run was trained on the other kind of physics (host <-> device), or this process is not rank 0 of
        # a distributed run (rank 0's generator is the one saved): the environments' draws start from this
        # process's seed, as its episodes start fresh
        levels = infos.get("curriculum_levels")  # absent in checkpoints written before it was saved
        if levels is not None:
            self.adapter.restart_on_levels(levels)
        # the std the run had reached: what a resume that adds no iteration (a finished run) saves again
        self.exploration.last_mean_std = infos.get("action_std")

    def warm_start(self, path: Path) -> None:
        """Begin with the actor and critic (and their observation normalisers) of a trained model.

        ``path`` is a margin_rl rsl-rl checkpoint or final model; its policy must see the same observation and give
        the same actions as this run's environment, and its networks must have this run's shapes. Optimizer,
        learning rate, iteration counter and random generators stay this run's own (a new run).

        Raises:
            ValueError: not a margin_rl rsl-rl model, or sizes or network shapes that differ from this run's.
        """
        loaded, infos = _load_checkpoint(path, f"--init-from {path}: not a margin_rl rsl-rl model")
        sizes = {
            "observation": (int(infos["obs_dim"]), self.obs_dim),
            "action": (int(infos["num_actions"]), int(self.adapter.num_actions)),
        }
        for name, (theirs, ours) in sizes.items():
            if theirs != ours:
                raise ValueError(
                    f"--init-from {path}: its policy has a {name} of size {theirs}, this run's environment {ours}; "
                    "start from a model trained on the same robot and observation layout"
                )
        try:
            self.alg.load(loaded, {"actor": True, "critic": True}, strict=True)
        except RuntimeError as exc:  # load_state_dict's message lists the mismatched tensors
            raise ValueError(
                f"--init-from {path}: its networks differ from this run's (hidden sizes, activation, privileged "
                f"critic observations must match): {exc}"
            ) from exc

    def close_writer(self) -> None:
        """Flush and close the TensorBoard writer (the runner leaves a SummaryWriter open)."""
        writer = self.logger.writer
        if writer is not None and hasattr(writer, "close"):
            writer.close()

    def export_final(self, final_model: Path) -> Path:
        """Copy the latest state to ``final_model`` and export the actor as TorchScript; returns the latter."""
        state = self.checkpoint_dict()
        atomic_write(final_model, lambda f: torch.save(state, f))
        staging = Path(tempfile.mkdtemp(prefix=".export-", dir=self.run_dir))
        try:  # exported into a private folder, then moved into place (the archive keeps the file's name)
            with torchscript_export():
                self.export_policy_to_jit(str(staging), filename=TORCHSCRIPT_FILE)
            target = self.run_dir / TORCHSCRIPT_FILE
            os.replace(staging / TORCHSCRIPT_FILE, target)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
        return target


def train_rsl(
    env: RslVecEnv,
    train_cfg: dict[str, Any],
    run_dir: Path,
    device: str,
    total_iterations: int,
    checkpoint: Path | None,
    hooks: RunHooks,
    final_model: Path,
    init_from: str | Path | None = None,
    update_threads: int | None = None,
) -> tuple[int, bool, Path | None]:
    """Run (or continue) rsl-rl PPO up to ``total_iterations``; returns (env steps, stopped, TorchScript path).

    The caller seeds torch before calling (the networks are initialised here). ``init_from``: a trained model whose
    weights a new run starts from (:meth:`CheckpointingRunner.warm_start`); ignored when continuing a checkpoint.
    ``update_threads``: torch threads inside the PPO update (None: the caller's setting throughout).
    """
    runner = CheckpointingRunner(env, train_cfg, run_dir, device, hooks, update_threads)
    if checkpoint is not None:
        runner.restore(checkpoint)
    elif init_from is not None:
        runner.warm_start(Path(init_from))
    remaining = total_iterations - runner.completed_iterations
    try:
        if remaining > 0:
            with quiet_stdout(not hooks.verbose):  # rsl-rl prints the model and a git note here
                runner.learn(remaining, init_at_random_ep_len=True)
    except TrainingStopped:
        return runner.env_steps, True, None
    finally:
        runner.close_writer()
    return runner.env_steps, False, runner.export_final(final_model) if runner.writes else None
