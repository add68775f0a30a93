"""``evaluate``: deterministic episodes of a saved policy, with metrics JSON, plots and an optional MP4.

Examples::

    python -m margin_rl.train.evaluate runs/<run>/final_model.pt            # rsl-rl checkpoint
    python -m margin_rl.train.evaluate runs/<run>/final_model.zip --episodes 8   # SB3 (unpickles: trusted files only)
    python -m margin_rl.train.evaluate runs/<run>/policy_torchscript.pt --video
    python -m margin_rl.train.evaluate policy.pt --env margin_rl/AnymalC-v0 --forward-velocity 1.0
    python -m margin_rl.train.evaluate runs/<slip run>/final_model.zip --env-option goal_velocity=0.5

The environment is the policy's training environment (its run's ``config.json``) unless ``--env`` or
environment options say otherwise (EnvConfig fields for the ANYmal ids, constructor keywords for the others,
as for ``train``).

ANYmal ids: the command is fixed (``--forward-velocity``, default 0.75 m/s as in seed
000 §V-C), episodes run in parallel from ``--seed``, each to its first termination or time limit. Outputs
(default ``<run>/eval/``): ``metrics.json`` (every episode's metrics, see :mod:`margin_rl.train.metrics`, and
their mean/std), ``episode.png`` (base accelerations, velocity, margin and stance width over the first episode)
and, with ``--video``, ``episode.mp4`` of the first episode (needs imageio with its ffmpeg plugin and a GL
backend, e.g. ``MUJOCO_GL=egl``).

Other ids (generic path, e.g. ``margin_rl/SLIPHopper-v0``): episode ``i`` runs on its own
``gymnasium.make(id, **env_kwargs)`` reset with seed ``--seed + i``, to its end or ``--max-steps``.
``metrics.json`` holds each episode's return, length, reward-term sums and means of the environment's other
numeric ``info`` values (:class:`margin_rl.train.adapters.InfoEpisodeStatistics`), ``episode.png`` the reward
terms and observations over the first episode, and ``--video`` replays that episode with
``render_mode="rgb_array"`` where the environment offers it (the metrics never come from a rendered run: some
environments, SLIPHopper among them, simulate slightly differently while recording). ``--forward-velocity`` and
``--warmup-s`` apply to ANYmal only.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from margin_rl.envs.config import CommandConfig, EnvConfig
from margin_rl.train.config import apply_overrides, from_dict, to_dict
from margin_rl.train.metrics import EpisodeStatistics, split_episodes, summarize
from margin_rl.train.policies import LoadedPolicy, PolicyMismatchError, load_policy
from margin_rl.train.runs import torch_threads, write_json

DEFAULT_FORWARD_VELOCITY = 0.75  # m/s, seed 000 §V-C
VIDEO_HINT = "install it with: pip install 'margin_rl[video]' (imageio, imageio-ffmpeg)"


@dataclass
class Evaluation:
    """Deterministic episodes of one policy."""

    episodes: list[dict[str, float]]  # metrics of each episode (margin_rl.train.metrics)
    trajectory: dict[str, np.ndarray]  # the first episode over time (see run_episodes)
    dt: float  # policy step [s]
    frames: list[np.ndarray] = field(default_factory=list)  # rendered frames of the first episode
    render_message: str = ""
    fps: float | None = None  # frame rate of ``frames`` [1/s]; None: one frame per policy step, 1 / dt

    @property
    def summary(self) -> dict[str, dict[str, float]]:
        return summarize(self.episodes)


def evaluation_config(config: EnvConfig, forward_velocity: float | None) -> EnvConfig:
    """``config`` with a fixed heading-velocity command (no lateral velocity, no yaw rate)."""
    if forward_velocity is None:
        return config
    v = float(forward_velocity)
    return config.replace(
        command=CommandConfig(forward_velocity=(v, v), lateral_velocity=(0.0, 0.0), yaw_rate=(0.0, 0.0))
    )


class _Recorder:
    """Per-step quantities of one environment while its first episode runs."""

    KEYS = ("lin_acc", "ang_acc", "forward_velocity", "command", "margin", "stance_width", "contacts", "reward")

    def __init__(self) -> None:
        self.rows: dict[str, list[np.ndarray]] = {k: [] for k in self.KEYS}

    def add(self, info: dict[str, np.ndarray], reward: np.ndarray, command: np.ndarray, env: int) -> None:
        self.rows["lin_acc"].append(np.array(info["base_lin_acc"][env]))
        self.rows["ang_acc"].append(np.array(info["base_ang_acc"][env]))
        self.rows["forward_velocity"].append(np.array(info["base_lin_vel"][env, 0]))
        self.rows["command"].append(np.array(command[env, 0]))
        self.rows["margin"].append(np.array(info["margin"][env]))
        self.rows["stance_width"].append(np.array(info["stance_width"][env]))
        self.rows["contacts"].append(np.array(info["contacts"][env]))
        self.rows["reward"].append(np.array(reward[env]))

    def arrays(self, dt: float) -> dict[str, np.ndarray]:
        data = {k: np.asarray(v) for k, v in self.rows.items()}
        data["time"] = dt * np.arange(1, len(self.rows["margin"]) + 1)
        return data


class _Camera:
    """Offscreen frames of one environment (a camera following its base)."""

    def __init__(self, core: Any, width: int, height: int) -> None:
        import mujoco

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


def _open_camera(core: Any, width: int, height: int) -> tuple[_Camera | None, str]:
    try:
        return _Camera(core, width, height), ""
    except Exception as exc:  # GL back ends fail in many ways (no display, no EGL, ...)
        return None, (
            f"rendering unavailable ({type(exc).__name__}: {exc}); set MUJOCO_GL=egl or osmesa before starting "
            "Python on a machine without a display"
        )


def run_episodes(
    policy: LoadedPolicy,
    config: EnvConfig,
    num_episodes: int = 4,
    seed: int = 0,
    warmup_s: float = 1.0,
    render: bool = False,
    size: tuple[int, int] = (640, 480),
    max_steps: int | None = None,
) -> Evaluation:
    """Run ``num_episodes`` deterministic episodes in parallel (one environment each, seeded by ``seed``).

    Each environment's first episode counts (to termination or the time limit, or ``max_steps`` policy steps).
    ``warmup_s``: the first seconds of each episode are left out of the acceleration statistics (landing
    after the reset). The trajectory holds, for the first episode: ``time`` [s], ``lin_acc`` (T, 3) [m/s²],
    ``ang_acc`` (T, 3) [rad/s²] (base frame), ``forward_velocity`` and ``command`` [m/s], ``margin`` [m],
    ``stance_width`` [m], ``contacts`` (T, 4), ``reward``.

    Raises:
        PolicyMismatchError: the policy's observation or action size does not fit the environment.
    """
    from margin_rl.envs.core import AnymalCore

    core = AnymalCore(config, num_envs=num_episodes, seed=seed)
    policy.check(int(core.observation_size), 12, f"{config.robot} ({config.terrain})")
    core.reset()
    stats = EpisodeStatistics(num_episodes, core.dt, warmup_steps=round(warmup_s / core.dt))
    recorder = _Recorder()
    camera, message = _open_camera(core, *size) if render else (None, "")
    frames: list[np.ndarray] = [camera.frame(0)] if camera is not None else []
    episodes: dict[int, dict[str, float]] = {}
    obs = core.observe_all()
    limit = max_steps if max_steps is not None else core.max_episode_steps
    for _ in range(limit):
        command = core.command.copy()
        out = core.step(policy(obs))
        obs = out.observation
        if 0 not in episodes:
            recorder.add(out.info, out.reward, command, 0)
            if camera is not None and not (out.terminated[0] or out.truncated[0]):
                frames.append(camera.frame(0))
        for episode in split_episodes(stats.update(out.reward, out.info, out.terminated, out.truncated)):
            env = int(episode.pop("env"))
            episodes.setdefault(env, episode)
        if len(episodes) == num_episodes:
            break
    if len(episodes) < num_episodes:  # max_steps reached: close the running episodes as they stand
        running = np.array([i for i in range(num_episodes) if i not in episodes])
        for episode in split_episodes(stats.close(running, out.info)):
            episodes[int(episode.pop("env"))] = episode
    if camera is not None:
        camera.close()
    ordered = [episodes[i] for i in range(num_episodes)]
    return Evaluation(ordered, recorder.arrays(core.dt), core.dt, frames, message)


def save_figure(fig: Any, path: str | Path) -> Path:
    """Lay out, write (creating the folder) and close a matplotlib figure; returns the path."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_episode(evaluation: Evaluation, path: str | Path, title: str = "") -> Path:
    """Base accelerations, heading velocity, margin and stance width over the first episode (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    traj = evaluation.trajectory
    t = traj["time"]
    fig, axes = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    for k, axis in enumerate("xyz"):
        axes[0].plot(t, traj["lin_acc"][:, k], lw=0.8, label=axis)
        axes[1].plot(t, traj["ang_acc"][:, k], lw=0.8, label=axis)
    axes[0].set_ylabel("base lin. acc. [m/s²]")
    axes[1].set_ylabel("base ang. acc. [rad/s²]")
    axes[2].plot(t, traj["forward_velocity"], label="ẋ (base frame)")
    axes[2].plot(t, traj["command"], "k--", lw=1, label="command")
    axes[2].set_ylabel("heading velocity [m/s]")
    axes[3].plot(t, traj["margin"], color="tab:red", label="margin")
    axes[3].set_ylabel("margin [m]", color="tab:red")
    twin = axes[3].twinx()
    twin.plot(t, traj["stance_width"], color="tab:green", label="stance width")
    twin.set_ylabel("stance width [m]", color="tab:green")
    axes[3].set_xlabel("time [s]")
    for ax in axes[:3]:
        ax.legend(loc="upper right", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle(title or "evaluation episode")
    return save_figure(fig, path)


class _GymRecorder:
    """Per-step observation, reward and reward terms of one generic episode."""

    def __init__(self) -> None:
        self.observation: list[np.ndarray] = []
        self.reward: list[float] = []
        self.terms: dict[str, list[float]] = {}

    def add(self, obs: np.ndarray, reward: float, info: Mapping[str, Any]) -> None:
        steps = len(self.reward)
        self.observation.append(np.asarray(obs, dtype=np.float64).ravel())
        self.reward.append(float(reward))
        for key, value in info.items():
            if key.startswith("reward_") and isinstance(value, (int, float, np.integer, np.floating)):
                self.terms.setdefault(key, [math.nan] * steps).append(float(value))
        for values in self.terms.values():  # a term missing on a step is NaN there (plots leave a gap)
            values.extend([math.nan] * (len(self.reward) - len(values)))

    def arrays(self) -> dict[str, np.ndarray]:
        data = {"step": np.arange(len(self.reward)), "observation": np.asarray(self.observation)}
        data["reward"] = np.asarray(self.reward)
        data.update({key: np.asarray(values) for key, values in self.terms.items()})
        return data


def _step_limit(env: Any, max_steps: int | None) -> int:
    """``max_steps``, else the environment's time limit, else :data:`~margin_rl.train.adapters.GENERIC_STEP_LIMIT`."""
    from margin_rl.train.adapters import GENERIC_STEP_LIMIT

    if max_steps is not None:
        return int(max_steps)
    limit = env.spec.max_episode_steps if env.spec is not None else None
    return int(limit) if limit else GENERIC_STEP_LIMIT


