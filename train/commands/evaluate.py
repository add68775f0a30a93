"""``evaluate``: deterministic episodes of a saved policy, with metrics JSON, plots and an optional MP4.

Examples::

    python -m margin_rl.train evaluate runs/<run>/final_model.pt            # rsl-rl checkpoint
    python -m margin_rl.train evaluate runs/<run>/final_model.zip --episodes 8   # SB3 (unpickles: trusted files only)
    python -m margin_rl.train evaluate runs/<run>/policy_torchscript.pt --video
    python -m margin_rl.train evaluate policy.pt --env margin_rl/AnymalC-v1 --forward-velocity 1.0

The environment, a batched ANYmal id, is the policy's training environment (its run's ``config.json``) unless
``--env`` or environment options (EnvConfig fields, as for ``train``) say otherwise; any other id is an error
(:func:`margin_rl.train.environments.anymal_id`).

The command is fixed (``--forward-velocity``, default 0.75 m/s as in seed
000 §V-C), and the world is an evaluation condition (``--condition``, default ``nominal``: the training
environment without its friction, mass, push and observation-noise randomisation;
:mod:`margin_rl.train.analysis.conditions`); environment options given apply on top of the condition. Episodes
run in parallel from ``--seed``, each to its first termination or time limit. Outputs
(default ``<run>/eval/``): ``metrics.json`` (every episode's metrics, see :mod:`margin_rl.train.metrics`, and
their mean/std), ``episode.png`` (base accelerations, velocity, margin and stance width over the first episode)
and, with ``--video``, ``episode.mp4`` of the first episode (needs imageio with its ffmpeg plugin and a GL
backend, e.g. ``MUJOCO_GL=egl``).

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
from margin_rl.train.analysis.conditions import CONDITIONS, DEFAULT_CONDITION, condition_config
from margin_rl.train.analysis.episodes import Evaluation, run_episodes
from margin_rl.train.analysis.media import plot_episode, write_video
from margin_rl.train.artifacts.policies import LoadedPolicy, PolicyMismatchError, load_policy
from margin_rl.train.commands.options import add_env_arguments, env_overrides
from margin_rl.train.config import apply_overrides, from_dict, to_dict
from margin_rl.train.environments import DEFAULT_ENV, AnymalTarget, anymal_id, env_config_for
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


def resolve_env(
    policy: LoadedPolicy,
    env_id: str | None,
    overrides: dict[str, Any] | None,
    condition: str = DEFAULT_CONDITION,
) -> tuple[str, EnvConfig]:
    """The evaluation environment: the policy's training environment (its run config) unless ``env_id`` is
    given, in evaluation ``condition`` (:func:`~margin_rl.train.analysis.conditions.condition_config`), with
    EnvConfig field ``overrides`` on top.

    Raises:
        ValueError: an unknown condition.
    """
    run = policy.train_config
    if run is not None and run.get("env_config") is not None and (env_id is None or env_id == run.get("env_id")):
        env_id = run["env_id"]
        base = from_dict(EnvConfig, run["env_config"], "env_config")
    else:
        env_id = env_id or DEFAULT_ENV
        base = env_config_for(env_id)
    return env_id, apply_overrides(condition_config(base, condition), dict(overrides or {}))


def evaluation_target(
    policy: LoadedPolicy,
    env_id: str | None,
    overrides: Mapping[str, Any] | None,
    forward_velocity: float | None = DEFAULT_FORWARD_VELOCITY,
    condition: str = DEFAULT_CONDITION,
) -> AnymalTarget:
    """The environment to evaluate ``policy`` in (see the module docstring): evaluation ``condition``, the fixed
    command ``forward_velocity`` (:func:`evaluation_config`).

    Raises:
        ValueError: not a batched ANYmal id, an unknown condition. TypeError: unknown options.
    """
    target = evaluation_env_id(policy, env_id)
    anymal_id(target, "evaluate")
    env_id, base = resolve_env(policy, target, dict(overrides or {}), condition)
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
    condition: str = DEFAULT_CONDITION,
) -> tuple[dict[str, Any], Evaluation]:
    """Evaluate a saved policy; writes ``metrics.json``, ``episode.png`` (and ``episode.mp4``) into ``out_dir``.

    ``env_overrides``: EnvConfig fields, on top of evaluation ``condition``
    (:mod:`margin_rl.train.analysis.conditions`). Returns the report written to ``metrics.json`` and the
    :class:`Evaluation`.

    Raises:
        PolicyMismatchError: the policy does not fit the environment.
        ValueError, TypeError: unknown id or options.
    """
    policy_path = Path(policy_path)
    policy = policy or load_policy(policy_path)
    target = evaluation_target(policy, env_id, env_overrides, forward_velocity, condition)
    out = Path(out_dir) if out_dir is not None else default_out_dir(policy_path)
    with torch_threads(1):  # see margin_rl.train.runs.torch_threads
        evaluation = run_episodes(policy, target, episodes, seed, warmup_s, render=video, max_steps=max_steps)
    title = f"{target.env_id}: {policy_path.name} ({policy.kind})"
    plot = plot_episode(evaluation, out / "episode.png", title)
    video_path, video_message = (None, "")
    if video:
        video_path, video_message = write_video(evaluation.frames, out / "episode.mp4", 1.0 / evaluation.dt)
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
        "forward_velocity": forward_velocity,
        "condition": condition,
        "warmup_s": warmup_s,
        "env_config": to_dict(target.config),
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
    parser.add_argument("--episodes", type=int, default=4, help="episodes (run in parallel)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the initial states")
    parser.add_argument(
        "--forward-velocity",
        type=float,
        default=None,
        help=f"fixed command [m/s] (default {DEFAULT_FORWARD_VELOCITY})",
    )
    parser.add_argument(
        "--condition",
        choices=tuple(CONDITIONS),
        default=DEFAULT_CONDITION,
        help=f"evaluation world (default {DEFAULT_CONDITION}: no training randomisation; "
        "margin_rl.train.analysis.conditions)",
    )
    parser.add_argument("--warmup-s", type=float, default=1.0, help="seconds left out of acceleration statistics")
    parser.add_argument("--max-steps", type=int, help="cut episodes after this many policy steps")
    parser.add_argument("--out", type=Path, help="output folder (default <run>/eval/<policy name>)")
    parser.add_argument("--video", action="store_true", help="also write episode.mp4 of the first episode")
    return parser


PRINTED_METRICS: tuple[str, ...] = (
    "return",
    "velocity_error_mean",
    "lin_acc_rms",
    "ang_acc_rms",
    "stance_width_mean",
    "base_height_mean",
    "edge_landing_fraction",
    "margin_mean",
    "fell",
)
"""Summary metrics printed by :func:`main`."""


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
            condition=args.condition,
        )
    except (PolicyMismatchError, FileNotFoundError, ValueError, TypeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(report["out_dir"])
    s = report["summary"]
    print(f"{report['episodes']} episodes of {report['env_id']} with {args.policy} ({report['kind']}):")
    for key in PRINTED_METRICS:
        print(f"  {key:>22}: {summary_line(s[key], report['episodes'], report.get('not_computed', {}).get(key))}")
    print(f"wrote {out / 'metrics.json'} and {out / report['plot']}")
    if args.video:
        print(f"video: {out / report['video']}" if report["video"] else f"no video: {report['video_message']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
