"""Experiment: training recipes of the learned margin, side by side on one subset of a dataset.

Usage:
    python benchmarks/studies/bench_margin_recipe.py --data data/anymal_c --max-samples 600000 \\
        --recipe '{"epochs": 15}' --recipe '{"epochs": 15, "schedule": "cosine", "batch_size": 1024, "lr": 4e-3}'
    python benchmarks/studies/bench_margin_recipe.py --data data/anymal_c --max-samples 600000 \\
        --recipe '{"epochs": 15}' --recipe '{"epochs": 15, "mirror": "augment"}' \\
        --recipe '{"epochs": 15, "mirror": "tied"}'

Each ``--recipe`` is a JSON object of :class:`margin_rl.stability.learned.training.TrainConfig` fields on top of the
defaults. Every recipe trains a fresh paper-size MLP on the same seeded split of the first ``--max-samples``
``ok`` samples and reports its best validation RMSE and the wall time, as a Markdown table. Only the
ranking of recipes on one machine state is meaningful: the wall time depends on the load.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np
import torch

from margin_rl.stability.learned.dataset import load_dataset
from margin_rl.stability.learned.training import (
    TrainConfig,
    build_model,
    check_config,
    fit,
    split_indices,
    training_split,
)


def parse_recipe(text: str) -> TrainConfig:
    """A TrainConfig from a JSON object of its fields (unknown fields are refused by name)."""
    fields = {f.name for f in dataclasses.fields(TrainConfig)}
    values = json.loads(text)
    if not isinstance(values, dict) or set(values) - fields:
        raise SystemExit(f"--recipe {text!r}: expected a JSON object of TrainConfig fields {sorted(fields)}")
    return check_config(dataclasses.replace(TrainConfig(grad_check_states=0, patience=10**6), **values))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True)
    parser.add_argument("--max-samples", type=int, default=600_000)
    parser.add_argument("--recipe", action="append", required=True, help="JSON object of TrainConfig fields")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    recipes = [(text, parse_recipe(text)) for text in args.recipe]
    torch.set_num_threads(args.threads)
    ds = load_dataset(args.data, max_samples=args.max_samples)
    lam, margin = ds.lam.astype(np.float64), ds.margin.astype(np.float64)
    split = split_indices(len(lam), TrainConfig())
    print(f"{args.data}: {len(lam):,} ok samples, {len(split.train):,} for training, {len(split.val):,} validation")
    print("| recipe | best val RMSE [cm] | best epoch | wall time [s] |\n|---|---|---|---|")
    for text, config in recipes:
        torch.manual_seed(config.seed)
        model = build_model(lam[split.train], margin[split.train], config.mirror)
        t0 = time.perf_counter()
        lam_fit, margin_fit = training_split(lam[split.train], margin[split.train], config)
        summary = fit(model, lam_fit, margin_fit, lam[split.val], margin[split.val], config, progress=False)
        wall = time.perf_counter() - t0
        print(f"| `{text}` | {summary['best_val_rmse_cm']:.3f} | {summary['best_epoch']} | {wall:.0f} |", flush=True)


if __name__ == "__main__":
    main()
