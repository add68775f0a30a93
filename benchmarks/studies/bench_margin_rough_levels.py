"""Study: the default learned margin against the analytic one on rough-ground states, level by level.

The rough-terrain issue asks, before any rough training, whether the default network is good enough on the states
rough ground produces (≤ 3 cm RMSE and ≥ 95 % sign agreement against the analytic margin) or must be continued on
them. This rolls the shipped flat bundles of a robot (both variants, every seed; blind policies, deterministic
actions, 0.75 m/s) over rough terrains of rising difficulty and compares the default learned margin with the
extended analytic margin m_x (the target the network was trained on) on the visited states.

Levels: the environments' rough terrain at a difficulty (:func:`margin_rl.envs.terrain.at_difficulty`: step heights
and incline scaled by it), 1.0 being seed 000's Fig. 8 scale (steps and bricks 6–18 cm, inclines to 15°); the
terrain curriculum's rows are the same difficulties. Evaluation seed 5000 (the terrain and the initial states), held
out of every labelling. States: every ``--every``-th policy step after the first second, diverged ones left out.

``--record FILE`` instead writes the visited states (npz, key ``lam``), the input of ``dataset generate
--distribution rollouts``; record training states with another ``--seed`` than the evaluation's.

Usage::

    python benchmarks/studies/bench_margin_rough_levels.py --robot anymal_c [--levels 0.25 0.5 0.75 1.0]
        [--bundle-seeds 3 4 | --runs runs/rough/c_mw0_s0 ...] [--weights anymal_c --weights data/candidate.npz]
        [--envs 8] [--steps 250] [--every 5] [--json docs/learned_margin/rough_levels_anymal_c.json]
    python benchmarks/studies/bench_margin_rough_levels.py --robot anymal_c --bundle-seeds 0 1 2 --seed 4000 \
        --levels 0.125 0.25 0.375 0.5 0.625 0.75 0.875 1 --envs 16 --every 1 --record data/rough_anymal_c_train.npz
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

import numpy as np

from benchmarks.harness import run_policies
from margin_rl import load_robot
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.terrain import MIN_SLOPE_DEG, TerrainConfig, at_difficulty
from margin_rl.stability import LAMBDA_SLICES, LearnedMargin
from margin_rl.stability.analytic.extended import extended_margin_batch
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import evaluation_config, resolve_env
from margin_rl.train.runs import torch_threads

EVALUATION_SEED = 5000
RMSE_TARGET_M = 0.03
SIGN_TARGET = 0.95


def visited_states(
    policy_path: Path, level: float, envs: int, steps: int, every: int, seed: int = EVALUATION_SEED
) -> tuple[np.ndarray, float]:
    """(lambda (M, 47), share of episodes that fell) of one policy on the level's terrain (terrain and initial
    states of ``seed``)."""
    policy = load_policy(policy_path)
    overrides = {"margin": "none", "terrain": "rough", "terrain_config": at_difficulty(TerrainConfig(), level)}
    _, base = resolve_env(policy, None, overrides)
    core = AnymalCore(evaluation_config(base, 0.75), num_envs=envs, seed=seed)
    core.reset(seed=seed)
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


def analytic_targets(robot: str, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the states with an extended analytic margin, m_x on them [m])."""
    target = extended_margin_batch(load_robot(robot), lam, workers=2).margin
    ok = np.isfinite(target)
    return lam[ok], target[ok]


LARGEST = 3
"""How many of the largest errors the tail statistics set aside and describe."""


