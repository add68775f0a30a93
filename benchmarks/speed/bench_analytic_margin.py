"""Benchmark: analytic_margin per call on one core, IK included, by stance type.

Usage:
    taskset -c 0 python benchmarks/speed/bench_analytic_margin.py [--robot anymal_c] [--n 300] [--seed 0] [--tol ...]
        [--friction cone|pyramid:K] [--json PATH]

Draws Table I states (kinematically feasible), evaluates each once in this process (one core), and
prints a Markdown table: median / p90 time per call, its parts, LPs per call, and the status mix, for
4-, 3- and 2-contact states. Pin the process to one core with ``taskset -c 0`` for a clean figure.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import numpy as np

from benchmarks.harness import machine_line, parser, print_table, write_record
from margin_rl import load_robot
from margin_rl.stability.analytic.lambda_state import from_lambda
from margin_rl.stability.analytic.margin import AnalyticSettings, analytic_margin
from margin_rl.stability.analytic.sampling import sample_states


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--robot", default="anymal_c")
    args_parser.add_argument("--n", type=int, default=300, help="states per stance type")
    args_parser.add_argument("--seed", type=int, default=0)
    args_parser.add_argument("--tol", type=float, default=None, help="iterative-projection tolerance [m^2]")
    args_parser.add_argument("--friction", default="cone", help="'cone' or 'pyramid:K'")
    args = args_parser.parse_args()

    robot = load_robot(args.robot)
    friction = args.friction if args.friction == "cone" else ("pyramid", int(args.friction.split(":")[1]))
    settings = (
        AnalyticSettings(friction=friction) if args.tol is None else AnalyticSettings(friction=friction, tol=args.tol)
    )
    pool = sample_states(robot, 6 * args.n, seed=args.seed)
    n_contacts = from_lambda(pool).contacts.sum(axis=1)
    analytic_margin(robot, pool[0], settings)  # warm-up (imports, caches)

    print(machine_line())
    print(f"robot {args.robot}, settings {settings.as_dict()}")
    print()
    rows, record = [], {}
    for k in (4, 3, 2):
        lams = pool[n_contacts == k][: args.n]
        results = []
        for lam in lams:
            t0 = time.perf_counter()
            r = analytic_margin(robot, lam, settings)
            results.append((time.perf_counter() - t0, r))
        total = np.array([t for t, _ in results]) * 1e3
        parts = {
            key: np.median([r.timings.get(key, 0.0) for _, r in results]) * 1e3
            for key in ("kinematics_dynamics", "region")
        }
        lps = np.median([r.n_lps for _, r in results if r.region is not None])
        statuses: dict[str, int] = {}
        for _, r in results:
            statuses[r.status] = statuses.get(r.status, 0) + 1
        mix = ", ".join(f"{s} {c}" for s, c in sorted(statuses.items()))
        rows.append(
            (k, len(lams), f"{np.median(total):.2f}", f"{np.percentile(total, 90):.2f}",
             f"{parts['kinematics_dynamics']:.2f}", f"{parts['region']:.2f}", f"{lps:.0f}", mix)
        )  # fmt: skip
        record[f"{k} contacts"] = {
            "states": len(lams),
            "median_ms": np.median(total),
            "p90_ms": np.percentile(total, 90),
            "parts_median_ms": parts,
            "lps_median": lps,
            "statuses": statuses,
        }
    print_table(
        ("contacts", "n", "median ms", "p90 ms", "kinematics+dynamics ms", "region ms", "LPs median", "statuses"), rows
    )
    write_record(args.json, "analytic_margin", {**vars(args), "settings": settings.as_dict()}, record)


if __name__ == "__main__":
    main()