def _gym_action(policy: LoadedPolicy, obs: np.ndarray, space: Any) -> np.ndarray:
    """The policy's deterministic action for one observation, in the action space's dtype."""
    return np.asarray(policy(np.asarray(obs)[None])[0], dtype=space.dtype)


def _gym_episode(
    policy: LoadedPolicy,
    env_id: str,
    env_kwargs: Mapping[str, Any],
    seed: int,
    max_steps: int | None,
    recorder: _GymRecorder | None,
) -> dict[str, float]:
    """One deterministic episode on a fresh environment reset with ``seed``; its metrics."""
    from margin_rl.train.adapters import InfoEpisodeStatistics, make_gym_env

    env = make_gym_env(env_id, env_kwargs)
    stats = InfoEpisodeStatistics(1)
    try:
        obs, _ = env.reset(seed=seed)
        finished: dict[str, np.ndarray] = {}
        for _ in range(_step_limit(env, max_steps)):
            previous = obs
            obs, reward, terminated, truncated, info = env.step(_gym_action(policy, obs, env.action_space))
            if recorder is not None:
                recorder.add(previous, float(reward), info)
            finished = stats.update(np.array([reward]), [info], np.array([terminated]), np.array([truncated]))
            if finished:
                break
        if not finished:  # max_steps reached: close the running episode as it stands
            finished = stats.close([0])
    finally:
        env.close()
    (episode,) = split_episodes(finished)
    episode.pop("env")
    return episode


