"""Throughput of the aSLIP hop simulators: batched RK4 vs solve_ivp per hop.

Samples are uniform in the paper's eq. (13) state-action box, so the mix of early failures
(no touchdown, slip at touchdown) and full hops is the one data generation sees.

Usage::

    python benchmarks/bench_slip.py [--n 200000] [--n-ref 300] [--repeats 3]

Prints a Markdown table of hops per second (best of ``--repeats``).
"""

from __future__ import annotations

import argparse
import platform
import time
from collections.abc import Callable, Sequence

import numpy as np

from margin_rl.slip.dynamics import SlipParams, simulate_batch, simulate_hop
from margin_rl.slip.margin import sample_box


def _best_rate(fn: Callable[[], None], n: int, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n / best


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
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

    print(
        f"aSLIP hop throughput ({platform.processor() or platform.machine()}, "
        f"numpy {np.__version__}, uniform eq. (13) samples)\n"
    )
    print("| simulator | hops | hops/s |")
    print("|---|---:|---:|")
    for name, n, rate in rows:
        print(f"| {name} | {n} | {rate:,.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
