"""Deterministic evaluation episodes of a policy on a batched ANYmal environment: one runner and one recorder.

:func:`run_episodes` takes an :class:`~margin_rl.train.environments.AnymalTarget` (or an ``EnvConfig``) and runs
``num_episodes`` episodes in parallel on one batched core seeded ``seed`` (environment ``i`` runs episode ``i``),
each environment's first episode to its end (or ``max_steps`` policy steps), recording the first one step by
step. Metrics are those of :class:`~margin_rl.train.metrics.EpisodeStatistics`, the first ``warmup_s`` seconds
left out of the acceleration statistics; ``render`` draws the first episode with an offscreen camera while it runs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.train.artifacts.policies import LoadedPolicy
from margin_rl.train.environments import ACTION_SIZE, AnymalTarget
from margin_rl.train.metrics import EpisodeStatistics, not_computed, split_episodes, summarize


@dataclass
class Evaluation:
    """Deterministic episodes of one policy."""

    episodes: list[dict[str, float]]  # metrics of each episode (margin_rl.train.metrics)
    trajectory: dict[str, np.ndarray]  # the first episode over time (see run_episodes)
    dt: float  # policy step [s]
    frames: list[np.ndarray] = field(default_factory=list)  # rendered frames of the first episode, one per step
    render_message: str = ""
    warmup_s: float | None = None  # seconds left out of the acceleration statistics

    @property
    def summary(self) -> dict[str, dict[str, float]]:
        return summarize(self.episodes)

    @property
    def not_computed(self) -> dict[str, str]:
        """Metric -> reason, for every metric that no episode could give (see :func:`metrics.not_computed`)."""
        return not_computed(self.summary, self.warmup_s)


class Recorder:
    """Per-step rows of one environment while its first episode runs; a key missing on a step is NaN there
    (a plot leaves a gap)."""

    def __init__(self, keys: tuple[str, ...] = ()) -> None:
        self.rows: dict[str, list[Any]] = {k: [] for k in keys}
        self.steps = 0

    def add(self, row: Mapping[str, Any]) -> None:
        for key, value in row.items():
            self.rows.setdefault(key, [math.nan] * self.steps).append(value)
        self.steps += 1
        for values in self.rows.values():
            values.extend([math.nan] * (self.steps - len(values)))

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self.rows.items()}


# ---------------------------------------------------------------------------------------------------------------------
# the batch of environments
# ---------------------------------------------------------------------------------------------------------------------
class _Camera:
    """Offscreen frames of one environment of a core (a camera following its base)."""

    def __init__(self, core: AnymalCore, width: int, height: int) -> None:
        self.core = core
        self.renderer = mujoco.Renderer(core.model, height, width)
        self.camera = mujoco.MjvCamera()
        self.camera.distance, self.camera.elevation, self.camera.azimuth = 2.5, -20.0, 120.0

    def frame(self, env: int) -> np.ndarray:
        data = self.core.render_data(env)
        self.camera.lookat[:] = data.qpos[:3]
        self.renderer.update_scene(data, self.camera)
        return self.renderer.render().copy()

    def close(self) -> None:
        self.renderer.close()


class _AnymalBatch:
    """Every episode at once on one batched ANYmal core; rows of ``lin_acc`` (3,), ``ang_acc`` (3,),
    ``forward_velocity``, ``command``, ``margin``, ``stance_width``, ``contacts`` (4,), ``reward``."""

    KEYS = ("lin_acc", "ang_acc", "forward_velocity", "command", "margin", "stance_width", "contacts", "reward")

    def __init__(self, core: AnymalCore, warmup_s: float) -> None:
        self.core, self.num_envs, self.warmup_s = core, core.num_envs, warmup_s
        self._info: Mapping[str, np.ndarray] = {}

    def start(self) -> np.ndarray:
        self.core.reset()
        self.stats = EpisodeStatistics(self.num_envs, self.core.dt, warmup_steps=round(self.warmup_s / self.core.dt))
        return self.core.observe_all()

    def step_limit(self, max_steps: int | None) -> int:
        return max_steps if max_steps is not None else self.core.max_episode_steps

    def step(self, policy: LoadedPolicy, obs: np.ndarray) -> tuple[np.ndarray, dict[str, Any], dict, bool]:
        """(next observations, row of environment 0, metrics of the episodes that ended, whether 0 ended)."""
        command = self.core.command.copy()
        out = self.core.step(policy(obs))
        info = self._info = out.info
        row = {
            "lin_acc": np.array(info["base_lin_acc"][0]),
            "ang_acc": np.array(info["base_ang_acc"][0]),
            "forward_velocity": np.array(info["base_lin_vel"][0, 0]),
            "command": np.array(command[0, 0]),
            "margin": np.array(info["margin"][0]),
            "stance_width": np.array(info["stance_width"][0]),
            "contacts": np.array(info["contacts"][0]),
            "reward": np.array(out.reward[0]),
        }
        finished = self.stats.update(out.reward, info, out.terminated, out.truncated)
        return out.observation, row, finished, bool(out.terminated[0] or out.truncated[0])

    def close_running(self, ids: np.ndarray) -> dict[str, np.ndarray]:
        """Metrics of the running episodes of ``ids``, ended as they stand."""
        return self.stats.close(ids, self._info)

    def open_camera(self, size: tuple[int, int]) -> tuple[_Camera | None, str]:
        try:
            return _Camera(self.core, *size), ""
        except Exception as exc:  # GL back ends fail in many ways (no display, no EGL, ...)
            return None, (
                f"rendering unavailable ({type(exc).__name__}: {exc}); set MUJOCO_GL=egl or osmesa before "
                "starting Python on a machine without a display"
            )


def _run_batch(
    policy: LoadedPolicy,
    batch: _AnymalBatch,
    max_steps: int | None,
    recorder: Recorder,
    camera: _Camera | None,
    frames: list[np.ndarray],
) -> list[dict[str, float]]:
    """Each environment's first episode, in environment order; records environment 0 (and draws its frames)
    while its first episode runs."""
    obs = batch.start()
    if camera is not None:
        frames.append(camera.frame(0))
    episodes: dict[int, dict[str, float]] = {}
    for _ in range(batch.step_limit(max_steps)):
        obs, row, finished, done0 = batch.step(policy, obs)
        if 0 not in episodes:
            recorder.add(row)
            if camera is not None and not done0:
                frames.append(camera.frame(0))
        for episode in split_episodes(finished):
            episodes.setdefault(int(episode.pop("env")), episode)
        if len(episodes) == batch.num_envs:
            break
    if len(episodes) < batch.num_envs:  # max_steps reached: close the running episodes as they stand
        running = np.array([i for i in range(batch.num_envs) if i not in episodes])
        for episode in split_episodes(batch.close_running(running)):
            episodes[int(episode.pop("env"))] = episode
    return [episodes[i] for i in range(batch.num_envs)]


def run_episodes(
    policy: LoadedPolicy,
    env: AnymalTarget | EnvConfig,
    num_episodes: int = 4,
    seed: int = 0,
    warmup_s: float = 1.0,
    render: bool = False,
    size: tuple[int, int] = (640, 480),
    max_steps: int | None = None,
) -> Evaluation:
    """Run ``num_episodes`` deterministic episodes of ``env`` (an :class:`~margin_rl.train.environments.AnymalTarget`
    or its ``EnvConfig``), see the module docstring.

    The trajectory holds, for the first episode, ``time`` [s], ``lin_acc`` (T, 3) [m/s²], ``ang_acc`` (T, 3)
    [rad/s²] (base frame), ``forward_velocity`` and ``command`` [m/s], ``margin`` [m], ``stance_width`` [m],
    ``contacts`` (T, 4), ``reward``. ``warmup_s``: the first seconds of each episode are left out of the
    acceleration statistics (landing after the reset). ``render``: frames of the first episode for a video;
    ``size`` (width, height) of the camera.

    Raises:
        PolicyMismatchError: the policy's observation or action size does not fit the environment.
    """
    config = env.config if isinstance(env, AnymalTarget) else env
    core = AnymalCore(config, num_envs=num_episodes, seed=seed)
    policy.check(int(core.observation_size), ACTION_SIZE, f"{config.robot} ({config.terrain})")
    batch = _AnymalBatch(core, warmup_s)
    recorder = Recorder(_AnymalBatch.KEYS)
    frames: list[np.ndarray] = []
    camera, message = batch.open_camera(size) if render else (None, "")
    try:
        episodes = _run_batch(policy, batch, max_steps, recorder, camera, frames)
    finally:
        if camera is not None:
            camera.close()
    trajectory = recorder.arrays()
    trajectory["time"] = core.dt * np.arange(1, recorder.steps + 1)
    return Evaluation(episodes, trajectory, core.dt, frames, message, warmup_s)