def _gym_frames(
    policy: LoadedPolicy, env_id: str, env_kwargs: Mapping[str, Any], seed: int, max_steps: int | None
) -> tuple[list[np.ndarray], str, float | None]:
    """Replay one episode with ``render_mode="rgb_array"``: (frames, message explaining no frames, fps)."""
    from margin_rl.train.adapters import make_gym_env

    try:
        env = make_gym_env(env_id, env_kwargs, render_mode="rgb_array")
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


def run_gym_episodes(
    policy: LoadedPolicy,
    env_id: str,
    env_kwargs: Mapping[str, Any],
    num_episodes: int = 4,
    seed: int = 0,
    render: bool = False,
    max_steps: int | None = None,
) -> Evaluation:
    """``num_episodes`` deterministic episodes of a generic (non-ANYmal) environment, one after the other.

    Episode ``i`` runs on a fresh ``gymnasium.make(env_id, **env_kwargs)`` reset with ``seed + i``, to its end
    or ``max_steps`` policy steps. The trajectory holds, for the first episode: ``step`` (T,), ``observation``
    (T, obs) (the one each action was chosen from), ``reward`` (T,) and every ``reward_<term>`` of ``info``.
    ``dt`` is the environment's ``dt`` when it has one, else NaN (steps of no fixed duration, e.g. hops).
    ``render``: also replay the first episode with ``render_mode="rgb_array"`` for a video.

    Raises:
        PolicyMismatchError: the policy's observation or action size does not fit the environment.
    """
    from margin_rl.train.adapters import check_gym_env, make_gym_env

    check_gym_env(env_id, env_kwargs)
    probe = make_gym_env(env_id, env_kwargs)
    try:
        obs_dim, action_dim = int(probe.observation_space.shape[0]), int(probe.action_space.shape[0])
        dt = float(getattr(probe.unwrapped, "dt", math.nan))
    finally:
        probe.close()
    policy.check(obs_dim, action_dim, env_id)
    recorder = _GymRecorder()
    episodes = [
        _gym_episode(policy, env_id, env_kwargs, seed + i, max_steps, recorder if i == 0 else None)
        for i in range(num_episodes)
    ]
    frames, message, fps = _gym_frames(policy, env_id, env_kwargs, seed, max_steps) if render else ([], "", None)
    return Evaluation(episodes, recorder.arrays(), dt, frames, message, fps)


