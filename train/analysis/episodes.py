"""Deterministic evaluation episodes of a policy: one runner and one recorder for both kinds of environment.

:func:`run_episodes` takes an :class:`~margin_rl.train.environments.EnvTarget` (or an ANYmal ``EnvConfig``) and
runs ``num_episodes`` episodes, each environment's first episode to its end (or ``max_steps`` policy steps),
recording the first one step by step. The environment kind only decides the batches the runner steps:

* ANYmal: all episodes in parallel on one batched core seeded ``seed`` (environment ``i`` runs episode ``i``),
  metrics of :class:`~margin_rl.train.metrics.EpisodeStatistics`, the first ``warmup_s`` seconds left out of
  the acceleration statistics; ``render`` draws the first episode with an offscreen camera while it runs;
* generic: episode ``i`` on its own ``gymnasium.make(id, **env_kwargs)`` reset with seed ``seed + i``, one after
  the other, metrics of :class:`~margin_rl.train.metrics.InfoEpisodeStatistics`; ``render`` replays the first
  episode with ``render_mode="rgb_array"`` (the metrics never come from a rendered run: some environments,
  SLIPHopper among them, simulate slightly differently while recording).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.train.artifacts.policies import LoadedPolicy
from margin_rl.train.environments import (
    ACTION_SIZE,
    GENERIC_STEP_LIMIT,
    AnymalTarget,
    EnvTarget,
    GymTarget,
    check_gym_env,
    make_gym_env,
)
from margin_rl.train.metrics import (
    EpisodeStatistics,
    InfoEpisodeStatistics,
    not_computed,
    split_episodes,
    summarize,
)


@dataclass
class Evaluation:
    """Deterministic episodes of one policy."""

    episodes: list[dict[str, float]]  # metrics of each episode (margin_rl.train.metrics)
    trajectory: dict[str, np.ndarray]  # the first episode over time (see run_episodes)
    dt: float  # policy step [s]
    frames: list[np.ndarray] = field(default_factory=list)  # rendered frames of the first episode
    render_message: str = ""
    fps: float | None = None  # frame rate of ``frames`` [1/s]; None: one frame per policy step, 1 / dt
    warmup_s: float | None = None  # seconds left out of the acceleration statistics (ANYmal), None otherwise

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
# batches of environments, one kind each
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

    def close(self) -> None:
        pass


def _step_limit(env: Any, max_steps: int | None) -> int:
    """``max_steps``, else the environment's time limit, else :data:`GENERIC_STEP_LIMIT`."""
    if max_steps is not None:
        return int(max_steps)
    limit = env.spec.max_episode_steps if env.spec is not None else None
    return int(limit) if limit else GENERIC_STEP_LIMIT


def _gym_action(policy: LoadedPolicy, obs: np.ndarray, space: Any) -> np.ndarray:
    """The policy's deterministic action for one observation, in the action space's dtype."""
    return np.asarray(policy(np.asarray(obs)[None])[0], dtype=space.dtype)


class _GymBatch:
    """One episode on a fresh generic environment reset with ``seed``; rows of ``observation`` (the one each
    action was chosen from), ``reward`` and every numeric ``info["reward_<term>"]``."""

    num_envs = 1

    def __init__(self, target: GymTarget, seed: int) -> None:
        self.env, self.seed = make_gym_env(target.env_id, target.kwargs), seed

    def start(self) -> np.ndarray:
        self.stats = InfoEpisodeStatistics(1)
        obs, _ = self.env.reset(seed=self.seed)
        return obs

    def step_limit(self, max_steps: int | None) -> int:
        return _step_limit(self.env, max_steps)

    def step(self, policy: LoadedPolicy, obs: np.ndarray) -> tuple[np.ndarray, dict[str, Any], dict, bool]:
        """(next observation, row, metrics of the episode if it ended, whether it ended)."""
        following, reward, terminated, truncated, info = self.env.step(_gym_action(policy, obs, self.env.action_space))
        row: dict[str, Any] = {"observation": np.asarray(obs, dtype=np.float64).ravel(), "reward": float(reward)}
        for key, value in info.items():
            if key.startswith("reward_") and isinstance(value, (int, float, np.integer, np.floating)):
                row[key] = float(value)
        finished = self.stats.update(np.array([reward]), [info], np.array([terminated]), np.array([truncated]))
        return following, row, finished, bool(terminated or truncated)

    def close_running(self, ids: np.ndarray) -> dict[str, np.ndarray]:
        return self.stats.close(ids)

    def open_camera(self, size: tuple[int, int]) -> tuple[None, str]:
        return None, ""  # a generic episode is replayed for its frames instead (_gym_frames)

    def close(self) -> None:
        self.env.close()


