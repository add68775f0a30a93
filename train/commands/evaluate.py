"""``evaluate``: deterministic episodes of a saved policy, with metrics JSON, plots and an optional MP4.

Examples::

    python -m margin_rl.train evaluate runs/<run>/final_model.pt            # rsl-rl checkpoint
    python -m margin_rl.train evaluate runs/<run>/final_model.zip --episodes 8   # SB3 (unpickles: trusted files only)
    python -m margin_rl.train evaluate runs/<run>/policy_torchscript.pt --video
    python -m margin_rl.train evaluate policy.pt --env margin_rl/AnymalC-v1 --forward-velocity 1.0
    python -m margin_rl.train evaluate runs/<slip run>/final_model.zip --env-option goal_velocity=0.5

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
numeric ``info`` values (:class:`margin_rl.train.metrics.InfoEpisodeStatistics`), ``episode.png`` the reward
terms and observations over the first episode, and ``--video`` replays that episode with
``render_mode="rgb_array"`` where the environment offers it (the metrics never come from a rendered run: some
environments, SLIPHopper among them, simulate slightly differently while recording). ``--forward-velocity`` and
``--warmup-s`` apply to ANYmal only.

A metric that no episode could give (e.g. the acceleration RMS when every episode ended within ``--warmup-s``)
is printed as "not computed" with the reason, and ``metrics.json`` holds it as ``null`` in ``summary`` with
its reason in ``"not_computed": {metric: reason}`` (present only when some metric is not computed).

The episodes themselves run in :mod:`margin_rl.train.analysis.episodes`; plots and video are
:mod:`margin_rl.train.analysis.media`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from margin_rl.envs.config import CommandConfig, EnvConfig
from margin_rl.train.analysis.episodes import Evaluation, run_episodes
from margin_rl.train.analysis.media import plot_episode, write_video
from margin_rl.train.artifacts.policies import LoadedPolicy, PolicyMismatchError, load_policy
from margin_rl.train.commands.options import add_env_arguments, env_overrides
from margin_rl.train.config import apply_overrides, from_dict, to_dict
from margin_rl.train.environments import (
    DEFAULT_ENV,
    AnymalTarget,
    EnvTarget,
    GymTarget,
    env_config_for,
    env_kwargs_for,
    is_batched_anymal,
)
from margin_rl.train.runs import find_run_config, torch_threads, write_json

DEFAULT_FORWARD_VELOCITY = 0.75  # m/s, seed 000 §V-C



def evaluation_config(config: EnvConfig, forward_velocity: float | None) -> EnvConfig:
    """``config`` with a fixed heading-velocity command (no lateral velocity, no yaw rate)."""
    if forward_velocity is None:
        return config
    v = float(forward_velocity)
    return config.replace(
        command=CommandConfig(forward_velocity=(v, v), lateral_velocity=(0.0, 0.0), yaw_rate=(0.0, 0.0))
    )


def evaluation_env_id(policy: LoadedPolicy, env_id: str | None) -> str:
    """``env_id``, else the policy's training environment (its run config), else :data:`DEFAULT_ENV`."""
    run = policy.train_config or {}
    return env_id or run.get("env_id") or DEFAULT_ENV


def resolve_gym_env(
    policy: LoadedPolicy, env_id: str, overrides: Mapping[str, Any] | None
) -> tuple[str, dict[str, Any]]:
    """A generic (non-ANYmal) evaluation environment: ``(env_id, gymnasium.make keywords)``, the training run's
    ``env_kwargs`` when the policy was trained on ``env_id``, with ``overrides`` on top (checked names)."""
    run = policy.train_config or {}
    trained_here = run.get("env_id") == env_id and isinstance(run.get("env_kwargs"), dict)
    base = run["env_kwargs"] if trained_here else {}
    return env_id, env_kwargs_for(env_id, {**base, **dict(overrides or {})})