def plot_gym_episode(evaluation: Evaluation, path: str | Path, title: str = "", max_observations: int = 12) -> Path:
    """Reward (and its ``reward_<term>`` parts) and the first ``max_observations`` observation components over
    the first episode of :func:`run_gym_episodes` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    traj = evaluation.trajectory
    step = traj["step"]
    style = {"marker": "." if step.size < 60 else None, "lw": 0.9}  # short episodes: show the points
    fig, axes = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    axes[0].plot(step, traj["reward"], color="black", label="reward", **style)
    for key in sorted(k for k in traj if k.startswith("reward_")):
        axes[0].plot(step, traj[key], label=key.removeprefix("reward_"), **style)
    axes[0].set_ylabel("reward per step")
    observation = traj["observation"]
    for k in range(min(observation.shape[1] if observation.ndim == 2 else 0, max_observations)):
        axes[1].plot(step, observation[:, k], label=f"obs[{k}]", **style)
    axes[1].set_ylabel("observation (acted on)")
    axes[1].set_xlabel("step")
    for ax in axes:
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(loc="upper right", fontsize=8)
    fig.suptitle(title or "evaluation episode")
    return save_figure(fig, path)


def write_video(frames: list[np.ndarray], path: str | Path, fps: float) -> tuple[Path | None, str]:
    """Write frames as an MP4 with imageio; returns (path or None, message explaining a missing video)."""
    if not frames:
        return None, "no frames were rendered"
    try:
        import imageio.v2 as imageio
    except ImportError:
        return None, f"MP4 needs imageio, which is not installed; {VIDEO_HINT}"
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        imageio.mimwrite(path, frames, fps=fps, macro_block_size=1)
    except Exception as exc:  # mostly a missing ffmpeg plugin
        return None, f"imageio could not write {path.name} ({type(exc).__name__}: {exc}); {VIDEO_HINT}"
    return path, ""


def evaluation_env_id(policy: LoadedPolicy, env_id: str | None) -> str:
    """``env_id``, else the policy's training environment (its run config), else :data:`DEFAULT_ENV`."""
    from margin_rl.train.train import DEFAULT_ENV

    run = policy.train_config or {}
    return env_id or run.get("env_id") or DEFAULT_ENV


