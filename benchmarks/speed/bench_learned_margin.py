"""Benchmark: learned margin speed vs the analytic margin, measured side by side.

Usage:
    python benchmarks/speed/bench_learned_margin.py [--robot anymal_c] [--weights PATH.npz] [--n-analytic 300]
        [--json PATH]

Rows: one lambda value, one lambda value + gradient (numpy), a batch of 4096 (value), a batch of 4096
through the torch module, and the analytic margin on the same Table I states (one core, focused
projection). Each learned row is the median over 5 rounds of the mean time per call in a round. Prints a
Markdown table with the per-lambda speed-up.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import torch

from benchmarks.harness import machine_line, parser, print_table, time_per_call, write_record
from margin_rl import load_robot
from margin_rl.stability.analytic.margin import analytic_margin
from margin_rl.stability.analytic.sampling import sample_states
from margin_rl.stability.learned.model import LearnedMargin


def per_call(fn, calls: int) -> float:
    """Median over 5 rounds of the mean seconds per call in a round."""
    return statistics.median(time_per_call(fn, calls, rounds=5))


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--robot", default="anymal_c")
    args_parser.add_argument("--weights", default=None, help="weights .npz (default: the robot's bundled weights)")
    args_parser.add_argument("--n-analytic", type=int, default=300)
    args = args_parser.parse_args()
    model = LearnedMargin.load(args.weights or args.robot)
    robot = load_robot(args.robot)
    lams = sample_states(robot, 4096, seed=0)
    one = lams[0]
    single = per_call(lambda: model(one), 2000)
    single_grad = per_call(lambda: model.value_and_grad(one), 2000)
    batch = per_call(lambda: model(lams), 20)
    module = model.torch_module()
    x = torch.as_tensor(lams, dtype=torch.float32)
    with torch.no_grad():
        batch_torch = per_call(lambda: module(x), 20)
    t0 = time.perf_counter()
    for lam in lams[: args.n_analytic]:
        analytic_margin(robot, lam)
    analytic = (time.perf_counter() - t0) / args.n_analytic
    print(machine_line())
    print(f"robot {args.robot}, torch threads {torch.get_num_threads()}")
    print()
    rows = [
        ("analytic margin, one lambda (one core)", analytic, 1),
        ("learned, one lambda, value (numpy)", single, 1),
        ("learned, one lambda, value + gradient (numpy)", single_grad, 1),
        ("learned, batch of 4096, value (numpy float32)", batch, 4096),
        ("learned, batch of 4096, value (torch module)", batch_torch, 4096),
    ]
    table = []
    for name, t, n in rows:
        unit = f"{t * 1e6:.1f} µs" if t < 1e-3 else f"{t * 1e3:.2f} ms"
        table.append((name, unit, f"{n / t:,.0f}", f"{analytic / (t / n):,.0f}x"))
    print_table(("evaluation", "time per call", "lambda/s", "speed-up per lambda vs analytic"), table)
    results = {
        name: {"seconds_per_call": t, "lambdas_per_call": n, "speed_up_vs_analytic": analytic / (t / n)}
        for name, t, n in rows
    }
    write_record(args.json, "learned_margin", {**vars(args), "torch_threads": torch.get_num_threads()}, results)


if __name__ == "__main__":
    main()
