"""Study: what the terrain normals in lambda do to the margin on the states policies visit on rough ground.

Seed 000's margin takes each foot's terrain normal (λ's ``normals``): the friction cones stand on it, and the Feasible
Region differs from the support polygon exactly where the contacts are not coplanar. The policies never observe the
margin, so the normals' role is measured on the margin itself: roll policies over a rough terrain, and on each visited
state compare the extended analytic margin m_x (what the learned margin approximates, and what the reward's margin
stands for) with m_x of the same state with every normal set to vertical (0, 0, 1 in the horizontal frame H: flat
ground's normals). States whose stance feet all stand on level ground do not change by construction; the figures are
given over every state and over the *tilted* ones (a stance foot's normal more than ``--tilt-deg`` from vertical).

Reported per terrain difficulty: states, the share that are tilted, and over the tilted ones the margin change
m_x(vertical) − m_x(terrain) (mean, RMS, 5th/95th percentiles) and the share whose sign flips. Policies: a bundle's
(``--bundled NAME``, its variants by name) or runs (``--variant NAME RUN ...``, repeatable); the terrain and initial
states of the evaluation seed 5000, deterministic actions at 0.75 m/s (``visited_states`` of
``bench_margin_rough_levels.py``).

Usage::

    python benchmarks/studies/bench_terrain_normals.py --bundled anymal_c --levels 0.5 1.0 [--envs 8] [--steps 250]
    python benchmarks/studies/bench_terrain_normals.py --variant "with margin" runs/r/c_mw0.1_s0 \\
        --variant "without margin" runs/r/c_mw0_s0 --levels 0.5 0.75 --json docs/comparison/terrain_normals_c.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks
sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_margin_rough_levels: the visited states

import numpy as np
from bench_margin_rough_levels import EVALUATION_SEED, visited_states

from benchmarks.harness import run_policies, write_record
from margin_rl import load_robot
from margin_rl.stability.analytic.extended import extended_margin_batch
from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES, N_FEET
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import resolve_env
from margin_rl.train.runs import torch_threads

VERTICAL = np.array([0.0, 0.0, 1.0])


def with_vertical_normals(lam: np.ndarray) -> np.ndarray:
    """A copy of states ``lam`` (M, 47) with every foot's terrain normal set to vertical (H frame)."""
    flat = np.array(lam, dtype=np.float64, copy=True)
    flat[:, LAMBDA_SLICES["normals"]] = np.tile(VERTICAL, N_FEET)
    return flat


def tilted(lam: np.ndarray, tilt_deg: float) -> np.ndarray:
    """(M,) states with a stance foot (contact flag set) whose normal is more than ``tilt_deg`` from vertical."""
    normals = lam[:, LAMBDA_SLICES["normals"]].reshape(-1, N_FEET, 3)
    stance = lam[:, LAMBDA_SLICES["contacts"]] > 0.5
    off_vertical = normals[..., 2] < np.cos(np.radians(tilt_deg))
    return np.any(stance & off_vertical, axis=1)


def normals_effect(robot: str, lam: np.ndarray, tilt_deg: float) -> dict[str, float]:
    """m_x with the terrain's normals and with vertical ones on ``lam``: the change over the tilted states."""
    model = load_robot(robot)
    terrain = extended_margin_batch(model, lam, workers=2).margin
    vertical = extended_margin_batch(model, with_vertical_normals(lam), workers=2).margin
    both = np.isfinite(terrain) & np.isfinite(vertical)
    on_tilt = both & tilted(lam, tilt_deg)
    change = (vertical - terrain)[on_tilt]
    result = {"states": int(both.sum()), "tilted_share": float(on_tilt.sum() / max(both.sum(), 1))}
    if change.size:
        result.update(
            change_mean_m=float(change.mean()),
            change_rms_m=float(np.sqrt(np.mean(change**2))),
            change_p5_m=float(np.percentile(change, 5)),
            change_p95_m=float(np.percentile(change, 95)),
            sign_flip_share=float(np.mean(np.sign(vertical[on_tilt]) != np.sign(terrain[on_tilt]))),
            margin_mean_m=float(terrain[on_tilt].mean()),
        )
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--bundled", help="a bundle's policies, by variant")
    source.add_argument("--variant", nargs="+", action="append", metavar=("NAME", "RUN"), help="a variant's runs")
    parser.add_argument("--levels", type=float, nargs="+", default=[0.5, 1.0])
    parser.add_argument("--seed", type=int, default=EVALUATION_SEED, help="terrain and initial states")
    parser.add_argument("--tilt-deg", type=float, default=1.0, help="a normal further than this from vertical tilts")
    parser.add_argument("--envs", type=int, default=8)
    parser.add_argument("--steps", type=int, default=250)
    parser.add_argument("--every", type=int, default=5)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    if args.bundled:
        bundle = load_bundle(args.bundled)
        variants: dict[str, list[Path]] = {}
        for run in bundle.runs:
            variants.setdefault(run.variant, []).append(Path(run.policy))
    else:
        variants = {}
        for name, *runs in args.variant:
            if not runs:
                parser.error(f"--variant {name!r} names no run")
            variants[name] = list(run_policies(parser, runs).values())
    robots = {resolve_env(load_policy(p), None, {})[1].robot for policies in variants.values() for p in policies}
    if len(robots) != 1:
        parser.error(f"the policies were trained on different robots {sorted(robots)}; study one robot at a time")
    robot = robots.pop()
    rows = []
    with torch_threads(1):
        for level in args.levels:
            for name, policies in variants.items():
                t0 = time.perf_counter()
                lam = np.concatenate(
                    [visited_states(p, level, args.envs, args.steps, args.every, args.seed)[0] for p in policies]
                )
                row = {"level": level, "variant": name, **normals_effect(robot, lam, args.tilt_deg)}
                row["seconds"] = time.perf_counter() - t0
                rows.append(row)
                print(json.dumps(row), flush=True)
    print(
        f"\n{robot}: m_x with vertical normals − with the terrain's, over states with a stance foot tilted > "
        f"{args.tilt_deg:g}° (seed {args.seed})\n"
    )
    print("| difficulty | variant | states | tilted | change mean [cm] | RMS [cm] | 5th–95th pct [cm] | sign flips |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "change_mean_m" not in r:
            print(f"| {r['level']:g} | {r['variant']} | {r['states']:,} | 0 | | | | |")
            continue
        print(
            f"| {r['level']:g} | {r['variant']} | {r['states']:,} | {r['tilted_share']:.0%} "
            f"| {100 * r['change_mean_m']:+.1f} | {100 * r['change_rms_m']:.1f} "
            f"| {100 * r['change_p5_m']:+.1f} to {100 * r['change_p95_m']:+.1f} | {r['sign_flip_share']:.1%} |"
        )
    variants_run = {k: [str(p) for p in v] for k, v in variants.items()}
    write_record(args.json, "terrain_normals", args, {"robot": robot, "variants": variants_run, "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