def resolve_gym_env(
    policy: LoadedPolicy, env_id: str, overrides: Mapping[str, Any] | None
) -> tuple[str, dict[str, Any]]:
    """A generic (non-ANYmal) evaluation environment: ``(env_id, gymnasium.make keywords)``, the training run's
    ``env_kwargs`` when the policy was trained on ``env_id``, with ``overrides`` on top (checked names)."""
    from margin_rl.train.adapters import env_kwargs_for

    run = policy.train_config or {}
    trained_here = run.get("env_id") == env_id and isinstance(run.get("env_kwargs"), dict)
    base = run["env_kwargs"] if trained_here else {}
    return env_id, env_kwargs_for(env_id, {**base, **dict(overrides or {})})


def resolve_env(policy: LoadedPolicy, env_id: str | None, overrides: dict[str, Any] | None) -> tuple[str, EnvConfig]:
    """The ANYmal evaluation environment: the policy's training environment (its run config) unless ``env_id`` is
    given, with EnvConfig field ``overrides`` (see :func:`resolve_gym_env` for the other ids)."""
    from margin_rl.train.adapters import env_config_for
    from margin_rl.train.train import DEFAULT_ENV

    run = policy.train_config
    if run is not None and run.get("env_config") is not None and (env_id is None or env_id == run.get("env_id")):
        env_id = run["env_id"]
        base = from_dict(EnvConfig, run["env_config"], "env_config")
    else:
        env_id = env_id or DEFAULT_ENV
        base = env_config_for(env_id)
    return env_id, apply_overrides(base, dict(overrides or {}))


def default_out_dir(policy_path: Path) -> Path:
    """``<run>/eval/<policy file stem>`` for policies inside a run directory, else next to the file."""
    from margin_rl.train.runs import find_run_config

    config = find_run_config(policy_path, levels=2)
    root = config.parent if config is not None else policy_path.parent
    return root / "eval" / policy_path.stem


