"""A margin-weight sweep over the evaluation grid: every weight's runs against weight 0, cell by cell, and the rule
that picks a weight.

Usage (ANYmal B, the ``robust`` recipe; each ``compare --runs`` pairs the weight-0 runs with one other weight, and
a grid cell already evaluated for the same policy is reused, so the weight-0 runs are evaluated once)::

    python -m margin_rl.train compare --runs runs/robust_pilot/b_mw0_s* runs/robust_pilot/b_mw0.1_s* \\
        --eval-episodes 64 --eval-seed 5000 --eval-commands 0.5 1.0 \\
        --eval-conditions friction_0.4 mass_-20 mass_+20 --out results/sweep_b_mw0.1
    python benchmarks/studies/sweep_grid.py docs/comparison/robust_pilot/compare_anymal_b.json \\
        results/sweep_b_mw*/compare.json --json docs/comparison/robust_sweep/sweep_anymal_b.json

The inputs are ``compare.json`` reports (``compare --runs`` or ``compare`` with ``--eval-commands`` /
``--eval-conditions``) of one environment, with the same evaluation episodes and seed. A run is identified by its
margin weight and training seed; a run found in several reports must have the same metrics in each (the same
evaluation reused), otherwise the reports disagree and the script stops, naming the run.

**The rule** (stated before the sweep's runs were evaluated): a weight is *eligible* when, in every grid cell, its
falls (mean over its seeds) are at most weight 0's + 1 point (the comparison's falls target). Among the
eligible weights the largest whose base linear acceleration RMS at the main cell (nominal, the comparison's
command) is at least 15 % below weight 0's is chosen (the acceleration target); if none is 15 % lower, the largest
eligible weight. If no weight is eligible, none is chosen and the JSON says by how much each weight misses (its
worst cell). With two or three seeds per weight this is a rule on means, not a test: a weight passes or fails by
one bad seed, which the per-seed falls in the output show.
"""

from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from margin_rl.train.analysis.significance import compare_seeds
from margin_rl.train.runs import write_json

METRICS = ("fell", "velocity_error_mean", "lin_acc_rms", "ang_acc_rms", "stance_width_mean", "margin_mean")
"""The per-run means kept from each cell (the rest of a run's metrics are not needed for the sweep)."""

FALLS_TOLERANCE = 0.01
"""A weight may fall this much more often than weight 0 (fraction of episodes, mean over seeds) in every cell."""

ACCELERATION_REDUCTION = 0.15
"""The relative reduction of base linear acceleration RMS at the main cell that a chosen weight should reach."""


def _cells(report: dict[str, Any]) -> list[tuple[str, float, dict[str, Any]]]:
    """(condition, command, variants) of the main cell and every grid cell of a compare report."""
    settings = report["settings"]
    cells = [("nominal", float(settings["forward_velocity"]), report["variants"])]
    for cell in report.get("grid") or []:
        key = (cell["condition"], float(cell["forward_velocity"]))
        if key != cells[0][:2]:
            cells.append((*key, cell["variants"]))
    return cells


def collect_runs(reports: list[tuple[str, dict[str, Any]]]) -> tuple[dict[str, Any], dict[tuple, dict]]:
    """The runs of several compare reports: (common settings, {(weight, seed): {(condition, command): metrics}}).

    Raises:
        ValueError: reports of different environments or evaluation protocols, or one run with different metrics
            in two reports (naming the run and the reports).
    """
    if not reports:
        raise ValueError("give at least one compare.json report")
    protocol_keys = ("env_id", "eval_episodes", "eval_seed", "forward_velocity", "warmup_s")
    first_name, first = reports[0]
    protocol = {key: first["settings"].get(key) for key in protocol_keys}
    runs: dict[tuple[float, int], dict[tuple[str, float], dict[str, float | None]]] = defaultdict(dict)
    seen_in: dict[tuple, str] = {}
    for name, report in reports:
        other = {key: report["settings"].get(key) for key in protocol_keys}
        if other != protocol:
            raise ValueError(
                f"{name}: evaluated with {other}, {first_name} with {protocol}: a sweep needs one environment and "
                "one evaluation protocol"
            )
        for condition, command, variants in _cells(report):
            for variant in variants.values():
                weight = float(variant["margin_weight"])
                for run in variant["runs"]:
                    key, cell = (weight, int(run["seed"])), (condition, command)
                    metrics = {metric: run["metrics"].get(metric) for metric in METRICS}
                    known = runs[key].get(cell)
                    if known is not None and known != metrics:
                        raise ValueError(
                            f"margin weight {weight:g}, seed {key[1]}, cell {condition} {command:g} m/s: "
                            f"{name} and {seen_in[(*key, *cell)]} report different metrics (two different "
                            "policies or evaluations under one name); give one of them"
                        )
                    runs[key][cell] = metrics
                    seen_in[(*key, *cell)] = name
    return protocol, dict(runs)


