"""Experiment: does the stability margin ask a walking policy for a narrower or a wider stance?

Usage:
    python benchmarks/studies/bench_margin_stance_width.py --bundle docs/comparison/robust_sweep/bundles/robust_ft_b \\
        [--variant "without margin"] [--forward-velocity 0.5] [--scales 0.85 0.9 1.0 1.1 1.15] [--workers 2]

The states one variant's policies visit (deterministic rollouts of every policy of the variant in the bundle, the
nominal world, as ``bench_margin_on_trajectories.py``) are copied with the feet moved sideways: in the heading frame
H each foot's lateral coordinate y_i becomes y_mid + s (y_i - y_mid), y_mid the mean of the four feet's y, so the
stance width scales by s and nothing else in lambda changes (CoM, velocities, accelerations, contacts, normals).
Each copy is labelled with the analytic margin (contact problem with the robot's torque limits at the moved feet)
and the learned margin the bundle's policies were trained with. The output: per scale, the mean margin over the
states whose analytic margin exists at every scale, its change against s = 1, and the share of states whose
margin rises; for both margins. A margin that rises as s falls rewards a narrower stance.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.*

import numpy as np

from benchmarks.studies.bench_margin_on_trajectories import visited_states
from margin_rl.stability import LAMBDA_SLICES
from margin_rl.stability.analytic.margin import STATUSES, analytic_margin_batch
from margin_rl.stability.learned.model import LearnedMargin
from margin_rl.train.artifacts.bundle import load_bundle


def with_stance_scaled(lam: np.ndarray, scale: float) -> np.ndarray:
    """lambda (N, 47) with each foot's lateral (H-frame y) offset from the feet's mean y scaled by ``scale``."""
    out = lam.copy()
    feet = out[:, LAMBDA_SLICES["feet"]].reshape(-1, 4, 3)
    middle = feet[:, :, 1].mean(axis=1, keepdims=True)
    feet[:, :, 1] = middle + scale * (feet[:, :, 1] - middle)
    out[:, LAMBDA_SLICES["feet"]] = feet.reshape(-1, 12)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bundle", required=True)
    parser.add_argument("--variant", default="without margin", help="whose states: a variant of the bundle")
    parser.add_argument("--forward-velocity", type=float, default=0.5)
    parser.add_argument("--scales", type=float, nargs="+", default=[0.85, 0.9, 1.0, 1.1, 1.15])
    parser.add_argument("--envs", type=int, default=8)
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--every", type=int, default=5)
    parser.add_argument("--seed", type=int, default=2000)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    if 1.0 not in args.scales:
        parser.error("--scales must include 1.0 (the states as visited)")
    bundle = load_bundle(args.bundle)
    runs = [run for run in bundle.runs if run.variant == args.variant]
    if not runs:
        parser.error(
            f"--variant {args.variant!r}: the bundle's variants are {sorted({r.variant for r in bundle.runs})}"
        )
    t0 = time.perf_counter()
    robot, parts = "", []
    for run in runs:
        robot, lam = visited_states(run.policy, args.envs, args.steps, args.every, args.forward_velocity, args.seed)
        parts.append(lam)
    lam = np.concatenate(parts)
    model = LearnedMargin.load(str(bundle.margin_weights))
    analytic, learned = {}, {}
    ok = np.ones(len(lam), dtype=bool)
    for scale in args.scales:
        scaled = with_stance_scaled(lam, scale)
        labels = analytic_margin_batch(robot, scaled, workers=args.workers)
        ok &= labels.status == STATUSES.index("ok")
        analytic[scale], learned[scale] = labels.margin, np.asarray(model(scaled), dtype=float)
    print(
        f"bundle {bundle.name}, {args.variant!r} ({len(runs)} policies) at {args.forward_velocity:g} m/s: "
        f"{len(lam):,} states, {ok.sum():,} with an analytic margin at every scale; {time.perf_counter() - t0:.0f} s"
    )
    print("| stance scale | analytic mean [m] | change [cm] | rises | learned mean [m] | change [cm] | rises |")
    print("|---|---|---|---|---|---|---|")
    for scale in args.scales:
        a, a1 = analytic[scale][ok], analytic[1.0][ok]
        m, m1 = learned[scale][ok], learned[1.0][ok]
        print(
            f"| {scale:g} | {a.mean():.4f} | {100 * (a - a1).mean():+.2f} | {np.mean(a > a1):.0%} | "
            f"{m.mean():.4f} | {100 * (m - m1).mean():+.2f} | {np.mean(m > m1):.0%} |"
        )


if __name__ == "__main__":
    main()