def evaluate(
    policy_path: str | Path,
    *,
    env_id: str | None = None,
    env_overrides: dict[str, Any] | None = None,
    episodes: int = 4,
    seed: int = 0,
    forward_velocity: float | None = DEFAULT_FORWARD_VELOCITY,
    warmup_s: float = 1.0,
    out_dir: str | Path | None = None,
    video: bool = False,
    max_steps: int | None = None,
    policy: LoadedPolicy | None = None,
) -> tuple[dict[str, Any], Evaluation]:
    """Evaluate a saved policy; writes ``metrics.json``, ``episode.png`` (and ``episode.mp4``) into ``out_dir``.

    ``env_overrides``: EnvConfig fields (ANYmal ids) or ``gymnasium.make`` keywords (other ids).
    ``forward_velocity`` and ``warmup_s`` apply to ANYmal ids only (see the module docstring).
    Returns the report written to ``metrics.json`` and the :class:`Evaluation`.

    Raises:
        PolicyMismatchError: the policy does not fit the environment.
        ValueError, TypeError: unknown id or options.
    """
    from margin_rl.train.adapters import is_batched_anymal

    policy_path = Path(policy_path)
    policy = policy or load_policy(policy_path)
    target = evaluation_env_id(policy, env_id)
    out = Path(out_dir) if out_dir is not None else default_out_dir(policy_path)
    if not is_batched_anymal(target):
        return _evaluate_gym(policy, policy_path, target, env_overrides, episodes, seed, out, video, max_steps)
    env_id, base = resolve_env(policy, target, env_overrides)
    config = evaluation_config(base, forward_velocity)
    with torch_threads(1):  # see margin_rl.train.runs.torch_threads
        evaluation = run_episodes(policy, config, episodes, seed, warmup_s, render=video, max_steps=max_steps)
    plot = plot_episode(evaluation, out / "episode.png", f"{env_id}: {policy_path.name} ({policy.kind})")
    fps = 1.0 / evaluation.dt
    extra = {"forward_velocity": forward_velocity, "warmup_s": warmup_s, "env_config": to_dict(config)}
    return _finish_report(policy, policy_path, env_id, seed, evaluation, plot, out, fps if video else None, extra)


def _finish_report(
    policy: LoadedPolicy,
    policy_path: Path,
    env_id: str,
    seed: int,
    evaluation: Evaluation,
    plot: Path,
    out: Path,
    video_fps: float | None,
    extra: Mapping[str, Any],
) -> tuple[dict[str, Any], Evaluation]:
    """Write the video (``video_fps`` not None) and ``metrics.json`` of an evaluation; returns (report, it)."""
    video_path, video_message = (None, "")
    if video_fps is not None:
        video_path, video_message = write_video(evaluation.frames, out / "episode.mp4", video_fps)
        video_message = evaluation.render_message or video_message
    report = {
        "policy": str(policy_path),
        "kind": policy.kind,
        "env_id": env_id,
        "seed": seed,
        "episodes": len(evaluation.episodes),
        "dt": evaluation.dt,
        "summary": evaluation.summary,
        "per_episode": evaluation.episodes,
        "plot": plot.name,
        "video": video_path.name if video_path is not None else None,
        "video_message": video_message or None,
        "out_dir": str(out),
        **extra,
    }
    write_json(out / "metrics.json", report)
    return report, evaluation