def _gym_frames(
    policy: LoadedPolicy, target: GymTarget, seed: int, max_steps: int | None
) -> tuple[list[np.ndarray], str, float | None]:
    """Replay one episode with ``render_mode="rgb_array"``: (frames, message explaining no frames, fps)."""
    env_id = target.env_id
    try:
        env = make_gym_env(env_id, target.kwargs, render_mode="rgb_array")
    except Exception as exc:  # environments refuse render modes in many ways
        return [], f"{env_id} cannot render rgb_array frames ({type(exc).__name__}: {exc})", None
    frames: list[np.ndarray] = []
    try:
        if "rgb_array" not in env.metadata.get("render_modes", []):
            return [], f"{env_id} offers no rgb_array rendering", None
        obs, _ = env.reset(seed=seed)
        frames.append(np.asarray(env.render()))
        for _ in range(_step_limit(env, max_steps)):
            obs, _, terminated, truncated, _ = env.step(_gym_action(policy, obs, env.action_space))
            frames.append(np.asarray(env.render()))
            if terminated or truncated:
                break
        fps = env.metadata.get("render_fps")
    except Exception as exc:  # a GL back end or a drawing library may be missing
        return [], f"rendering {env_id} failed ({type(exc).__name__}: {exc})", None
    finally:
        env.close()
    return frames, "", float(fps) if fps else None


_Batch = _AnymalBatch | _GymBatch


def _batches(
    policy: LoadedPolicy, target: EnvTarget, num_episodes: int, seed: int, warmup_s: float
) -> tuple[Iterator[_Batch], float]:
    """The batches that run the episodes (built lazily), once the policy is checked against the environment;
    and the policy step [s] (NaN for a generic environment without ``dt``: steps of no fixed duration, e.g. hops).

    Raises:
        PolicyMismatchError: the policy's observation or action size does not fit the environment.
    """
    if isinstance(target, AnymalTarget):
        core = AnymalCore(target.config, num_envs=num_episodes, seed=seed)
        config = target.config
        policy.check(int(core.observation_size), ACTION_SIZE, f"{config.robot} ({config.terrain})")
        return iter([_AnymalBatch(core, warmup_s)]), core.dt
    check_gym_env(target.env_id, target.kwargs)
    probe = make_gym_env(target.env_id, target.kwargs)
    try:
        obs_dim, action_dim = int(probe.observation_space.shape[0]), int(probe.action_space.shape[0])
        dt = float(getattr(probe.unwrapped, "dt", math.nan))
    finally:
        probe.close()
    policy.check(obs_dim, action_dim, target.env_id)
    return (_GymBatch(target, seed + i) for i in range(num_episodes)), dt


def _run_batch(
    policy: LoadedPolicy,
    batch: _Batch,
    max_steps: int | None,
    recorder: Recorder | None,
    camera: _Camera | None,
    frames: list[np.ndarray],
) -> list[dict[str, float]]:
    """Each environment's first episode of a batch, in environment order; records environment 0 (and draws its
    frames) while its first episode runs."""
    obs = batch.start()
    if camera is not None:
        frames.append(camera.frame(0))
    episodes: dict[int, dict[str, float]] = {}
    for _ in range(batch.step_limit(max_steps)):
        obs, row, finished, done0 = batch.step(policy, obs)
        if recorder is not None and 0 not in episodes:
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
    env: EnvTarget | EnvConfig,
    num_episodes: int = 4,
    seed: int = 0,
    warmup_s: float = 1.0,
    render: bool = False,
    size: tuple[int, int] = (640, 480),
    max_steps: int | None = None,
) -> Evaluation:
    """Run ``num_episodes`` deterministic episodes of ``env`` (an ANYmal ``EnvConfig`` or any
    :class:`~margin_rl.train.environments.EnvTarget`), see the module docstring.

    The trajectory holds, for the first episode, ANYmal: ``time`` [s], ``lin_acc`` (T, 3) [m/s²], ``ang_acc``
    (T, 3) [rad/s²] (base frame), ``forward_velocity`` and ``command`` [m/s], ``margin`` [m], ``stance_width`` [m],
    ``contacts`` (T, 4), ``reward``; generic: ``step`` (T,), ``observation`` (T, obs) (the one each action was
    chosen from), ``reward`` (T,) and every ``reward_<term>`` of ``info``. ``warmup_s`` (ANYmal only): the first
    seconds of each episode are left out of the acceleration statistics (landing after the reset). ``render``:
    frames of the first episode for a video; ``size`` (width, height) of the ANYmal camera.

    Raises:
        PolicyMismatchError: the policy's observation or action size does not fit the environment.
    """
    target = env if isinstance(env, (AnymalTarget, GymTarget)) else AnymalTarget("", env)
    anymal = isinstance(target, AnymalTarget)
    batches, dt = _batches(policy, target, num_episodes, seed, warmup_s)
    recorder = Recorder(_AnymalBatch.KEYS if anymal else ())
    frames: list[np.ndarray] = []
    message, fps = "", None
    episodes: list[dict[str, float]] = []
    for index, batch in enumerate(batches):
        camera = None
        try:
            if index == 0 and render:
                camera, message = batch.open_camera(size)
            first = recorder if index == 0 else None
            episodes += _run_batch(policy, batch, max_steps, first, camera, frames)
        finally:
            if camera is not None:
                camera.close()
            batch.close()
    trajectory = recorder.arrays()
    if anymal:
        trajectory["time"] = dt * np.arange(1, recorder.steps + 1)
    else:
        trajectory = {"step": np.arange(recorder.steps), **trajectory}
        if render:
            frames, message, fps = _gym_frames(policy, target, seed, max_steps)
    return Evaluation(episodes, trajectory, dt, frames, message, fps, warmup_s if anymal else None)