def _mean(values: list[float | None]) -> float | None:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(finite)) if finite else None


def sweep(protocol: dict[str, Any], runs: dict[tuple, dict]) -> dict[str, Any]:
    """Per weight and cell: the seeds' values, their mean and (weight ≠ 0) the Welch comparison with weight 0;
    then the rule of the module docstring."""
    weights = sorted({weight for weight, _ in runs})
    if 0.0 not in weights:
        raise ValueError("the sweep needs runs of margin weight 0 (the baseline every weight is compared with)")
    seen = list(dict.fromkeys(cell for per_cell in runs.values() for cell in per_cell))  # the reports' order
    conditions = list(dict.fromkeys(["nominal", *(condition for condition, _ in seen)]))
    cells = sorted(seen, key=lambda cell: (conditions.index(cell[0]), cell[1]))
    main_cell = ("nominal", float(protocol["forward_velocity"]))
    by_weight: dict[str, Any] = {}
    for weight in weights:
        seeds = sorted(seed for w, seed in runs if w == weight)
        per_cell = {}
        for cell in cells:
            present = [seed for seed in seeds if cell in runs[(weight, seed)]]
            values = {metric: [runs[(weight, seed)][cell][metric] for seed in present] for metric in METRICS}
            entry: dict[str, Any] = {
                "seeds": present,
                "values": values,
                "mean": {metric: _mean(v) for metric, v in values.items()},
            }
            if weight != 0.0:  # weight 0 sorts first: its cells are in by_weight already
                baseline = by_weight["0"]["cells"][_cell_key(cell)]["values"]
                entry["versus_weight_0"] = {
                    metric: asdict(
                        compare_seeds(
                            metric,
                            baseline[metric],
                            values[metric],
                            names=("margin weight 0", f"margin weight {weight:g}"),
                        )
                    )
                    for metric in METRICS
                }
            per_cell[_cell_key(cell)] = entry
        by_weight[f"{weight:g}"] = {"seeds": seeds, "cells": per_cell}
    return {
        "protocol": protocol,
        "cells": [_cell_key(cell) for cell in cells],
        "main_cell": _cell_key(main_cell),
        "by_weight": by_weight,
        "rule": apply_rule(by_weight, _cell_key(main_cell)),
    }


def _cell_key(cell: tuple[str, float]) -> str:
    return f"{cell[0]}__v{cell[1]:g}"


def apply_rule(by_weight: dict[str, Any], main_cell: str) -> dict[str, Any]:
    """The rule of the module docstring on :func:`sweep`'s ``by_weight``: per weight its worst cell's excess falls
    over weight 0 and its linear-acceleration change at the main cell; the chosen weight (or None)."""
    baseline = by_weight["0"]["cells"]
    verdicts = {}
    for weight, group in by_weight.items():
        if weight == "0":
            continue
        excess = {
            cell: entry["mean"]["fell"] - baseline[cell]["mean"]["fell"]
            for cell, entry in group["cells"].items()
            if cell in baseline and entry["mean"]["fell"] is not None and baseline[cell]["mean"]["fell"] is not None
        }
        worst = max(excess, key=excess.get) if excess else None
        main = group["cells"].get(main_cell, {}).get("versus_weight_0", {}).get("lin_acc_rms", {})
        over = sorted(cell for cell, value in excess.items() if value > FALLS_TOLERANCE + 1e-12)
        verdicts[weight] = {
            "worst_cell": worst,
            "worst_excess_falls": excess.get(worst),
            "cells_over_tolerance": over,
            "eligible": bool(excess) and not over,
            "lin_acc_relative_main": main.get("relative"),
            "lin_acc_p_main": main.get("p_value"),
        }
    eligible = [w for w, v in verdicts.items() if v["eligible"]]
    reaching = [
        w
        for w in eligible
        if verdicts[w]["lin_acc_relative_main"] is not None
        and verdicts[w]["lin_acc_relative_main"] <= -ACCELERATION_REDUCTION
    ]
    pool = reaching or eligible
    chosen = max(pool, key=float) if pool else None
    return {
        "falls_tolerance": FALLS_TOLERANCE,
        "acceleration_reduction": ACCELERATION_REDUCTION,
        "per_weight": verdicts,
        "chosen": chosen,
        "chosen_reaches_acceleration_target": chosen in reaching if chosen is not None else False,
    }


