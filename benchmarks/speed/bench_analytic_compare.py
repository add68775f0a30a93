"""Benchmark: analytic_margin of this checkout against a baseline copy, side by side in one process.

Usage:
    mkdir -p /tmp/baseline && git archive <rev> margin_rl | tar -x -C /tmp/baseline
    taskset -c 0 .venv/bin/python benchmarks/speed/bench_analytic_compare.py --baseline /tmp/baseline [--n 300]

Options: --robot (anymal_c), --n states per stance type (300), --rounds timed calls per state and copy (3),
--seed (0), --json PATH (a JSON record of the results and the machine).

On a shared machine two benchmark runs minutes apart measure different loads, so this script imports
the baseline package (a directory holding a ``margin_rl`` package, e.g. an older revision unpacked by
``git archive``) next to the current one and times both on the same Table I states, interleaved call
by call (A, B, B, A, ...: the order alternates so neither copy always runs on a warm cache). It prints
a Markdown table of the median time per call of each copy and their ratio, for 4-, 3- and 2-contact
states, and checks that both give the same statuses and margins (max |difference| [m]).
"""

from __future__ import annotations

import importlib
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import numpy as np

from benchmarks.harness import machine_line, parser, print_table, round_order, write_record
from margin_rl import load_robot
from margin_rl.stability.analytic.lambda_state import from_lambda
from margin_rl.stability.analytic.margin import analytic_margin
from margin_rl.stability.analytic.sampling import sample_states


def _is_ours(module_name: str) -> bool:
    return module_name == "margin_rl" or module_name.startswith("margin_rl.")


def load_baseline(src: Path, robot_name: str) -> tuple[Any, Callable[..., Any]]:
    """``(robot, analytic_margin)`` of the ``margin_rl`` package under ``src``, imported as a second copy.

    The current modules are set aside in ``sys.modules`` while the baseline is imported and restored
    afterwards; the baseline's functions keep their own module globals, so both copies coexist.
    """
    if not (src / "margin_rl" / "__init__.py").is_file():
        raise SystemExit(f"--baseline {src}: no margin_rl package there")
    current = {name: module for name, module in sys.modules.items() if _is_ours(name)}
    for name in current:
        del sys.modules[name]
    sys.path.insert(0, str(src))
    try:
        robot_module = importlib.import_module("margin_rl.robot")
        analytic_module = importlib.import_module("margin_rl.stability.analytic.margin")
        if not Path(analytic_module.__file__ or "").resolve().is_relative_to(src.resolve()):
            raise SystemExit(f"--baseline {src}: imported {analytic_module.__file__} instead")
        robot = robot_module.load_robot(robot_name)
    finally:
        sys.path.remove(str(src))
        for name in [name for name in sys.modules if _is_ours(name)]:
            del sys.modules[name]
        sys.modules.update(current)
    return robot, analytic_module.analytic_margin


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--baseline", type=Path, required=True, help="directory holding the baseline margin_rl")
    args_parser.add_argument("--robot", default="anymal_c")
    args_parser.add_argument("--n", type=int, default=300, help="states per stance type")
    args_parser.add_argument("--rounds", type=int, default=3, help="timed calls per state and copy")
    args_parser.add_argument("--seed", type=int, default=0)
    args = args_parser.parse_args()

    base_robot, base_margin = load_baseline(args.baseline, args.robot)
    robot = load_robot(args.robot)
    pool = sample_states(robot, 6 * args.n, seed=args.seed)
    n_contacts = from_lambda(pool).contacts.sum(axis=1)
    variants = {"baseline": (base_margin, base_robot), "current": (analytic_margin, robot)}
    for fn, rb in variants.values():
        fn(rb, pool[0])  # warm-up (imports, caches)

    print(machine_line())
    print(f"robot {args.robot}, baseline {args.baseline}")
    print()
    rows, record = [], {}
    for k in (4, 3, 2):
        lams = pool[n_contacts == k][: args.n]
        times: dict[str, list[float]] = {name: [] for name in variants}
        results: dict[str, list[Any]] = {name: [] for name in variants}
        for r in range(args.rounds):
            for i, lam in enumerate(lams):
                for name in round_order(list(variants), i + r):
                    fn, rb = variants[name]
                    t0 = time.perf_counter()
                    res = fn(rb, lam)
                    times[name].append(time.perf_counter() - t0)
                    if r == 0:
                        results[name].append(res)
        status = {name: [res.status for res in results[name]] for name in variants}
        if status["baseline"] != status["current"]:
            changed = sum(a != b for a, b in zip(status["baseline"], status["current"], strict=True))
            print(f"WARNING: {changed} of {len(lams)} {k}-contact states changed status")
        margins = {name: np.array([res.margin for res in results[name]]) for name in variants}
        diff = np.abs(margins["current"] - margins["baseline"])
        max_diff = float(np.nanmax(diff)) if np.isfinite(diff).any() else 0.0
        med = {name: float(np.median(times[name])) * 1e3 for name in variants}
        ratio = med["current"] / med["baseline"]
        rows.append(
            (k, len(lams), f"{med['baseline']:.3f}", f"{med['current']:.3f}", f"{ratio:.3f}", f"{max_diff:.2e}")
        )
        record[f"{k} contacts"] = {
            "states": len(lams),
            "median_ms": med,
            "ratio": ratio,
            "max_abs_margin_diff_m": max_diff,
        }
    headers = (
        "contacts",
        "n",
        "baseline median ms",
        "current median ms",
        "current / baseline",
        "max abs margin diff m",
    )
    print_table(headers, rows)
    write_record(args.json, "analytic_compare", args, record)


if __name__ == "__main__":
    main()
