"""Experiment: is the paper-size network what limits the learned margin's error? Widths side by side.

Usage:
    python benchmarks/studies/bench_margin_capacity.py --data data/anymal_c --max-samples 600000 --epochs 20 \\
        --widths 256,128,128 --widths 512,256,256 --widths 1024,512,512
    python benchmarks/studies/bench_margin_capacity.py --data data/anymal_c --train-subset 20000 --epochs 400 \\
        --schedule cosine --widths 256,128,128    # can the paper network fit (memorise) a small training set?

Every ``--widths`` (hidden layers) trains a fresh softsign MLP with the bundled recipe (Adam, batch 256,
lr 1e-3 halved on plateaus, or annealed with ``--schedule cosine``; no early stop) on the same seeded
split of the first ``--max-samples`` ok samples, optionally cut to its first ``--train-subset`` training
samples. It reports the RMSE on the training samples themselves (running mean over the last epoch, and
with the best-validation weights) and the best validation RMSE, as a Markdown table. A network whose
*training* error stays far above the target cannot reach the target on new states, whatever the amount of
data; one whose training error falls below it and whose validation error follows is limited by data or
training time instead.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM
from margin_rl.stability.learned.dataset import load_dataset
from margin_rl.stability.learned.training import (
    TrainConfig,
    build_model,
    check_config,
    fit,
    mean_squared_error,
    split_indices,
)


def parse_widths(text: str) -> tuple[int, ...]:
    """(47, *hidden, 1) from "256,128,128"."""
    try:
        hidden = tuple(int(w) for w in text.split(","))
    except ValueError:
        raise SystemExit(f"--widths {text!r}: expected comma-separated hidden-layer widths like 256,128,128") from None
    if not hidden or min(hidden) < 1:
        raise SystemExit(f"--widths {text!r}: widths must be positive")
    return (LAMBDA_DIM, *hidden, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True)
    parser.add_argument("--max-samples", type=int, default=600_000)
    parser.add_argument("--train-subset", type=int, default=None, help="use only this many training samples")
    parser.add_argument("--widths", action="append", required=True, help="hidden widths, e.g. 256,128,128")
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--mirror", choices=("none", "tied"), default="none")
    parser.add_argument(
        "--schedule",
        choices=("plateau", "cosine"),
        default="plateau",
        help="cosine for long fits of a small subset: the plateau schedule halves the rate to nothing once "
        "the validation error stops falling",
    )
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    architectures = [parse_widths(text) for text in args.widths]
    config = check_config(TrainConfig(epochs=args.epochs, batch_size=256, patience=10**6, grad_check_states=0,
                                      mirror=args.mirror, schedule=args.schedule))  # fmt: skip
    torch.set_num_threads(args.threads)
    ds = load_dataset(args.data, max_samples=args.max_samples)
    lam, margin = ds.lam.astype(np.float64), ds.margin.astype(np.float64)
    split = split_indices(len(lam), config)
    train = split.train[: args.train_subset] if args.train_subset else split.train
    print(f"{args.data}: {len(lam):,} ok samples; {len(train):,} training, {len(split.val):,} validation; "
          f"{args.epochs} epochs, batch 256, {args.schedule} schedule, mirror {args.mirror}")  # fmt: skip
    print(
        "| widths | parameters | train RMSE, last epoch [cm] | train RMSE at best val [cm] | best val RMSE [cm] "
        "| best epoch | wall [s] |\n|---|---|---|---|---|---|---|"
    )
    x_train = torch.as_tensor(lam[train], dtype=torch.float32)
    y_train = torch.as_tensor(margin[train], dtype=torch.float32)
    for widths in architectures:
        torch.manual_seed(config.seed)
        model = build_model(lam[train], margin[train], config.mirror, widths=widths)
        n_params = sum(p.numel() for p in model.parameters())
        t0 = time.perf_counter()
        summary = fit(model, lam[train], margin[train], lam[split.val], margin[split.val], config, progress=False)
        wall = time.perf_counter() - t0
        train_rmse = 100 * mean_squared_error(model, x_train, y_train) ** 0.5  # best-validation weights
        print(f"| {'-'.join(map(str, widths))} | {n_params:,} | {summary['last_train_rmse_cm']:.3f} "
              f"| {train_rmse:.3f} | {summary['best_val_rmse_cm']:.3f} | {summary['best_epoch']} | {wall:.0f} |",
              flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