def _evaluate_gym(
    policy: LoadedPolicy,
    policy_path: Path,
    env_id: str,
    env_overrides: Mapping[str, Any] | None,
    episodes: int,
    seed: int,
    out: Path,
    video: bool,
    max_steps: int | None,
) -> tuple[dict[str, Any], Evaluation]:
    """:func:`evaluate` on a generic (non-ANYmal) environment."""
    env_id, env_kwargs = resolve_gym_env(policy, env_id, env_overrides)
    with torch_threads(1):  # small MLP on one observation at a time: threads only cost
        evaluation = run_gym_episodes(policy, env_id, env_kwargs, episodes, seed, render=video, max_steps=max_steps)
    plot = plot_gym_episode(evaluation, out / "episode.png", f"{env_id}: {policy_path.name} ({policy.kind})")
    fps = (evaluation.fps or 1.0) if video else None
    extra = {"max_steps": max_steps, "env_kwargs": env_kwargs}
    return _finish_report(policy, policy_path, env_id, seed, evaluation, plot, out, fps, extra)


def build_parser() -> argparse.ArgumentParser:
    from margin_rl.train.train import add_env_arguments

    parser = argparse.ArgumentParser(
        prog="margin-rl-evaluate", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("policy", type=Path, help="SB3 .zip, rsl-rl checkpoint .pt or TorchScript .pt")
    add_env_arguments(parser)
    parser.add_argument("--margin-weight", type=float, help="margin reward weight (affects the reported return)")
    parser.add_argument(
        "--episodes", type=int, default=4, help="episodes (ANYmal ids: run in parallel; others: one after another)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the initial states")
    parser.add_argument(
        "--forward-velocity",
        type=float,
        default=None,
        help=f"fixed command [m/s] (ANYmal ids; default {DEFAULT_FORWARD_VELOCITY})",
    )
    parser.add_argument(
        "--warmup-s", type=float, default=1.0, help="seconds left out of acceleration statistics (ANYmal ids)"
    )
    parser.add_argument("--max-steps", type=int, help="cut episodes after this many policy steps")
    parser.add_argument("--out", type=Path, help="output folder (default <run>/eval/<policy name>)")
    parser.add_argument("--video", action="store_true", help="also write episode.mp4 of the first episode")
    return parser


ANYMAL_PRINTED: tuple[str, ...] = (
    "return",
    "velocity_error_mean",
    "lin_acc_rms",
    "ang_acc_rms",
    "stance_width_mean",
    "margin_mean",
    "fell",
)
"""Summary metrics printed by :func:`main` for the ANYmal ids."""


def _generic_printed(summary: Mapping[str, Any]) -> list[str]:
    """Summary metrics printed for a generic environment: return, length, reward terms, terminations."""
    keys = ["return", "length", *(k for k in summary if k.startswith("reward/")), "terminated"]
    return [k for k in keys if k in summary]


def main(argv: list[str] | None = None) -> int:
    """Console entry point; 2 on bad input (missing file, wrong policy for the environment)."""
    from margin_rl.train.train import env_overrides

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    try:
        report, _ = evaluate(
            args.policy,
            env_id=args.env,
            env_overrides=env_overrides(args),
            episodes=args.episodes,
            seed=args.seed,
            forward_velocity=DEFAULT_FORWARD_VELOCITY if args.forward_velocity is None else args.forward_velocity,
            warmup_s=args.warmup_s,
            out_dir=args.out,
            video=args.video,
            max_steps=args.max_steps,
        )
    except (PolicyMismatchError, FileNotFoundError, ValueError, TypeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(report["out_dir"])
    s = report["summary"]
    anymal = "env_config" in report
    if not anymal and args.forward_velocity is not None:
        print(f"note: --forward-velocity applies to ANYmal ids only; ignored for {report['env_id']}", file=sys.stderr)
    print(f"{report['episodes']} episodes of {report['env_id']} with {args.policy} ({report['kind']}):")
    for key in ANYMAL_PRINTED if anymal else _generic_printed(s):
        print(f"  {key:>22}: {s[key]['mean']:.4g} ± {s[key]['std']:.3g}")
    print(f"wrote {out / 'metrics.json'} and {out / report['plot']}")
    if args.video:
        print(f"video: {out / report['video']}" if report["video"] else f"no video: {report['video_message']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
