"""Experiment: the extended margin m_x on the states walking policies visit.

Usage:
    python benchmarks/studies/bench_extended_margin.py --robot anymal_b --states data/rollouts_b_test.npz --envs 8 \
        [--steps 250] [--limit 4000] [--workers 2] [--json docs/learned_margin/extended_margin_anymal_b.json]

``--states`` is a recording of ``benchmarks/studies/bench_locomotion_distribution.py --states`` (or a split of it
by ``bench_margin_rollout_holdout.py``): blocks of ``--steps`` policy steps x ``--envs`` environments, step-major,
so state ``i`` and ``i + envs`` are one environment 20 ms apart. Measured, per robot:

1. where m_x comes from (m_a, the relaxed load, the support fallback) on the visited states;
2. the jump of the reward's margin between consecutive steps of one environment, split by what happens
   to the analytic status (ok -> ok, ok <-> no margin), with the floor (-0.5 m, what the environment gave
   states without m_a), with m_x, and with m_x clipped at the floor as the environment clips it;
3. the bisection's resolution: m_x with the default halvings vs 10 on the relaxed states;
4. whether feasibility is monotone in the load fraction alpha (a 1/32 grid on a sample of relaxed states);
5. the labelling cost: states per second for m_a and for m_x, side by side, one process.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from margin_rl import load_robot
from margin_rl.stability.analytic.extended import (
    DEFAULT_BISECTION_STEPS,
    SOURCES,
    extended_margin_batch,
    scale_dynamic_load,
)
from margin_rl.stability.analytic.margin import STATUSES, AnalyticSettings, analytic_margin_batch

FLOOR = -0.5  # the environment's clip floor: what a state without m_a was rated before m_x


def consecutive_pairs(n: int, envs: int, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i, i + envs) of one environment one policy step apart, within each recorded block."""
    block = envs * steps
    index = np.arange(n)
    later = index + envs
    same_block = (index // block) == (later // block)
    keep = same_block & (later < n)
    return index[keep], later[keep]


def jumps(margin: np.ndarray, ok: np.ndarray, first: np.ndarray, second: np.ndarray) -> dict[str, dict[str, float]]:
    """Median and 90th percentile |m(t+1) - m(t)| [cm] by the analytic status change."""
    out = {}
    groups = {
        "ok -> ok": ok[first] & ok[second],
        "ok <-> no m_a": ok[first] != ok[second],
        "no m_a -> no m_a": ~ok[first] & ~ok[second],
    }
    defined = np.isfinite(margin[first]) & np.isfinite(margin[second])  # m_x is NaN for unreachable feet
    for name, sel in groups.items():
        sel = sel & defined
        d = 100 * np.abs(margin[second] - margin[first])[sel]
        out[name] = {"pairs": int(sel.sum()), "median_cm": float(np.median(d)), "p90_cm": float(np.percentile(d, 90))}
    return out


def monotone_fraction(robot_name: str, lams: np.ndarray, workers: int) -> float:
    """Share of states whose feasible load fractions on a 1/32 grid form one interval [0, a]."""
    grid = np.linspace(0.0, 1.0, 33)
    scaled = np.concatenate([scale_dynamic_load(lams, a) for a in grid])
    ok = analytic_margin_batch(robot_name, scaled, workers=workers).status == STATUSES.index("ok")
    ok = ok.reshape(len(grid), len(lams)).T  # (states, grid)
    # Monotone: once infeasible, infeasible for every larger alpha.
    first_bad = np.where(~ok.all(axis=1), np.argmin(ok, axis=1), len(grid))
    monotone = [not ok[i, first_bad[i] :].any() for i in range(len(lams))]
    return float(np.mean(monotone))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", required=True)
    parser.add_argument("--states", type=Path, required=True)
    parser.add_argument("--envs", type=int, required=True, help="environments of the recording")
    parser.add_argument("--steps", type=int, default=250, help="policy steps per block of the recording")
    parser.add_argument("--limit", type=int, default=None, help="use the first LIMIT states (whole steps)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--monotone-states", type=int, default=60)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    robot = load_robot(args.robot)
    lam = np.load(args.states)["lam"].astype(float)
    if args.limit:
        lam = lam[: args.limit - args.limit % args.envs]

    t0 = time.perf_counter()
    result = extended_margin_batch(robot, lam, workers=args.workers)
    seconds = time.perf_counter() - t0
    ok = result.source == SOURCES.index("analytic")
    floor_margin = np.where(ok, result.analytic.margin, FLOOR)
    first, second = consecutive_pairs(len(lam), args.envs, args.steps)
    record: dict[str, object] = {
        "robot": args.robot,
        "states": len(lam),
        "recording": str(args.states),
        "sources": {name: float(np.mean(result.source == i)) for i, name in enumerate(SOURCES)},
        "statuses": {name: float(np.mean(result.status == i)) for i, name in enumerate(STATUSES)},
        "margin_percentiles_cm": {
            name: np.percentile(100 * result.margin[result.source == i], [5, 50, 95]).round(1).tolist()
            for i, name in enumerate(SOURCES)
            if (result.source == i).any()
        },
        "step_jumps_floor": jumps(floor_margin, ok, first, second),
        "step_jumps_extended": jumps(result.margin, ok, first, second),
        # What the reward sees: the environment clips the margin to [FLOOR, ...].
        "step_jumps_extended_clipped": jumps(np.maximum(result.margin, FLOOR), ok, first, second),
        "load_fraction_percentiles": np.percentile(
            result.load_fraction[result.source == SOURCES.index("relaxed")], [5, 25, 50, 75, 95]
        ).tolist(),
    }

    relaxed = np.flatnonzero(result.source == SOURCES.index("relaxed"))
    fine = extended_margin_batch(robot, lam[relaxed], workers=args.workers, bisection_steps=10)
    both = fine.source == SOURCES.index("relaxed")
    diff = 100 * (result.margin[relaxed] - fine.margin)[both]
    record["bisection_default_vs_10"] = {
        "default_steps": DEFAULT_BISECTION_STEPS,
        "states": int(both.sum()),
        "rms_cm": float(np.sqrt(np.mean(diff**2))),
        "p95_abs_cm": float(np.percentile(np.abs(diff), 95)),
    }
    pick = np.random.default_rng(0).choice(relaxed, size=min(args.monotone_states, len(relaxed)), replace=False)
    record["monotone_in_alpha"] = {"states": len(pick), "fraction": monotone_fraction(args.robot, lam[pick], 1)}

    # Cost, side by side in one process: m_a alone, then m_x (which includes m_a).
    sample = lam[: min(len(lam), 2000)]
    t0 = time.perf_counter()
    analytic_margin_batch(args.robot, sample, AnalyticSettings(), workers=1)
    t_analytic = time.perf_counter() - t0
    t0 = time.perf_counter()
    extended_margin_batch(robot, sample, workers=1)
    t_extended = time.perf_counter() - t0
    record["labels_per_second_one_process"] = {
        "analytic": len(sample) / t_analytic,
        "extended": len(sample) / t_extended,
        "ratio": t_extended / t_analytic,
    }
    record["seconds_all_states"] = seconds
    print(json.dumps(record, indent=1))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
