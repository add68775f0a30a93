"""CLI: ``python -m margin_rl.planning.crawl --robot anymal_c --out DIR`` (seed 004 §VI on one robot).

Writes ``DIR/crawl.json`` (per planner: ``vertical_disturbance_limit_N``, ``displacement_unload_m``,
``torque_limit_hits_loaded_crawl``, ``solve_ms_median`` and more), ``DIR/crawl_series.npz`` (the
series the figures are drawn from), the figures and, unless ``--no-video``, ``DIR/loaded_crawl.mp4``.
"""

from __future__ import annotations

import argparse
import json
import sys

from margin_rl.robot import available_robots


def main(argv: list[str] | None = None) -> int:
    from margin_rl.planning.crawl.experiments import ExperimentSettings

    defaults = ExperimentSettings()
    parser = argparse.ArgumentParser(
        prog="python -m margin_rl.planning.crawl",
        description="Seed 004's crawl with three CoM planners (heuristic, CWC, FWP): the triple-stance "
        "disturbance tests, the CWC margin and FWP factor along a crawl, loaded and hindered crawls.",
    )
    parser.add_argument("--robot", default=defaults.robot, choices=available_robots())
    parser.add_argument("--out", required=True, help="directory for crawl.json, the figures and the MP4")
    parser.add_argument("--load-kg", type=float, default=defaults.load_kg, help="load carried on the base [kg]")
    parser.add_argument(
        "--heavy-load-fraction", type=float, default=defaults.heavy_load_fraction,
        help="the heavier crawl's load as a fraction of the robot's mass",
    )  # fmt: skip
    parser.add_argument("--hindered-fraction", type=float, default=defaults.hindered_fraction,
                        help="torque limit of the hindered joint (LF knee) as a fraction of its own")  # fmt: skip
    parser.add_argument("--steps", type=int, default=defaults.steps, help="steps of every crawl")
    parser.add_argument("--no-video", action="store_true", help="skip the MP4")
    args = parser.parse_args(argv)
    if args.load_kg < 0 or args.heavy_load_fraction < 0:
        parser.error("loads must be >= 0")
    if not 0 < args.hindered_fraction <= 1:
        parser.error("--hindered-fraction must be in (0, 1]")
    if args.steps < 1:
        parser.error("--steps must be >= 1")
    from margin_rl.planning.crawl.experiments import run_experiments, write_video
    from margin_rl.planning.crawl.figures import write_figures

    settings = ExperimentSettings(
        robot=args.robot, load_kg=args.load_kg, heavy_load_fraction=args.heavy_load_fraction,
        hindered_fraction=args.hindered_fraction, steps=args.steps,
    )  # fmt: skip
    summary = run_experiments(settings, args.out)
    write_figures(args.out)
    if not args.no_video:
        write_video(args.robot, args.out)
    brief = {name: {k: v for k, v in result.items() if k != "crawls"} for name, result in summary["planners"].items()}
    json.dump(brief, sys.stdout, indent=2, default=float)
    print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
