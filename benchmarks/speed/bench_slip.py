"""Throughput of the aSLIP hop simulators: batched RK4 vs solve_ivp per hop.

Samples are uniform in the paper's eq. (13) state-action box, so the mix of early failures
(no touchdown, slip at touchdown) and full hops is the one data generation sees.

Usage::

    python benchmarks/speed/bench_slip.py [--n 200000] [--n-ref 300] [--repeats 3] [--seed 0] [--json PATH]

Prints a Markdown table of hops per second (best of ``--repeats``).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import numpy as np

from benchmarks.harness import durations, machine_line, parser, print_table, write_record
from margin_rl.slip.dynamics import SlipParams, simulate_batch, simulate_hop
from margin_rl.slip.margin import sample_box


def _best_rate(fn: Callable[[], None], n: int, repeats: int) -> float:
    """Hops per second of the fastest of ``repeats`` calls of ``fn`` (``n`` hops each)."""
    return n / min(durations(fn, repeats))


def main(argv: Sequence[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=200_000, help="hops per batched run")
    ap.add_argument("--n-ref", type=int, default=300, help="hops for the solve_ivp reference")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    p = SlipParams()
    z = sample_box(args.n, np.random.default_rng(args.seed))
    rows: list[tuple[str, int, float]] = []
    for dt in (0.01, 0.005):
        rate = _best_rate(lambda dt=dt: simulate_batch(z[:, :2], z[:, 2:], p, dt=dt), args.n, args.repeats)
        rows.append((f"batched RK4, dt={dt}, one process", args.n, rate))
    for batch in (1_000, 10_000):
        zb = z[:batch]
        rate = _best_rate(lambda zb=zb: simulate_batch(zb[:, :2], zb[:, 2:], p), batch, args.repeats)
        rows.append((f"batched RK4, dt=0.01, batch {batch}", batch, rate))
    zr = z[: args.n_ref]

    def reference() -> None:
        for row in zr:
            simulate_hop(row[:2], row[2:], p)

    rows.append(("solve_ivp DOP853 per hop (rtol 1e-10)", args.n_ref, _best_rate(reference, args.n_ref, 1)))

    print(machine_line(("numpy", "scipy")))
    print("aSLIP hop throughput (uniform eq. (13) samples)\n")
    print_table(("simulator", "hops", "hops/s"), [(name, n, f"{rate:,.0f}") for name, n, rate in rows], ("", "r", "r"))
    write_record(
        args.json, "slip", args, [{"simulator": name, "hops": n, "hops_per_s": rate} for name, n, rate in rows]
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