def resolve_env(policy: LoadedPolicy, env_id: str | None, overrides: dict[str, Any] | None) -> tuple[str, EnvConfig]:
    """The ANYmal evaluation environment: the policy's training environment (its run config) unless ``env_id`` is
    given, with EnvConfig field ``overrides`` (see :func:`resolve_gym_env` for the other ids)."""
    run = policy.train_config
    if run is not None and run.get("env_config") is not None and (env_id is None or env_id == run.get("env_id")):
        env_id = run["env_id"]
        base = from_dict(EnvConfig, run["env_config"], "env_config")
    else:
        env_id = env_id or DEFAULT_ENV
        base = env_config_for(env_id)
    return env_id, apply_overrides(base, dict(overrides or {}))


def evaluation_target(
    policy: LoadedPolicy,
    env_id: str | None,
    overrides: Mapping[str, Any] | None,
    forward_velocity: float | None = DEFAULT_FORWARD_VELOCITY,
) -> EnvTarget:
    """The environment to evaluate ``policy`` in (see the module docstring): ANYmal with the fixed command
    ``forward_velocity`` (:func:`evaluation_config`), or generic (:func:`resolve_gym_env`).

    Raises:
        ValueError, TypeError: unknown id or options.
    """
    target = evaluation_env_id(policy, env_id)
    if not is_batched_anymal(target):
        return GymTarget(*resolve_gym_env(policy, target, overrides))
    env_id, base = resolve_env(policy, target, dict(overrides or {}))
    return AnymalTarget(env_id, evaluation_config(base, forward_velocity))


def default_out_dir(policy_path: Path) -> Path:
    """``<run>/eval/<policy file stem>`` for policies inside a run directory, else next to the file."""
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
    policy_path = Path(policy_path)
    policy = policy or load_policy(policy_path)
    target = evaluation_target(policy, env_id, env_overrides, forward_velocity)
    out = Path(out_dir) if out_dir is not None else default_out_dir(policy_path)
    with torch_threads(1):  # see margin_rl.train.runs.torch_threads
        evaluation = run_episodes(policy, target, episodes, seed, warmup_s, render=video, max_steps=max_steps)
    title = f"{target.env_id}: {policy_path.name} ({policy.kind})"
    plot = plot_episode(evaluation, out / "episode.png", title)
    if target.is_anymal:
        fps = 1.0 / evaluation.dt
        extra = {"forward_velocity": forward_velocity, "warmup_s": warmup_s, "env_config": to_dict(target.config)}
    else:
        fps = evaluation.fps or 1.0
        extra = {"max_steps": max_steps, "env_kwargs": dict(target.kwargs)}
    video_path, video_message = (None, "")
    if video:
        video_path, video_message = write_video(evaluation.frames, out / "episode.mp4", fps)
        video_message = evaluation.render_message or video_message
    report = {
        "policy": str(policy_path),
        "kind": policy.kind,
        "env_id": target.env_id,
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
    if evaluation.not_computed:
        report["not_computed"] = evaluation.not_computed
    write_json(out / "metrics.json", report)
    return report, evaluation


def build_parser() -> argparse.ArgumentParser:
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


def summary_line(stats: Mapping[str, Any], episodes: int, reason: str | None = None) -> str:
    """``mean ± std`` of a summary entry; "not computed (reason)" when no episode gave a value; the number of
    episodes that gave one when some could not."""
    if reason is not None or not stats.get("count"):
        return f"not computed ({reason or 'no episode reported a finite value'})"
    line = f"{stats['mean']:.4g} ± {stats['std']:.3g}"
    return line if stats["count"] == episodes else f"{line} (over {stats['count']} of {episodes} episodes)"


def main(argv: list[str] | None = None) -> int:
    """Console entry point; 2 on bad input (missing file, wrong policy for the environment)."""
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
        print(f"  {key:>22}: {summary_line(s[key], report['episodes'], report.get('not_computed', {}).get(key))}")
    print(f"wrote {out / 'metrics.json'} and {out / report['plot']}")
    if args.video:
        print(f"video: {out / report['video']}" if report["video"] else f"no video: {report['video_message']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