def markdown(result: dict[str, Any]) -> list[str]:
    """Two tables: falls per seed in every cell (out of the evaluation's episodes), then per weight the main cell's
    metrics against weight 0 and the rule's verdict."""
    episodes = result["protocol"]["eval_episodes"]
    weights = list(result["by_weight"])
    lines = [
        f"Falls out of {episodes} per training seed, each weight's seeds in order "
        + ", ".join(f"{w}: seeds {result['by_weight'][w]['seeds']}" for w in weights),
        "",
        "| cell | " + " | ".join(f"weight {w}" for w in weights) + " |",
        "|---|" + "---|" * len(weights),
    ]
    for cell in result["cells"]:
        row = []
        for w in weights:
            entry = result["by_weight"][w]["cells"].get(cell)
            falls = entry["values"]["fell"] if entry else []
            row.append(" / ".join("–" if f is None else f"{round(f * episodes)}" for f in falls) or "–")
        condition, command = cell.split("__v")
        lines.append(f"| {condition} {command} m/s | " + " | ".join(row) + " |")
    main = result["main_cell"]
    lines += [
        "",
        f"Main cell ({main.replace('__v', ' ')} m/s), mean over seeds; change against weight 0 with Welch's p; "
        "the rule",
        "",
        "| weight | velocity error [m/s] | lin. acc. RMS [m/s²] | ang. acc. RMS [rad/s²] | stance width [m] "
        "| learned margin [m] | worst cell (excess falls) | eligible |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for w in weights:
        entry = result["by_weight"][w]["cells"][main]
        versus = entry.get("versus_weight_0", {})

        def cell(metric: str, spec: str, entry: dict = entry, versus: dict = versus) -> str:
            value = entry["mean"][metric]
            text = "–" if value is None else f"{value:{spec}}"
            difference = versus.get(metric)
            if difference and difference["relative"] is not None:
                p = difference["p_value"]
                text += f" ({difference['relative']:+.0%}" + ("" if p is None else f", p = {p:.2g}") + ")"
            return text

        verdict = result["rule"]["per_weight"].get(w)
        worst = (
            "–"
            if verdict is None or verdict["worst_cell"] is None
            else f"{verdict['worst_cell'].replace('__v', ' ')} (+{verdict['worst_excess_falls'] * 100:.1f} points)"
        )
        eligible = "baseline" if verdict is None else ("yes" if verdict["eligible"] else "no")
        lines.append(
            f"| {w} | {cell('velocity_error_mean', '.3f')} | {cell('lin_acc_rms', '.2f')} "
            f"| {cell('ang_acc_rms', '.1f')} | {cell('stance_width_mean', '.3f')} | {cell('margin_mean', '.3f')} "
            f"| {worst} | {eligible} |"
        )
    chosen = result["rule"]["chosen"]
    lines += ["", f"Chosen weight: {chosen if chosen is not None else 'none (no weight is eligible)'}"]
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("reports", nargs="+", type=Path, help="compare.json reports of one environment")
    parser.add_argument("--json", type=Path, required=True, help="where to write the sweep (JSON)")
    args = parser.parse_args(argv)
    missing = [str(path) for path in args.reports if not path.is_file()]
    if missing:
        parser.error(f"no such report: {', '.join(missing)}")
    try:
        reports = [(str(path), json.loads(path.read_text())) for path in args.reports]
        result = sweep(*collect_runs(reports))
    except (ValueError, KeyError) as exc:
        parser.error(f"{type(exc).__name__}: {exc}")
    write_json(args.json, result)
    print("\n".join(markdown(result)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
