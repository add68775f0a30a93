"""CLI: ``python -m margin_rl.planning --scenario side_step --robot anymal_c --out results/to``."""

from __future__ import annotations

import argparse
import json
import sys

from margin_rl.planning.gait import GAITS
from margin_rl.planning.problem import HESSIANS, PlannerConfig
from margin_rl.planning.scenarios import SCENARIOS


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m margin_rl.planning",
        description="Receding-horizon trajectory optimisation with the learned stability margin (seed 000 §IV-B).",
    )
    parser.add_argument("--scenario", default="side_step", help=f"one of {', '.join(SCENARIOS)}, or 'all'")
    parser.add_argument("--robot", default="anymal_c", help="anymal_c (the paper's robot) or anymal_b")
    parser.add_argument("--gait", default="walk", choices=sorted(GAITS))
    parser.add_argument("--out", default="results/to", help="directory for the figure, MP4 and JSON summary")
    parser.add_argument("--no-video", action="store_true", help="skip the MP4")
    parser.add_argument("--no-contrast", action="store_true", help="skip the plans without the margin constraint")
    parser.add_argument("--max-plans", type=int, default=None, help="stop after this many replans (a short run)")
    parser.add_argument(
        "--hessian", choices=HESSIANS, default=PlannerConfig().hessian,
        help="IPOPT's Hessian of the Lagrangian: exact (the network's second derivatives) or quasi-newton (L-BFGS)",
    )  # fmt: skip
    parser.add_argument(
        "--weights", default=None,
        help="learned-margin weights the plans are constrained by: a bundled name (e.g. anymal_c) or an .npz with "
        "its card (default: the robot's default network, margin_rl.planning.mlp.planning_weights)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    names = list(SCENARIOS) if args.scenario == "all" else [args.scenario]
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        parser.error(f"unknown scenario {unknown[0]!r}; choose from {', '.join(SCENARIOS)} or 'all'")
    from margin_rl.planning.experiment import evaluate_scenario

    if args.weights is not None:
        from margin_rl.stability import LearnedMargin
        from margin_rl.stability.learned.model import WeightsError

        try:  # refuse bad weights before the first course, not after it
            LearnedMargin.load(args.weights)
        except WeightsError as exc:
            parser.error(f"--weights: {exc}")

    for name in names:
        summary = evaluate_scenario(
            args.robot,
            name,
            args.gait,
            out=args.out,
            video=not args.no_video,
            contrast=not args.no_contrast,
            max_plans=args.max_plans,
            config=PlannerConfig(hessian=args.hessian),
            weights=args.weights,
        )
        json.dump(summary, sys.stdout, indent=2, default=float)
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
