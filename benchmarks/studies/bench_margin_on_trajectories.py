"""Experiment: learned vs analytic margin on the states that trained policies actually visit.

Usage:
    python benchmarks/studies/bench_margin_on_trajectories.py [--bundle anymal_b] [--envs 8] [--steps 500]
        [--every 5] [--forward-velocity 0.75] [--seed 2000] [--weights PATH_OR_ROBOT ...] [--workers 2]

The held-out test split of a model card measures the learned margin on Table I samples; a policy walks in
a narrower (and partly different) part of lambda space. This rolls out every policy of a bundle in the
batched ANYmal environment (deterministic actions, 0.75 m/s command by default, margin switched off so
nothing but the policy drives the states), keeps lambda every ``--every`` policy steps, labels the states
with the analytic margin and compares each set of learned-margin weights with it: RMSE, bias, sign
agreement and the fraction of states outside the weights' training ranges. Default weights: the copy
the bundle carries (what its policies were trained with) and the package's weights for the robot.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from margin_rl.stability.analytic.lambda_state import lambda_names
from margin_rl.stability.analytic.margin import STATUSES, analytic_margin_batch
from margin_rl.stability.learned.model import LearnedMargin
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import evaluation_config, resolve_env


def visited_states(
    policy_path: Path, envs: int, steps: int, every: int, velocity: float, seed: int
) -> tuple[str, np.ndarray]:
    """(robot name, lambda (M, 47)) of ``envs`` parallel rollouts of one policy, every ``every`` steps."""
    from margin_rl.envs.core import AnymalCore

    policy = load_policy(policy_path)
    _, base = resolve_env(policy, None, {"margin": "none"})
    config = evaluation_config(base, velocity)
    core = AnymalCore(config, num_envs=envs, seed=seed)
    core.reset()
    obs, kept = core.observe_all(), []
    for step in range(steps):
        obs = core.step(policy(obs)).observation
        if step % every == every - 1:
            kept.append(core.last_lambda.copy())
    return config.robot, np.concatenate(kept)


def compare(model: LearnedMargin, lam: np.ndarray, analytic: np.ndarray) -> dict[str, float]:
    """Learned vs analytic on states whose analytic margin exists."""
    learned = np.asarray(model(lam))
    err = learned - analytic
    return {
        "rmse_cm": 100 * float(np.sqrt(np.mean(err**2))),
        "bias_cm": 100 * float(np.mean(err)),
        "sign": float(np.mean((learned >= 0) == (analytic >= 0))),
        "ood": float(np.mean(model.out_of_distribution(lam))),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bundle", default="anymal_b")
    parser.add_argument("--envs", type=int, default=8)
    parser.add_argument("--steps", type=int, default=500, help="policy steps per rollout (50 Hz)")
    parser.add_argument("--every", type=int, default=5)
    parser.add_argument("--forward-velocity", type=float, default=0.75)
    parser.add_argument("--seed", type=int, default=2000)
    parser.add_argument("--weights", nargs="*", help="learned-margin weights (robot name or .npz)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    bundle = load_bundle(args.bundle)
    t0 = time.perf_counter()
    states: dict[str, list[np.ndarray]] = {}
    robot = ""
    for run in bundle.runs:
        robot, lam = visited_states(run.policy, args.envs, args.steps, args.every, args.forward_velocity, args.seed)
        states.setdefault(run.variant, []).append(lam)
    weights = args.weights or [str(bundle.margin_weights), robot]
    models = {w: LearnedMargin.load(w) for w in weights}
    print(f"bundle {bundle.name}: {len(bundle.runs)} policies, rollouts {time.perf_counter() - t0:.0f} s")
    header = "| variant | states (ok) | analytic mean [m] | weights | learned mean [m] | RMSE [cm] | bias [cm] |"
    print(header + " sign agreement | outside training ranges |\n|---|---|---|---|---|---|---|---|---|")
    for variant, parts in states.items():
        lam = np.concatenate(parts)
        labels = analytic_margin_batch(robot, lam, workers=args.workers)
        ok = labels.status == STATUSES.index("ok")
        counts = ", ".join(f"{k} {v}" for k, v in labels.counts().items() if v and k != "ok")
        for name, model in models.items():
            c = compare(model, lam[ok], labels.margin[ok])
            learned_mean = float(np.mean(model(lam[ok])))
            print(
                f"| {variant} | {len(lam):,} ({ok.sum():,}{'; ' + counts if counts else ''}) | "
                f"{labels.margin[ok].mean():.3f} | `{name.split('/')[-1]}` ({model.card['sha256'][:8]}) | "
                f"{learned_mean:.3f} | {c['rmse_cm']:.2f} | {c['bias_cm']:+.2f} | {c['sign']:.1%} | {c['ood']:.1%} |"
            )
    model = next(iter(models.values()))
    for variant, parts in states.items():
        outside = model.outside_ranges(np.concatenate(parts)).mean(axis=0)
        worst = sorted(zip(outside, lambda_names(), strict=True), reverse=True)[:8]
        print(f"{variant}: outside the ranges of the first weights: " + ", ".join(f"{n} {f:.0%}" for f, n in worst))
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
