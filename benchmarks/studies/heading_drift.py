"""Study: how far policies turn away from a straight walk under a zero yaw command.

Seed 000's reward tracks the heading velocity alone (the logistic kernel of v_cmd − ẋ in the base frame), so nothing
in it keeps the heading: a policy may track its forward speed perfectly while walking a circle. The velocity error
does not see it; the distance walked does. This rolls policies (deterministic actions, a fixed forward command, yaw
command 0, the evaluation's nominal world) for ``--seconds`` from the evaluation seed and reports, over the
environments that did not fall, the median ratio of the straight-line distance from the start to the path length
walked (1: straight; a circle walked in full: 0) and the mean absolute yaw rate [rad/s].

Policies: a bundle's (``--bundled NAME``, every run by variant and seed) or runs (``--runs RUN ...``). Ground: flat,
or the rough evaluation terrain at ``--terrain-difficulty D``.

Usage::

    python benchmarks/studies/heading_drift.py --bundled anymal_c [--speeds 0.5 0.75] [--seconds 10]
    python benchmarks/studies/heading_drift.py --runs runs/rough_pilot/c_mw0_s0 --terrain-difficulty 0.125
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks
sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_margin_rough_levels: the evaluation seed

import numpy as np
from bench_margin_rough_levels import EVALUATION_SEED

from benchmarks.harness import run_policies, write_record
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.terrain import TerrainConfig, at_difficulty
from margin_rl.robot import mjcf_names as names
from margin_rl.train.analysis.conditions import condition_config
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import evaluation_config, resolve_env
from margin_rl.train.runs import torch_threads


def straightness(policy_path: Path, speed: float, seconds: float, envs: int, difficulty: float | None) -> dict:
    """Median (distance from the start / path length) and mean |yaw rate| over the environments that did not
    fall, and how many fell."""
    policy = load_policy(policy_path)
    overrides = (
        {} if difficulty is None else {"terrain": "rough", "terrain_config": at_difficulty(TerrainConfig(), difficulty)}
    )
    _, config = resolve_env(policy, None, overrides)
    config = evaluation_config(condition_config(config, "nominal"), speed)
    core = AnymalCore(config, num_envs=envs, seed=EVALUATION_SEED, autoreset=False)
    core.reset(seed=EVALUATION_SEED)
    xy = lambda: np.array(core.physics.qpos[:, names.BASE_POSITION_QPOS][:, :2])  # noqa: E731
    start, previous = xy(), xy()
    standing, path, yaw = np.ones(envs, bool), np.zeros(envs), np.zeros(envs)
    obs = core.observe_all()
    steps = round(seconds / core.dt)
    for _ in range(steps):
        out = core.step(policy(obs))
        obs = out.observation
        standing &= ~out.terminated
        now = xy()
        path += np.where(standing, np.linalg.norm(now - previous, axis=1), 0.0)
        yaw += np.abs(np.asarray(core.physics.qvel[:, names.BASE_QVEL])[:, 5]) / steps  # body-frame z (free joint)
        previous = now
    distance = np.linalg.norm(xy() - start, axis=1)
    kept = standing & (path > 0)
    return {
        "environments": envs,
        "fell": int((~standing).sum()),
        "straightness_median": float(np.median(distance[kept] / path[kept])) if kept.any() else None,
        "path_m_median": float(np.median(path[kept])) if kept.any() else None,
        "yaw_rate_abs_mean": float(np.mean(yaw[kept])) if kept.any() else None,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--bundled", help="a bundle's policies")
    source.add_argument("--runs", type=Path, nargs="+", help="runs (folders: final_model.pt) or policy files")
    parser.add_argument("--speeds", type=float, nargs="+", default=[0.5, 0.75])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--terrain-difficulty", type=float, default=None, help="rough evaluation terrain (else flat)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    if args.bundled:
        policies = {f"{r.variant} s{r.seed}": Path(r.policy) for r in load_bundle(args.bundled).runs}
    else:
        policies = run_policies(parser, args.runs)
    t0, rows = time.perf_counter(), []
    with torch_threads(1):
        for name, path in policies.items():
            for speed in args.speeds:
                row = {"policy": name, "speed": speed, **straightness(path, speed, args.seconds, args.envs,
                                                                     args.terrain_difficulty)}  # fmt: skip
                rows.append(row)
    ground = "flat" if args.terrain_difficulty is None else f"rough, difficulty {args.terrain_difficulty:g}"
    print(f"\nheading drift under a zero yaw command ({ground}, {args.seconds:g} s, {args.envs} environments)\n")
    print("| policy | command [m/s] | fell | distance / path (median) | path [m] | mean abs. yaw rate [rad/s] |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        if r["straightness_median"] is None:
            print(f"| {r['policy']} | {r['speed']:g} | {r['fell']} | – | – | – |")
            continue
        print(
            f"| {r['policy']} | {r['speed']:g} | {r['fell']} | {r['straightness_median']:.2f} "
            f"| {r['path_m_median']:.1f} | {r['yaw_rate_abs_mean']:.2f} |"
        )
    print(f"({time.perf_counter() - t0:.0f} s)")
    write_record(args.json, "heading_drift", args, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
