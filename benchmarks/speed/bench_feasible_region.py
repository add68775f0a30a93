"""Benchmark of :func:`margin_rl.stability.geometry.region.feasible_region`.

Times whole calls (validation, problem set-up, all conic programs and the polygon clean-up) on
synthetic quadruped states from ``tests/stability/cases.py``: random foot placements, tilted
normals, accelerations and an external wrench, with 4, 3 and 2 (trot diagonal) contacts, for the
exact friction cone and an 8-face pyramid.  Prints a Markdown table of the median time per call,
the conic programs (LPs) per call and the median time per program.

Usage::

    python benchmarks/speed/bench_feasible_region.py [--cases 30] [--repeats 3] [--tol T] [--max-lps N] [--rebuild]
        [--json PATH]

``--rebuild`` adds rows where a new Clarabel solver is built for every direction instead of
updating only the cost vector of one solver (the default strategy), to show what the update
saves.  Timings are wall-clock on whatever else the machine is running: run it on a quiet one.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness, tests

import clarabel
import numpy as np

from benchmarks.harness import machine_line, markdown_header, markdown_row, parser, write_record
from margin_rl.stability.geometry import region as fr
from margin_rl.stability.geometry.region_program import FAST_SETTINGS, zero_cost
from tests.stability import cases

STANCES: dict[int, list[tuple[bool, bool, bool, bool]]] = {
    4: [(True, True, True, True)],
    3: [(False, True, True, True), (True, False, True, True), (True, True, False, True), (True, True, True, False)],
    2: [(True, False, False, True), (False, True, True, False)],
}
FRICTIONS: list[Any] = ["cone", ("pyramid", 8)]


class _RebuildOracle(fr.SupportOracle):
    """Builds a fresh solver for every direction (the alternative to ``solver.update(q=...)``)."""

    def __call__(self, ax: float, ay: float) -> tuple[int, float, float]:
        prob = self._prob
        q = np.zeros(prob.n_var)
        q[0], q[1] = -ax, -ay
        solver = clarabel.DefaultSolver(zero_cost(prob.n_var), q, prob.A, prob.b, prob.cones, FAST_SETTINGS)
        return self._solve(solver, ax, ay)


def make_cases(n_contacts: int, n_cases: int, seed: int) -> list[dict[str, Any]]:
    rng = np.random.default_rng(seed + n_contacts)
    stances = STANCES[n_contacts]
    return [cases.random_quadruped_case(rng, stances[i % len(stances)]) for i in range(n_cases)]


def run(kws: list[dict[str, Any]], friction: Any, repeats: int, tol: float, max_lps: int) -> dict[str, float]:
    times, lps, per_lp = [], [], []
    empty = 0
    for kw in kws:
        for _ in range(repeats):
            t0 = time.perf_counter()
            region = fr.feasible_region(**kw, friction=friction, tol=tol, max_lps=max_lps)
            dt = time.perf_counter() - t0
            times.append(dt)
            lps.append(region.n_lps)
            per_lp.append(dt / max(region.n_lps, 1))
        empty += region.status == "empty"
    t = np.array(times) * 1e3
    return {
        "median_ms": float(np.median(t)),
        "p90_ms": float(np.percentile(t, 90)),
        "mean_lps": float(np.mean(lps)),
        "max_lps": float(np.max(lps)),
        "us_per_lp": float(np.median(per_lp) * 1e6),
        "empty_pct": 100.0 * empty / len(kws),
    }


def main(argv: list[str] | None = None) -> None:
    ap = parser(__doc__)
    ap.add_argument("--cases", type=int, default=30, help="random states per contact count")
    ap.add_argument("--repeats", type=int, default=3, help="calls per state")
    ap.add_argument("--tol", type=float, default=fr.DEFAULT_TOL, help="area tolerance [m^2]")
    ap.add_argument("--max-lps", type=int, default=fr.DEFAULT_MAX_LPS)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rebuild", action="store_true", help="also time rebuilding the solver per direction")
    args = ap.parse_args(argv)

    # Warm-up: imports, BLAS/Clarabel first-call costs.
    warm = make_cases(4, 2, 999)
    run(warm, "cone", 2, args.tol, args.max_lps)

    print(machine_line())
    print(f"tol={args.tol:g} m^2, max_lps={args.max_lps}, {args.cases} states x {args.repeats} calls per row\n")
    header = ["contacts", "friction", "strategy", "median ms/call", "p90 ms/call"]
    header += ["LPs/call (mean / max)", "median us/LP (call / LPs)", "empty"]
    print("\n".join(markdown_header(header)))
    record = []
    strategies = [("update q", fr.SupportOracle)]
    if args.rebuild:
        strategies.append(("rebuild", _RebuildOracle))
    for n_contacts in (4, 3, 2):
        kws = make_cases(n_contacts, args.cases, args.seed)
        for friction in FRICTIONS:
            for label, oracle in strategies:
                original = fr.SupportOracle
                fr.SupportOracle = oracle  # type: ignore[misc]  # looked up at call time
                try:
                    r = run(kws, friction, args.repeats, args.tol, args.max_lps)
                finally:
                    fr.SupportOracle = original  # type: ignore[misc]
                name = friction if isinstance(friction, str) else f"pyramid-{friction[1]}"
                print(
                    markdown_row(
                        (n_contacts, name, label, f"{r['median_ms']:.2f}", f"{r['p90_ms']:.2f}",
                         f"{r['mean_lps']:.1f} / {r['max_lps']:.0f}", f"{r['us_per_lp']:.0f}",
                         f"{r['empty_pct']:.0f} %")
                    ),
                    flush=True,
                )  # fmt: skip
                record.append({"contacts": n_contacts, "friction": name, "strategy": label, **r})
    write_record(args.json, "feasible_region", args, record)


if __name__ == "__main__":
    main()
