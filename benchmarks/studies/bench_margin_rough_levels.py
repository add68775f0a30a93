"""Study: the default learned margin against the analytic one on rough-ground states, level by level.

The rough-terrain issue asks, before any rough training, whether the default network is good enough on the states
rough ground produces (≤ 3 cm RMSE and ≥ 95 % sign agreement against the analytic margin) or must be continued on
them. This rolls the shipped flat bundles of a robot (both variants, every seed; blind policies, deterministic
actions, 0.75 m/s) over rough terrains of rising difficulty and compares the default learned margin with the
extended analytic margin m_x (the target the network was trained on) on the visited states.

Levels: the environments' rough terrain (``TerrainConfig``) with its step heights and incline scaled by the level,
1.0 being seed 000's Fig. 8 scale (steps and bricks 6–18 cm, inclines to 15°); a provisional scale until the
curriculum defines its rows. Evaluation seed 5000 (the terrain and the initial states), held out of every
labelling. States: every ``--every``-th policy step after the first second, diverged ones left out.

Usage::

    python benchmarks/studies/bench_margin_rough_levels.py --robot anymal_c [--levels 0.25 0.5 0.75 1.0]
        [--envs 8] [--steps 250] [--every 5] [--json docs/learned_margin/rough_levels_anymal_c.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

import numpy as np

from margin_rl import load_robot
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.terrain import MIN_SLOPE_DEG, TerrainConfig
from margin_rl.stability import LearnedMargin
from margin_rl.stability.analytic.extended import extended_margin_batch
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import evaluation_config, resolve_env
from margin_rl.train.runs import torch_threads

EVALUATION_SEED = 5000
RMSE_TARGET_M = 0.03
SIGN_TARGET = 0.95


def level_terrain(level: float, base: TerrainConfig = TerrainConfig()) -> TerrainConfig:  # noqa: B008
    """The rough terrain with step heights and incline scaled by ``level`` (1: Fig. 8's 6-18 cm, 15 degrees)."""
    low, high = base.step_height
    return dataclasses.replace(
        base, step_height=(low * level, high * level), max_slope_deg=max(base.max_slope_deg * level, 0.1)
    )


def visited_states(policy_path: Path, level: float, envs: int, steps: int, every: int) -> tuple[np.ndarray, float]:
    """(lambda (M, 47), share of episodes that fell) of one policy on the level's terrain."""
    policy = load_policy(policy_path)
    overrides = {"margin": "none", "terrain": "rough", "terrain_config": level_terrain(level)}
    _, base = resolve_env(policy, None, overrides)
    core = AnymalCore(evaluation_config(base, 0.75), num_envs=envs, seed=EVALUATION_SEED)
    core.reset(seed=EVALUATION_SEED)
    obs = core.observe_all()
    kept, falls = [], 0
    warmup = round(1.0 / core.dt)
    for step in range(steps):
        out = core.step(policy(obs))
        obs = out.observation
        falls += int(out.info["fell"].sum())
        if step >= warmup and step % every == 0:
            finite = out.info["diverged"] == 0
            kept.append(out.info["lambda"][finite])
    return np.concatenate(kept), falls / envs


def compare(robot: str, lam: np.ndarray, weights: LearnedMargin) -> dict[str, float]:
    """The learned margin against m_x on ``lam``: RMSE, bias, sign agreement, the share outside the training
    ranges."""
    target = extended_margin_batch(load_robot(robot), lam, workers=2).margin
    ok = np.isfinite(target)
    learned = np.asarray(weights(lam[ok]))
    error = learned - target[ok]
    return {
        "states": int(ok.sum()),
        "rmse_m": float(np.sqrt(np.mean(error**2))),
        "bias_m": float(np.mean(error)),
        "sign_agreement": float(np.mean(np.sign(learned) == np.sign(target[ok]))),
        "out_of_distribution": float(np.mean(weights.out_of_distribution(lam[ok]))),
        "analytic_mean_m": float(np.mean(target[ok])),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="anymal_c", choices=("anymal_b", "anymal_c"))
    parser.add_argument("--levels", type=float, nargs="+", default=[0.25, 0.5, 0.75, 1.0])
    parser.add_argument("--envs", type=int, default=8)
    parser.add_argument("--steps", type=int, default=250)
    parser.add_argument("--every", type=int, default=5)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    bundle = load_bundle(args.robot)
    weights = LearnedMargin.load(args.robot)  # the default network, what the environments use
    rows = []
    with torch_threads(1):
        for level in args.levels:
            t0 = time.perf_counter()
            states, falls = [], []
            for run in bundle.runs:
                lam, fell = visited_states(run.policy, level, args.envs, args.steps, args.every)
                states.append(lam)
                falls.append(fell)
            result = compare(args.robot, np.concatenate(states), weights)
            row = {"level": level, "falls_per_env": float(np.mean(falls)), **result}
            row["meets_target"] = row["rmse_m"] <= RMSE_TARGET_M and row["sign_agreement"] >= SIGN_TARGET
            row["seconds"] = time.perf_counter() - t0
            rows.append(row)
            print(json.dumps(row), flush=True)
    print(f"\n{args.robot}, default learned margin (sha256 {str(weights.card.get('sha256'))[:12]}) against m_x\n")
    print("| level (Fig. 8 = 1) | states | RMSE [cm] | bias [cm] | sign agreement | outside training ranges |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['level']:g} | {r['states']:,} | {100 * r['rmse_m']:.1f} | {100 * r['bias_m']:+.1f} "
            f"| {r['sign_agreement']:.1%} | {r['out_of_distribution']:.1%} |"
        )
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        record = {
            "command": " ".join([Path(sys.executable).name, *sys.argv]),
            "robot": args.robot,
            "weights_sha256": weights.card.get("sha256"),
            "evaluation_seed": EVALUATION_SEED,
            "min_slope_deg": MIN_SLOPE_DEG,
            "targets": {"rmse_m": RMSE_TARGET_M, "sign_agreement": SIGN_TARGET},
            "levels": rows,
        }
        args.json.write_text(json.dumps(record, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
