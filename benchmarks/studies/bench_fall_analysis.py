"""Why do the margin policies fall? Falls, gait, reward terms and margins along a bundle's episodes.

Usage:
    MUJOCO_GL=egl python benchmarks/studies/bench_fall_analysis.py --bundle anymal_b --envs 64 \
        --seed 1000 5000 --workers 2 --json docs/comparison/fall_analysis_anymal_b.json \
        --figure docs/comparison/fall_analysis_anymal_b.png

Every policy of the bundle runs one deterministic episode per environment (``--envs``) at each evaluation seed
(``--seed``), with the card's protocol: fixed command (0.75 m/s), 20 s episodes, the environment of the policy's
training run with the learned margin the policies were trained with (the bundle's copy, and each variant's margin
weight), so the per-term rewards are the ones the policy was trained on. Episodes run to their first termination
or the time limit (no autoreset). Measured, per variant (mean ± std over the policies, i.e. training seeds):

* falls: fraction of episodes (overall, per evaluation seed, before and after the first 2 s), time of the fall,
  which termination fired (the environment's ``info["termination_<cause>"]``: base contact, thigh contact, base
  below the height bound, tilt beyond the bound, diverged simulation; several can fire at once), which thigh and
  which of its geoms touched the terrain;
* gait before falls: each foot's contact share and the number of feet in contact over the last
  ``--contact-window`` s, against the steps of non-falling episodes after the first second;
* trends: base height, lowest knee height, stance width, tilt, base-frame velocities and angular rates, feet in
  contact and learned margin at fixed times before the fall, against their mean and 5th/95th percentiles in the
  steady gait;
* reward: per-step mean of every weighted term (``info["reward_<term>"]``) and of the total, the margin term's
  share of the return, and how often the margin term sat at its floor (margin clipped at -0.5 m), in falling
  and non-falling episodes and in the last ``--window`` s before falls;
* margins: on a subsample of the visited lambdas (every ``--every``-th step, plus every step of the last
  ``--window`` s before each fall) the learned margin (unclipped) against the extended margin m_x and the
  analytic margin m_a (:func:`margin_rl.stability.analytic.extended.extended_margin_batch`): how often the learned
  margin is positive where m_x is negative, or where m_a is negative or undefined (no Feasible Region);
* posture probe: on ``--probe-states`` steady states per policy, the change of the learned margin and of m_x when
  lambda's CoM is put 5 cm lower over the same feet, or the stance 5 cm wider;
* the two variants compared over training seeds (``margin_rl.train.analysis.significance``: difference, Welch test,
  bootstrap interval) on the headline figures: fall fractions, the steady gait, the reward, the learned margin's
  false positives against m_x.

Prints Markdown tables; ``--json`` writes every number (with each policy's episode metrics as ``evaluate`` reports
them), ``--figure`` a summary figure. The episodes are recorded by ``fall_episodes``, measured by ``fall_report``
and drawn by ``fall_figure`` (beside this script).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.*

from benchmarks.harness import json_ready
from benchmarks.studies.fall_episodes import CAUSES, LEGS, Episodes, add_labels, add_learned, join, roll_out
from benchmarks.studies.fall_report import (
    fall_summary,
    gait_summary,
    margin_summary,
    posture_probe,
    print_report,
    reward_summary,
    trend_summary,
    variant_differences,
)
from margin_rl.stability.learned.model import LearnedMargin
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.commands.evaluate import DEFAULT_FORWARD_VELOCITY


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--bundle", default="anymal_b", help="shipped bundle name or folder")
    parser.add_argument("--envs", type=int, default=32, help="episodes (parallel environments) per policy and seed")
    parser.add_argument("--seed", type=int, nargs="+", default=[1000, 5000], help="evaluation seeds")
    parser.add_argument("--forward-velocity", type=float, default=DEFAULT_FORWARD_VELOCITY, help="command [m/s]")
    parser.add_argument("--every", type=int, default=5, help="label every n-th policy step with m_x and m_a")
    parser.add_argument("--window", type=float, default=1.0, help="seconds before a fall: labelled densely [s]")
    parser.add_argument("--contact-window", type=float, default=0.5, help="seconds before a fall for the gait [s]")
    parser.add_argument("--probe-states", type=int, default=300, help="steady states per policy for the posture probe")
    parser.add_argument("--workers", type=int, default=1, help="processes for the analytic labels")
    parser.add_argument("--json", type=Path, help="write every number here")
    parser.add_argument("--figure", type=Path, help="write the summary figure here (.png)")
    args = parser.parse_args(argv)
    for name in ("envs", "every", "workers", "probe_states"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be an integer >= 1, got {getattr(args, name)}")
    for name in ("window", "contact_window", "forward_velocity"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            parser.error(f"--{name.replace('_', '-')} must be a finite number > 0, got {value}")
    if len(set(args.seed)) != len(args.seed):
        parser.error(f"--seed values must differ, got {args.seed}")
    return args


def display_path(path: Path) -> str:
    """``path`` relative to the working directory where it lies inside it (the repository root), else absolute."""
    resolved = path.resolve()
    return str(resolved.relative_to(Path.cwd())) if resolved.is_relative_to(Path.cwd()) else str(resolved)


def policy_record(e: Episodes) -> dict[str, object]:
    """What the JSON keeps of one policy's episodes."""
    return {
        "variant": e.variant,
        "seed": e.policy_seed,
        "margin_weight": e.margin_weight,
        "episodes": len(e.fell),
        "falls": int(e.fell.sum()),
        "fall_times_s": e.fall_times().tolist(),
        "fall_causes": {c: int(e.causes[e.fell, i].sum()) for i, c in enumerate(CAUSES)},
        "thigh_contacts_at_fall": dict(zip(LEGS, e.thighs[e.fell].sum(axis=0).tolist(), strict=True)),
        "evaluation": e.summary(),
    }


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        bundle = load_bundle(args.bundle)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if bundle.margin_weights is None:
        print(f"error: bundle {bundle.name} carries no learned-margin weights (card format 1)", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    model = LearnedMargin.load(bundle.margin_weights)
    everything: list[Episodes] = []
    for run in bundle.runs:
        parts = [roll_out(bundle, run, args.envs, seed, args.forward_velocity) for seed in args.seed]
        everything.append(join(parts))
        add_learned(everything[-1], model)
        print(f"{everything[-1].name}: {int(everything[-1].fell.sum())} falls in {len(everything[-1].fell)} episodes")
    rollout_s = time.perf_counter() - t0
    labels = add_labels(everything, args.every, args.window, args.workers)
    label_s = time.perf_counter() - t0 - rollout_s
    groups: dict[str, list[Episodes]] = {}
    for e in everything:
        groups.setdefault(e.variant, []).append(e)
    weight = max(e.margin_weight for e in everything)
    report = {
        "falls": fall_summary(groups, args.seed),
        "gait": gait_summary(groups, args.contact_window),
        "trends": trend_summary(groups),
        "rewards": reward_summary(groups, args.window),
        "margins": margin_summary(groups, args.window, weight),
        "posture_probe": posture_probe(groups, model, args.probe_states, args.workers),
    }
    report["differences"] = variant_differences(report, args.window)
    total = max(len(v) for v in groups.values())
    print(
        f"\nbundle {bundle.name}: {len(everything)} policies x {len(args.seed)} seeds x {args.envs} episodes; "
        f"rollouts {rollout_s:.0f} s, {labels:,} states labelled in {label_s:.0f} s"
    )
    print_report(report, list(groups), total)
    if args.figure:
        from benchmarks.studies.fall_figure import plot

        plot(groups, report, args.window, args.figure)
        print(f"\nfigure: {args.figure}")
    runtime_s = time.perf_counter() - t0
    if args.json:
        record = {
            "command": "python " + " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]]),
            "bundle": bundle.name,
            "learned_margin": display_path(bundle.margin_weights),
            "learned_margin_sha256": model.card.get("sha256"),
            "settings": vars(args),
            "policies": [policy_record(e) for e in everything],
            "labelled_states": labels,
            "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
            "runtime_s": {"rollouts": rollout_s, "labels": label_s, "total": runtime_s},
            **report,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(json_ready(record), indent=1) + "\n")
        print(f"json: {args.json}")
    print(f"total {runtime_s:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
