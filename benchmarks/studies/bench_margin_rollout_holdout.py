"""Learned margins on the states of a walking policy that none of their labels came from.

Usage:
    # 1. record the visited lambdas of the bundled ANYmal B policies (6 policies x 5 conditions x 8 envs x 250 steps)
    python benchmarks/studies/bench_locomotion_distribution.py --robot anymal_b --bundle anymal_b --num-envs 8 \
        --steps 250 --states data/rollouts_anymal_b.npz
    # 2. split them by policy: the last policy's states are held out
    python benchmarks/studies/bench_margin_rollout_holdout.py split --states data/rollouts_anymal_b.npz --policies 6 \
        --block 2000 --train data/rollouts_b_train.npz --test data/rollouts_b_test.npz
    # 3. label states around the other policies' states, train (see BENCHMARKS.md), then compare weights:
    python benchmarks/studies/bench_margin_rollout_holdout.py evaluate --robot anymal_b \
        --test data/rollouts_b_test.npz --weights anymal_b --weights data/w_v2_rollouts_b.npz ...

``evaluate`` labels the held-out states with the analytic margin m_a and the extended margin m_x
(:mod:`margin_rl.stability.analytic.extended`; cached beside the test file) and prints, per weights file, the RMSE,
median
absolute error and sign agreement against m_a on the ``ok`` states and against m_x on every state that has one,
and the share of states outside that network's training ranges.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from margin_rl import load_robot
from margin_rl.stability import STATUSES, LearnedMargin
from margin_rl.stability.analytic.extended import extended_margin_batch


def split(states: Path, policies: int, block: int, train: Path, test: Path, held_out: int = -1) -> None:
    """Blocks of ``block`` states cycle through ``policies`` policies (condition-major); policy ``held_out``
    (an index in the recording's policy order, default the last) is held out."""
    lam = np.load(states)["lam"]
    if len(lam) % (policies * block):
        raise SystemExit(f"{states}: {len(lam)} states are not whole blocks of {policies} x {block}")
    blocks = lam.reshape(-1, block, lam.shape[1])
    policy = np.arange(len(blocks)) % policies
    held = policy == held_out % policies
    np.savez_compressed(train, lam=blocks[~held].reshape(-1, lam.shape[1]))
    np.savez_compressed(test, lam=blocks[held].reshape(-1, lam.shape[1]))
    print(f"train {train}: {(~held).sum() * block} states; test {test}: {held.sum() * block}")


def labels(robot: str, test: Path, workers: int = 2) -> tuple[np.ndarray, ...]:
    """(lam, m_a, status, m_x) of the held-out states, cached beside the test file."""
    cache = test.with_name(test.stem + "_labels_v2.npz")
    if cache.is_file():
        with np.load(cache) as z:
            return z["lam"], z["margin"], z["status"], z["extended"]
    lam = np.load(test)["lam"].astype(float)
    lam = lam[np.isfinite(lam).all(axis=1)]
    result = extended_margin_batch(load_robot(robot), lam, workers=workers)
    margin, status = np.asarray(result.analytic.margin), np.asarray(result.status)
    np.savez(cache, lam=lam, margin=margin, status=status, extended=result.margin)
    return lam, margin, status, result.margin


def scores(pred: np.ndarray, truth: np.ndarray) -> str:
    err = pred - truth
    return (
        f"{100 * np.sqrt(np.mean(err**2)):.1f} cm | {100 * np.median(np.abs(err)):.1f} cm "
        f"| {100 * np.mean((pred >= 0) == (truth >= 0)):.1f} %"
    )


def evaluate(robot: str, test: Path, weights: list[str]) -> None:
    lam, margin, status, extended = labels(robot, test)
    ok = status == STATUSES.index("ok")
    defined = np.isfinite(extended)
    print(
        f"{test}: {len(lam)} held-out states, {ok.sum()} with an analytic margin m_a ({100 * ok.mean():.1f} %), "
        f"{defined.sum()} with an extended margin m_x ({100 * defined.mean():.1f} %)\n"
    )
    print(
        "| weights | vs m_a (ok states): RMSE | median abs. error | sign | vs m_x (all with m_x): RMSE "
        "| median abs. error | sign | outside its training ranges |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in weights:
        model = LearnedMargin.load(name)
        pred = np.asarray(model(lam))
        print(
            f"| {name} | {scores(pred[ok], margin[ok])} | {scores(pred[defined], extended[defined])} "
            f"| {100 * np.mean(model.out_of_distribution(lam)):.0f} % |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    s = sub.add_parser("split")
    s.add_argument("--states", type=Path, required=True)
    s.add_argument("--policies", type=int, required=True)
    s.add_argument("--block", type=int, required=True, help="states per policy and condition (envs x steps)")
    s.add_argument("--train", type=Path, required=True)
    s.add_argument("--test", type=Path, required=True)
    s.add_argument("--held-out", type=int, default=-1, help="index of the held-out policy (default: the last)")
    e = sub.add_parser("evaluate")
    e.add_argument("--robot", required=True)
    e.add_argument("--test", type=Path, required=True)
    e.add_argument("--weights", action="append", required=True, help="robot name (bundled) or .npz (repeatable)")
    args = parser.parse_args()
    if args.command == "split":
        split(args.states, args.policies, args.block, args.train, args.test, args.held_out)
    else:
        evaluate(args.robot, args.test, args.weights)


if __name__ == "__main__":
    main()
