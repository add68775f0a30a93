"""Benchmark: labelling throughput of the batched path against the per-state path, side by side in one run.

Usage:
    taskset -c 0 .venv/bin/python benchmarks/bench_labelling.py [--n 2000] [--rounds 5] [--e2e-n 2000]

Part 1 times the dataset's per-shard labelling function (``analytic_margin_batch(robot, lams, settings,
workers=1)``, what ``dataset.make_shard`` calls) with ``AnalyticSettings(labelling="per_state")`` (the
path before learned margin v2 item 6) and ``labelling="batched"`` on the same Table I states (shard 0 of
seed 0), in interleaved rounds (A B, B A, ...: neither path always runs second), for ANYmal B and C. It
prints labels/s per path (median over rounds), the ratio of the medians and the median of the per-round
ratios, and the agreement of the two (statuses, max |margin difference|).

Part 2 times end-to-end ``dataset generate`` (sampling, labelling, shard files; one process, as
``--workers 1``) into fresh temporary directories, alternating the paths, for ANYmal C.

On a shared machine only figures from the same run compare: quote the medians and ratios.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from margin_rl.stability.analytic.margin import STATUSES, AnalyticSettings, analytic_margin_batch, worker_robot
from margin_rl.stability.analytic.sampling import sample_states
from margin_rl.stability.learned.dataset import DatasetSpec, generate

PATHS = {"per_state": AnalyticSettings(labelling="per_state"), "batched": AnalyticSettings(labelling="batched")}


def label_rounds(robot_name: str, n: int, rounds: int) -> None:
    robot = worker_robot(robot_name)
    lams = sample_states(robot, n, seed=np.random.SeedSequence(0, spawn_key=(0,)))  # a dataset's shard 0
    for settings in PATHS.values():
        analytic_margin_batch(robot_name, lams[:64], settings, workers=1)  # warm-up (imports, caches)
    rates: dict[str, list[float]] = {name: [] for name in PATHS}
    results = {}
    for r in range(rounds):
        order = list(PATHS) if r % 2 == 0 else list(reversed(PATHS))
        for name in order:
            t0 = time.perf_counter()
            results[name] = analytic_margin_batch(robot_name, lams, PATHS[name], workers=1)
            rates[name].append(n / (time.perf_counter() - t0))
    old, new = results["per_state"], results["batched"]
    ok = old.status == STATUSES.index("ok")
    diff = np.abs(new.margin[ok] - old.margin[ok])
    med = {name: statistics.median(v) for name, v in rates.items()}
    per_round = statistics.median(b / a for a, b in zip(rates["per_state"], rates["batched"], strict=True))
    counts = ", ".join(f"{k} {v}" for k, v in old.counts().items() if v)
    ratio = med["batched"] / med["per_state"]
    lps = f"{old.n_lps.mean():.2f} / {new.n_lps.mean():.2f}"
    changed = int((old.status != new.status).sum())
    print(
        f"| {robot_name} | {n} | {med['per_state']:.0f} | {med['batched']:.0f} | {ratio:.2f} | {per_round:.2f} "
        f"| {lps} | {changed} | {diff.max() * 1e3:.3f} | {counts} |"
    )


def end_to_end(robot_name: str, n: int, shard_size: int, rounds: int) -> None:
    rates: dict[str, list[float]] = {name: [] for name in PATHS}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            order = list(PATHS) if r % 2 == 0 else list(reversed(PATHS))
            for name in order:
                spec = DatasetSpec(robot_name, n=n, shard_size=shard_size, seed=0, settings=PATHS[name])
                t0 = time.perf_counter()
                generate(spec, Path(tmp) / f"{name}_{r}", workers=1, progress=False)
                rates[name].append(n / (time.perf_counter() - t0))
    med = {name: statistics.median(v) for name, v in rates.items()}
    per_round = statistics.median(b / a for a, b in zip(rates["per_state"], rates["batched"], strict=True))
    print(
        f"| {robot_name} | {n} ({shard_size} a shard) | {med['per_state']:.0f} | {med['batched']:.0f} "
        f"| {med['batched'] / med['per_state']:.2f} | {per_round:.2f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=2000, help="states per robot for the labelling rounds")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (each path once a round)")
    parser.add_argument("--e2e-n", type=int, default=2000, help="samples of each end-to-end dataset (0: skip)")
    parser.add_argument("--e2e-rounds", type=int, default=3)
    parser.add_argument("--shard-size", type=int, default=500)
    args = parser.parse_args()

    print(f"{platform.processor() or platform.machine()}, settings {PATHS['batched'].as_dict()}")
    print()
    print(
        "| robot | states | per_state labels/s | batched labels/s | ratio of medians | median per-round ratio "
        "| LPs per label (per_state / batched) | status differences | max abs margin diff mm | statuses |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for robot_name in ("anymal_b", "anymal_c"):
        label_rounds(robot_name, args.n, args.rounds)
    if args.e2e_n:
        print()
        print(
            "| robot | dataset generate samples | per_state labels/s | batched labels/s | ratio of medians "
            "| median per-round ratio |"
        )
        print("|---|---|---|---|---|---|")
        end_to_end("anymal_c", args.e2e_n, args.shard_size, args.e2e_rounds)


if __name__ == "__main__":
    main()
