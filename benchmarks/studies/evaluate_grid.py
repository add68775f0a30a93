"""Evaluate training runs over commands and evaluation conditions, then summarise per cell (resumable).

Usage:
    python benchmarks/studies/evaluate_grid.py runs/robust_pilot/b_mw*_s* --commands 0.5 0.75 1.0 \
        --conditions nominal friction_0.4 mass_-20 mass_+20 --episodes 64 --seed 5000 \
        --json docs/comparison/robust_pilot_anymal_b.json

Every run's final policy is evaluated (``python -m margin_rl.train evaluate``'s :func:`evaluate`) at each fixed
forward command and in each condition of :mod:`margin_rl.train.analysis.conditions`, into
``<run>/eval_grid/<condition>__v<command>__s<seed>/metrics.json``; a cell whose metrics exist is not run again,
so a killed grid continues where it stopped. Unfinished runs (no final model) are left out with a note.

The summary JSON holds, per cell, the runs' figures and their grouping by margin weight with the comparison
against weight 0 over the training seeds (:mod:`summarise_runs`: mean ± std over seeds, Welch test and
bootstrap interval). A Markdown table is printed: falls, velocity error and base accelerations per cell and
variant, with the difference's p value.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from summarise_runs import by_weight, run_summary, versus_baseline

from margin_rl.train.analysis.conditions import CONDITIONS
from margin_rl.train.commands.evaluate import evaluate
from margin_rl.train.runs import read_json

GRID_DIR = "eval_grid"
TABLE_METRICS = (("fell", ".3f"), ("velocity_error_mean", ".3f"), ("lin_acc_rms", ".2f"), ("ang_acc_rms", ".1f"))


def cell_name(condition: str, command: float, seed: int) -> str:
    """Folder of one cell inside ``<run>/eval_grid``."""
    return f"{condition}__v{command:g}__s{seed}"


def finished(run: Path) -> bool:
    progress = run / "progress.json"
    return progress.is_file() and bool(read_json(progress).get("finished")) and (run / "final_model.pt").is_file()


def evaluate_cells(runs: list[Path], commands: list[float], conditions: list[str], episodes: int, seed: int) -> None:
    """Run every missing cell of every run (a cell's ``metrics.json`` is written last, atomically)."""
    for run in runs:
        for condition in conditions:
            for command in commands:
                out = run / GRID_DIR / cell_name(condition, command, seed)
                if (out / "metrics.json").is_file():
                    continue
                report, _ = evaluate(
                    run / "final_model.pt",
                    episodes=episodes,
                    seed=seed,
                    forward_velocity=command,
                    condition=condition,
                    out_dir=out,
                )
                fell = report["summary"]["fell"]["mean"]
                print(f"{run.name} {out.name}: falls {fell:.3f}", flush=True)


def summarise(runs: list[Path], commands: list[float], conditions: list[str], seed: int) -> dict[str, object]:
    cells = {}
    for condition in conditions:
        for command in commands:
            name = cell_name(condition, command, seed)
            members = [run_summary(run, f"{GRID_DIR}/{name}") for run in runs]
            cells[name] = {
                "condition": condition,
                "forward_velocity": command,
                "runs": members,
                "by_margin_weight": by_weight(members),
                "versus_baseline": versus_baseline(members),
            }
    return cells


def print_table(cells: dict[str, dict]) -> None:
    header = "| condition | command [m/s] | margin weight | seeds |"
    header += "".join(f" {metric} |" for metric, _ in TABLE_METRICS)
    print(header)
    print("|---|---|---|---|" + "---|" * len(TABLE_METRICS))
    for cell in cells.values():
        for weight, group in cell["by_margin_weight"].items():
            versus = cell["versus_baseline"].get(weight, {})
            row = f"| {cell['condition']} | {cell['forward_velocity']:g} | {weight} | {len(group['seeds'])} |"
            for metric, fmt in TABLE_METRICS:
                stats = group["metrics"].get(metric)
                text = f"{stats['mean']:{fmt}} ± {stats['std']:{fmt}}" if stats else "–"
                p_value = versus.get(metric, {}).get("p_value")
                row += f" {text}{f' (p={p_value:.2g})' if p_value is not None else ''} |"
            print(row)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--commands", nargs="+", type=float, default=[0.5, 0.75, 1.0])
    parser.add_argument("--conditions", nargs="+", choices=tuple(CONDITIONS), default=["nominal"])
    parser.add_argument("--episodes", type=int, default=64)
    parser.add_argument("--seed", type=int, default=5000, help="evaluation seed (held out: no run trains with it)")
    parser.add_argument("--json", type=Path, help="summary JSON")
    args = parser.parse_args()
    runs = sorted(run for run in args.runs if (run / "config.json").is_file())
    ready = [run for run in runs if finished(run)]
    for run in sorted(set(runs) - set(ready)):
        print(f"{run}: not finished, left out")
    if not ready:
        raise SystemExit("no finished run to evaluate")
    evaluate_cells(ready, args.commands, args.conditions, args.episodes, args.seed)
    cells = summarise(ready, args.commands, args.conditions, args.seed)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"cells": cells}, indent=1) + "\n")
    print_table(cells)


if __name__ == "__main__":
    main()
