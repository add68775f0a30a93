"""Summarise evaluated training runs into one small JSON and a Markdown table (what is committed of a run).

Usage:
    python benchmarks/studies/summarise_runs.py runs/v2_sweep/b_mw*_s* --eval eval5000 \
        --json docs/comparison/v2_sweep_anymal_b.json

Each run directory holds ``config.json`` (``margin_rl.train.commands.train``) and ``<eval>/metrics.json``
(``python -m margin_rl.train evaluate RUN/final_model.pt --episodes 64 --seed 5000 --out RUN/<eval>``). Run
directories are never committed; this keeps, per run, the settings that define it (environment, margin
weight, seed, steps, weights' sha256, acceleration filter, warm start) and the evaluation's per-metric mean and
std with the environment it ran in (``evaluate --env`` may differ from the training one), then groups the runs
by margin weight (mean ± std over seeds, and the number of seeds) and compares every other weight with weight 0
over the seeds (``"versus_baseline"``: difference, bootstrap interval and Welch test of
:func:`margin_rl.train.analysis.significance.compare_seeds`; printed as a second table).
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from dataclasses import asdict
from pathlib import Path

import numpy as np

from margin_rl.envs.config import upgrade_stored_env_config
from margin_rl.train.analysis.significance import compare_seeds, difference_table

METRICS = (
    "fell",
    "velocity_error_mean",
    "lin_acc_rms",
    "ang_acc_rms",
    "stance_width_mean",
    "margin_mean",
    "return",
)
"""Metrics tabulated and compared with weight 0."""

RECORDED = ("base_height_mean", "edge_landing_fraction", "forward_velocity_mean")
"""Metrics kept in the record beside :data:`METRICS` and every fall's cause (``termination/<cause>``), not tabulated."""


def run_summary(run: Path, eval_name: str) -> dict[str, object]:
    """Settings and evaluated metrics (mean, std over episodes) of one run."""
    config = json.loads((run / "config.json").read_text())
    metrics_path = run / eval_name / "metrics.json"
    if not metrics_path.is_file():
        raise SystemExit(f"{run}: no {eval_name}/metrics.json; evaluate the run first (see the module docstring)")
    metrics = json.loads(metrics_path.read_text())
    env = upgrade_stored_env_config(config.get("env_config", {}))  # runs stored by EnvConfig v0 too
    reward_params = env.get("reward_params") or {}
    progress = json.loads((run / "progress.json").read_text()) if (run / "progress.json").is_file() else {}
    return {
        "run": run.name,
        "env_id": config.get("env_id"),
        "margin_weight": env.get("margin_weight"),
        "seed": config.get("seed"),
        "env_steps": progress.get("env_steps"),
        "margin_weights": env.get("margin_weights") or f"bundled {env.get('robot')}",
        "acceleration_filter": env.get("acceleration_filter"),
        "alive_bonus": reward_params.get("alive_bonus"),
        "knee_clearance": reward_params.get("knee_clearance", 0.0),
        "termination_penalty": reward_params.get("termination_penalty", 0.0),
        "yaw_tracking": reward_params.get("yaw_tracking", 0.0),
        "margin_normals": env.get("margin_normals", "terrain"),  # stored before the option: the terrain's
        "recipe": config.get("recipe"),
        "init_from": config.get("init_from"),  # warm start (train --init-from), None: trained from scratch
        "evaluation": {
            "episodes": metrics.get("episodes"),
            "seed": metrics.get("seed"),
            "env_id": metrics.get("env_id"),
            "forward_velocity": metrics.get("forward_velocity"),
            "condition": metrics.get("condition"),
            "terrain": (metrics.get("env_config") or {}).get("terrain"),
            "terrain_config": (metrics.get("env_config") or {}).get("terrain_config"),
        },
        "metrics": {
            k: v for k, v in metrics["summary"].items() if k in METRICS or k in RECORDED or k.startswith("termination/")
        },
    }


def weight_groups(runs: list[dict[str, object]]) -> list[tuple[str, list[dict]]]:
    """The runs grouped by margin weight (keyed by its string), in increasing weight."""
    groups: dict[str, list[dict]] = defaultdict(list)
    for r in runs:
        groups[str(r["margin_weight"])].append(r)
    return sorted(groups.items(), key=lambda kv: float(kv[0]))


def by_weight(runs: list[dict[str, object]]) -> dict[str, dict[str, object]]:
    """Per margin weight: each metric's mean and std over the runs' (seeds') episode means."""
    out = {}
    for weight, members in weight_groups(runs):
        table = {}
        for metric in METRICS:
            values = [m["metrics"][metric]["mean"] for m in members if metric in m["metrics"]]
            values = [v for v in values if v is not None]
            if values:
                table[metric] = {"mean": float(np.mean(values)), "std": float(np.std(values)), "n_seeds": len(values)}
        out[weight] = {"seeds": sorted(m["seed"] for m in members), "metrics": table}
    return out


def versus_baseline(runs: list[dict[str, object]]) -> dict[str, dict[str, dict[str, object]]]:
    """Per margin weight other than 0: each metric against weight 0 over the seeds (the runs' episode means),
    as :class:`~margin_rl.train.analysis.significance.Difference` dicts; empty without runs at weight 0."""
    groups = weight_groups(runs)
    baseline = [r for weight, members in groups if float(weight) == 0 for r in members]
    if not baseline:
        return {}

    def seed_means(members: list[dict], metric: str) -> list[float | None]:
        return [m["metrics"][metric]["mean"] if metric in m["metrics"] else None for m in members]

    return {
        str(weight): {
            metric: asdict(
                compare_seeds(
                    metric,
                    seed_means(baseline, metric),
                    seed_means(members, metric),
                    names=("margin weight 0", f"margin weight {weight}"),
                )
            )
            for metric in METRICS
        }
        for weight, members in groups
        if float(weight) != 0
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--eval", default="eval5000", help="evaluation folder inside each run")
    parser.add_argument("--json", type=Path, required=True)
    args = parser.parse_args()
    runs = [run_summary(r, args.eval) for r in sorted(args.runs) if (r / "config.json").is_file()]
    record = {"runs": runs, "by_margin_weight": by_weight(runs), "versus_baseline": versus_baseline(runs)}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(record, indent=1) + "\n")
    print("| margin weight | seeds | falls | velocity error [m/s] | lin. acc. RMS [m/s²] | ang. acc. RMS [rad/s²] "
          "| stance width [m] | learned margin [m] |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for weight, group in record["by_margin_weight"].items():
        m = group["metrics"]
        cell = lambda name, fmt, m=m: (  # noqa: E731
            f"{m[name]['mean']:{fmt}} ± {m[name]['std']:{fmt}}" if name in m else "–"
        )
        print(
            f"| {weight} | {', '.join(map(str, group['seeds']))} | {cell('fell', '.3f')} "
            f"| {cell('velocity_error_mean', '.3f')} | {cell('lin_acc_rms', '.2f')} | {cell('ang_acc_rms', '.1f')} "
            f"| {cell('stance_width_mean', '.3f')} | {cell('margin_mean', '.3f')} |"
        )

    if record["versus_baseline"]:
        print()
        rows = [
            ((weight, metric), difference)
            for weight, differences in record["versus_baseline"].items()
            for metric, difference in differences.items()
        ]
        for line in difference_table(rows, ("margin weight", "metric"), "difference (weight − weight 0)"):
            print(line)


if __name__ == "__main__":
    main()
