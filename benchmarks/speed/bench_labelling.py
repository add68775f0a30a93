"""Benchmark: labelling throughput of the batched path against the per-state path, side by side in one run.

Usage:
    taskset -c 0 .venv/bin/python benchmarks/speed/bench_labelling.py [--n 2000] [--rounds 5] [--e2e-n 2000]
        [--e2e-rounds 3] [--shard-size 500] [--json PATH]

Part 1 times the dataset's per-shard labelling function (``analytic_margin_batch(robot, lams, settings,
workers=1)``, what ``dataset.make_shard`` calls) with ``AnalyticSettings(labelling="per_state")`` (one
program set-up per state) and ``labelling="batched"`` on the same Table I states (shard 0 of seed 0), in
interleaved rounds (A B, B A, ...: neither path always runs second), for ANYmal B and C. It prints labels/s per
path (median over rounds), the ratio of the medians and the median of the per-round ratios, and the agreement of
the two (statuses, max |margin difference|).

Part 2 times end-to-end ``dataset generate`` (sampling, labelling, shard files; one process, as
``--workers 1``) into fresh temporary directories, alternating the paths, for ANYmal C.

On a shared machine only figures from the same run compare: quote the medians and ratios.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import numpy as np

from benchmarks.harness import interleave, machine_line, median_ratio, parser, print_table, write_record
from margin_rl.stability.analytic.margin import STATUSES, AnalyticSettings, analytic_margin_batch, worker_robot
from margin_rl.stability.analytic.sampling import sample_states
from margin_rl.stability.learned.dataset import DatasetSpec, generate

PATHS = {"per_state": AnalyticSettings(labelling="per_state"), "batched": AnalyticSettings(labelling="batched")}


def label_rounds(robot_name: str, n: int, rounds: int) -> tuple[tuple[object, ...], dict[str, object]]:
    """(table row, record) of the labelling function's rounds for one robot."""
    robot = worker_robot(robot_name)
    lams = sample_states(robot, n, seed=np.random.SeedSequence(0, spawn_key=(0,)))  # a dataset's shard 0
    for settings in PATHS.values():
        analytic_margin_batch(robot_name, lams[:64], settings, workers=1)  # warm-up (imports, caches)
    results = {}

    def runner(name: str):
        def run(_round: int) -> float:
            t0 = time.perf_counter()
            results[name] = analytic_margin_batch(robot_name, lams, PATHS[name], workers=1)
            return n / (time.perf_counter() - t0)

        return run

    rates = interleave({name: runner(name) for name in PATHS}, rounds, alternate=True)
    old, new = results["per_state"], results["batched"]
    ok = old.status == STATUSES.index("ok")
    diff = np.abs(new.margin[ok] - old.margin[ok])
    med = {name: statistics.median(v) for name, v in rates.items()}
    per_round = median_ratio(rates["batched"], rates["per_state"])
    counts = {k: v for k, v in old.counts().items() if v}
    ratio = med["batched"] / med["per_state"]
    changed = int((old.status != new.status).sum())
    row = (
        robot_name, n, f"{med['per_state']:.0f}", f"{med['batched']:.0f}", f"{ratio:.2f}", f"{per_round:.2f}",
        f"{old.n_lps.mean():.2f} / {new.n_lps.mean():.2f}", changed, f"{diff.max() * 1e3:.3f}",
        ", ".join(f"{k} {v}" for k, v in counts.items()),
    )  # fmt: skip
    record = {
        "states": n,
        "labels_per_s": rates,
        "ratio_of_medians": ratio,
        "median_per_round_ratio": per_round,
        "lps_per_label": {"per_state": old.n_lps.mean(), "batched": new.n_lps.mean()},
        "status_differences": changed,
        "max_abs_margin_diff_mm": diff.max() * 1e3,
        "statuses": counts,
    }
    return row, record


def end_to_end(robot_name: str, n: int, shard_size: int, rounds: int) -> tuple[tuple[object, ...], dict[str, object]]:
    """(table row, record) of alternating ``dataset generate`` runs into fresh directories."""
    with tempfile.TemporaryDirectory() as tmp:

        def runner(name: str):
            def run(index: int) -> float:
                spec = DatasetSpec(robot_name, n=n, shard_size=shard_size, seed=0, settings=PATHS[name])
                t0 = time.perf_counter()
                generate(spec, Path(tmp) / f"{name}_{index}", workers=1, progress=False)
                return n / (time.perf_counter() - t0)

            return run

        rates = interleave({name: runner(name) for name in PATHS}, rounds, alternate=True)
    med = {name: statistics.median(v) for name, v in rates.items()}
    per_round = median_ratio(rates["batched"], rates["per_state"])
    ratio = med["batched"] / med["per_state"]
    row = (
        robot_name, f"{n} ({shard_size} a shard)", f"{med['per_state']:.0f}", f"{med['batched']:.0f}",
        f"{ratio:.2f}", f"{per_round:.2f}",
    )  # fmt: skip
    record = {
        "samples": n,
        "shard_size": shard_size,
        "labels_per_s": rates,
        "ratio_of_medians": ratio,
        "median_per_round_ratio": per_round,
    }
    return row, record


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--n", type=int, default=2000, help="states per robot for the labelling rounds")
    args_parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (each path once a round)")
    args_parser.add_argument("--e2e-n", type=int, default=2000, help="samples of each end-to-end dataset (0: skip)")
    args_parser.add_argument("--e2e-rounds", type=int, default=3)
    args_parser.add_argument("--shard-size", type=int, default=500)
    args = args_parser.parse_args()

    print(machine_line())
    print(f"settings {PATHS['batched'].as_dict()}")
    print()
    labelling = {robot: label_rounds(robot, args.n, args.rounds) for robot in ("anymal_b", "anymal_c")}
    print_table(
        ("robot", "states", "per_state labels/s", "batched labels/s", "ratio of medians", "median per-round ratio",
         "LPs per label (per_state / batched)", "status differences", "max abs margin diff mm", "statuses"),
        [row for row, _ in labelling.values()],
    )  # fmt: skip
    record: dict[str, object] = {"labelling": {robot: rec for robot, (_, rec) in labelling.items()}}
    if args.e2e_n:
        row, record["end_to_end"] = end_to_end("anymal_c", args.e2e_n, args.shard_size, args.e2e_rounds)
        print()
        print_table(
            ("robot", "dataset generate samples", "per_state labels/s", "batched labels/s", "ratio of medians",
             "median per-round ratio"),
            [row],
        )  # fmt: skip
    write_record(args.json, "labelling", {**vars(args), "settings": PATHS["batched"].as_dict()}, record)


if __name__ == "__main__":
    main()