def compare(lam: np.ndarray, target: np.ndarray, weights: LearnedMargin) -> dict[str, Any]:
    """The learned margin against m_x on ``lam``: RMSE, bias, sign agreement, the share outside the training
    ranges, and the tail: median and 95th percentile of |error|, the RMSE without the :data:`LARGEST` largest
    errors, and those states (m_x, the network, the CoM acceleration in the heading frame [m/s²], the contacts)."""
    learned = np.asarray(weights(lam), dtype=float)
    error = learned - target
    magnitude = np.abs(error)
    order = np.argsort(magnitude)
    rest = error[order[:-LARGEST]] if len(error) > LARGEST else error[:0]
    return {
        "states": len(lam),
        "rmse_m": float(np.sqrt(np.mean(error**2))),
        "bias_m": float(np.mean(error)),
        "sign_agreement": float(np.mean(np.sign(learned) == np.sign(target))),
        "out_of_distribution": float(np.mean(weights.out_of_distribution(lam))),
        "analytic_mean_m": float(np.mean(target)),
        "median_abs_error_m": float(np.median(magnitude)),
        "p95_abs_error_m": float(np.percentile(magnitude, 95)),
        f"rmse_without_largest_{LARGEST}_m": float(np.sqrt(np.mean(rest**2))) if rest.size else None,
        "largest": [
            {
                "analytic_m": float(target[i]),
                "learned_m": float(learned[i]),
                "com_acc": [float(v) for v in lam[i, LAMBDA_SLICES["com_acc"]]],
                "contacts": int(np.sum(lam[i, LAMBDA_SLICES["contacts"]] > 0.5)),
            }
            for i in order[::-1][:LARGEST]
        ],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="anymal_c", choices=("anymal_b", "anymal_c"))
    parser.add_argument("--levels", type=float, nargs="+", default=[0.25, 0.5, 0.75, 1.0])
    parser.add_argument("--bundle-seeds", type=int, nargs="+", default=None, help="only these training seeds' policies")
    parser.add_argument(
        "--runs", type=Path, nargs="+", default=None, help="these runs' policies (folders: final_model.pt) instead"
    )
    parser.add_argument("--seed", type=int, default=EVALUATION_SEED, help="terrain and initial states")
    parser.add_argument(
        "--weights", action="append", default=None, help="learned margins to compare (default: the robot's default)"
    )
    parser.add_argument("--envs", type=int, default=8)
    parser.add_argument("--steps", type=int, default=250)
    parser.add_argument("--every", type=int, default=5)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--record", type=Path, default=None, help="write the visited states (npz, key lam); no labels")
    args = parser.parse_args()
    if args.runs is not None:
        if args.bundle_seeds is not None:
            parser.error("--runs and --bundle-seeds choose the policies two ways: give one of them")
        policies = run_policies(parser, args.runs)
        for name, path in policies.items():
            robot = resolve_env(load_policy(path), None, {})[1].robot
            if robot != args.robot:
                parser.error(f"--runs {name} was trained on {robot}, not --robot {args.robot}")
    else:
        bundle = load_bundle(args.robot)
        runs = [r for r in bundle.runs if args.bundle_seeds is None or r.seed in args.bundle_seeds]
        if not runs:
            parser.error(f"no policy of bundle {bundle.name} has a training seed in {args.bundle_seeds}")
        policies = {f"{r.variant} s{r.seed}": Path(r.policy) for r in runs}
    names = args.weights or [args.robot]  # the robot's name: the default network, what the environments use
    networks = {name: LearnedMargin.load(name) for name in names}
    rows, recorded = [], []
    with torch_threads(1):
        for level in args.levels:
            t0 = time.perf_counter()
            states, falls = [], []
            for path in policies.values():
                lam, fell = visited_states(path, level, args.envs, args.steps, args.every, args.seed)
                states.append(lam)
                falls.append(fell)
            lam = np.concatenate(states)
            row: dict = {"level": level, "falls_per_env": float(np.mean(falls)), "visited": len(lam)}
            if args.record is not None:
                recorded.append(lam)
            else:
                lam, target = analytic_targets(args.robot, lam)
                row["networks"] = {}
                for name, network in networks.items():
                    result = compare(lam, target, network)
                    met = result["rmse_m"] <= RMSE_TARGET_M and result["sign_agreement"] >= SIGN_TARGET
                    result["meets_target"] = met
                    row["networks"][name] = result
            row["seconds"] = time.perf_counter() - t0
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.record is not None:
        lam = np.concatenate(recorded)
        args.record.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(args.record, lam=lam.astype(np.float32))
        print(f"{len(lam):,} states: {args.record}")
        return 0
    print(f"\n{args.robot}, learned margins against m_x (seed {args.seed}; policies {', '.join(policies)})\n")
    print(
        "| network | level (Fig. 8 = 1) | states | RMSE [cm] | bias [cm] | sign | outside training ranges "
        f"| median / 95th pct. of abs. error [cm] | RMSE without the {LARGEST} largest [cm] |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, network in networks.items():
        for r in rows:
            n = r["networks"][name]
            print(
                f"| {name} ({str(network.card.get('sha256'))[:8]}) | {r['level']:g} | {n['states']:,} "
                f"| {100 * n['rmse_m']:.1f} | {100 * n['bias_m']:+.1f} | {n['sign_agreement']:.1%} "
                f"| {n['out_of_distribution']:.1%} | {100 * n['median_abs_error_m']:.1f} / "
                f"{100 * n['p95_abs_error_m']:.1f} | {_cm(n[f'rmse_without_largest_{LARGEST}_m'])} |"
            )
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        record = {
            "command": " ".join([Path(sys.executable).name, *sys.argv]),
            "robot": args.robot,
            "weights_sha256": {name: network.card.get("sha256") for name, network in networks.items()},
            "seed": args.seed,
            "policies": list(policies),
            "min_slope_deg": MIN_SLOPE_DEG,
            "targets": {"rmse_m": RMSE_TARGET_M, "sign_agreement": SIGN_TARGET},
            "levels": rows,
        }
        args.json.write_text(json.dumps(record, indent=2) + "\n")
    return 0


def _cm(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.1f}"


if __name__ == "__main__":
    raise SystemExit(main())
