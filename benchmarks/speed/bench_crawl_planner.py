"""Benchmark of the crawl's base-motion trajectory optimisation (seed 004 §V, Table III) and its polytopes.

Records the base-motion tasks of a heuristic crawl of ``--steps`` steps on flat ground (so that the
stances vary as in a crawl), then times, per task and for each optimising planner (``cwc``, ``fwp``),
side by side in the same rounds:

* ``polytopes``: building the stance's two V-descriptions (four-foot and triple stance, pruned; the
  paper's step a: ~150 ms for a triple stance, Table II: 0.15 s / 0.49 s for 3 / 4 contacts);
* ``TO``: one solve of eq. (25)-(28) with 10 knots (41 variables) in those polytopes, IPOPT with exact
  second derivatives (the paper's step b, Table III: 75 ms / 85 ms). Target: <= 20 ms on one core.

Medians over tasks x ``--repeats`` [ms], with IPOPT's iteration count. Usage::

    python benchmarks/speed/bench_crawl_planner.py [--robot anymal_c] [--steps 12] [--repeats 5] [--json PATH]
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import numpy as np

from benchmarks.harness import machine_line, parser, print_table, summarise, write_record
from margin_rl import load_robot
from margin_rl.planning.crawl import CrawlGait, CrawlSimulation, HeuristicPlanner, WrenchPolytopePlanner
from margin_rl.planning.crawl.gait import swing_leg


def crawl_tasks(robot, gait: CrawlGait, steps: int) -> list:
    """The base-motion tasks met along a heuristic crawl."""
    sim = CrawlSimulation(robot, gait)
    planner = HeuristicPlanner(gait)
    tasks = []
    for step in range(steps):
        tasks.append(sim.task(swing_leg(step)))
        sim.crawl_step(step, planner)
    return tasks


def main() -> int:
    cli = parser(__doc__)
    cli.add_argument("--robot", default="anymal_c")
    cli.add_argument("--steps", type=int, default=12)
    cli.add_argument("--repeats", type=int, default=5)
    args = cli.parse_args()
    robot = load_robot(args.robot)
    gait = CrawlGait()
    tasks = crawl_tasks(robot, gait, args.steps)
    planners = {kind: WrenchPolytopePlanner(robot, gait, kind) for kind in ("cwc", "fwp")}
    for planner in planners.values():
        planner.calibrate(tasks[0])
    build = {kind: [] for kind in planners}
    solve = {kind: [] for kind in planners}
    iterations = {kind: [] for kind in planners}
    vertices = {kind: [] for kind in planners}
    for task in tasks:
        for _ in range(args.repeats):
            for kind, planner in planners.items():  # side by side: both planners in every round
                t0 = time.perf_counter()
                four, triple = planner.polytopes(task)
                build[kind].append(time.perf_counter() - t0)
                plan = planner.solve(task, four, triple)
                solve[kind].append(plan.solve_seconds)
                iterations[kind].append(plan.iterations)
                vertices[kind].append((four.n_vertices, triple.n_vertices))
    rows, results = [], {}
    for kind in planners:
        b, s = summarise(1e3 * np.array(build[kind])), summarise(1e3 * np.array(solve[kind]))
        v = np.array(vertices[kind])
        rows.append([
            kind, f"{np.median(v[:, 0]):.0f} / {np.median(v[:, 1]):.0f}", f"{b.median:.1f} ({b.q1:.1f}-{b.q3:.1f})",
            f"{s.median:.1f} ({s.q1:.1f}-{s.q3:.1f})", f"{np.median(iterations[kind]):.0f}",
            f"{np.median(np.array(build[kind]) / np.array(solve[kind])):.0f}x",
        ])  # fmt: skip
        results[kind] = {
            "polytopes_ms": asdict(b),
            "to_ms": asdict(s),
            "iterations_median": float(np.median(iterations[kind])),
            "vertices_four_triple_median": [float(np.median(v[:, 0])), float(np.median(v[:, 1]))],
        }
    print(
        f"{args.robot}, {len(tasks)} base-motion tasks of a heuristic crawl x {args.repeats} repeats; {machine_line()}"
    )
    print_table(
        [
            "planner",
            "vertices (4 / 3 feet)",
            "polytopes [ms]",
            "TO, 10 knots [ms]",
            "IPOPT iterations",
            "polytopes / TO",
        ],
        rows,
    )
    write_record(args.json, "bench_crawl_planner", args, results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
