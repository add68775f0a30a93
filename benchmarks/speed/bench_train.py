"""Benchmark: PPO training throughput (environment steps per second) of both backends, margin on and off.

Usage:
    python benchmarks/speed/bench_train.py [--env margin_rl/AnymalB-v1] [--num-envs 128] [--steps 30000]
        [--backends rsl sb3] [--margin-weights PATH] [--device cpu] [--json PATH]

Each configuration trains a fresh run of ``--steps`` environment steps into a temporary folder (checkpoints and
TensorBoard included, as in real use) and reports steps/s over the whole call (environment construction and the
final export included, so short budgets understate the steady rate) and over the learning loop only (from the
rsl-rl ``Perf/total_fps`` / SB3 ``Perf/total_fps`` TensorBoard scalars, the median over updates). The learned
margin uses the bundled weights unless ``--margin-weights`` is given. Prints a Markdown table.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("GIT_PYTHON_REFRESH", "quiet")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

from benchmarks.harness import machine_line, markdown_header, markdown_row, parser, write_record


def steady_fps(run_dir: Path) -> float:
    """Median of the ``Perf/total_fps`` scalars of a run (steps/s over collection and update)."""
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader
    from tensorboard.util import tensor_util

    values = [
        float(tensor_util.make_ndarray(v.tensor)) if v.HasField("tensor") else v.simple_value
        for path in (run_dir / "tb").glob("events.out.tfevents.*")
        for event in EventFileLoader(str(path)).Load()
        for v in event.summary.value
        if v.tag == "Perf/total_fps"
    ]
    return statistics.median(values) if values else float("nan")


def measure(env_id: str, backend: str, num_envs: int, steps: int, margin: dict[str, object], device: str) -> tuple:
    from margin_rl.train.commands.train import make_spec, train

    spec = make_spec(
        env_id,
        backend,
        margin,
        None,
        seed=0,
        num_envs=num_envs,
        total_steps=steps,
        checkpoint_every=10 * steps,
        device=device,
    )
    with tempfile.TemporaryDirectory() as tmp:
        result = train(spec, Path(tmp) / "run", progress=False)
        return result.steps_per_second, steady_fps(result.run_dir), result.env_steps


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--env", default="margin_rl/AnymalB-v1")
    args_parser.add_argument("--num-envs", type=int, default=128)
    args_parser.add_argument("--steps", type=int, default=30_000)
    args_parser.add_argument("--backends", nargs="+", default=["rsl", "sb3"], choices=["rsl", "sb3"])
    args_parser.add_argument("--margin-weights", default=None, help="learned-margin weights .npz (default: bundled)")
    args_parser.add_argument("--device", default="cpu")
    args = args_parser.parse_args()
    learned: dict[str, object] = {"margin": "learned", "margin_weight": 1.0}
    if args.margin_weights:
        learned["margin_weights"] = args.margin_weights
    margins = {"learned margin, weight 1": learned, "no margin evaluation": {"margin": "none"}}
    print(machine_line())
    print(f"{args.env}, {args.num_envs} envs, {args.steps:,} steps per configuration, learner on {args.device}")
    print()
    print("\n".join(markdown_header(("backend", "margin", "steps/s (whole call)", "steps/s (learning loop, median)"))))
    record = []
    for backend in args.backends:
        for label, margin in margins.items():
            overall, steady, env_steps = measure(args.env, backend, args.num_envs, args.steps, margin, args.device)
            print(markdown_row((backend, label, f"{overall:,.0f}", f"{steady:,.0f}")), flush=True)
            record.append(
                {
                    "backend": backend,
                    "margin": label,
                    "env_steps": env_steps,
                    "whole_call": overall,
                    "learning_loop": steady,
                }
            )
    write_record(args.json, "train", args, record)


if __name__ == "__main__":
    main()
