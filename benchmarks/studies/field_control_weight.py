"""The field-reward study's control: the first weight K₀ of its plain acceleration penalty, by the rule written before
any control run (docs/studies/field_reward.md, "The control").

K₀ gives the penalty K |a|² the same size in the baseline's reward as the margin term has in the margin variant's:
K₀ = (the margin variant's mean per-step |margin term|) / (the baseline's mean per-step |a|²), both at the study's
command (0.75 m/s), nominal condition, after each episode's first second, |a| the CoM acceleration the comparison's
``lin_acc_rms`` averages. The margin term of a step is its weight in the run's reward (``reward_weights["margin"]``)
times the clipped margin; both are read off deterministic evaluation episodes of the trained policies (one episode
per evaluation seed, ``--episodes`` seeds from 5000, as the study's evaluations). The control then trains one seed at
each of K₀, 10 K₀ and 100 K₀::

    python benchmarks/studies/field_control_weight.py --margin-runs runs/field/c_mw0.1_s0 runs/field/c_mw0.1_s1 \\
        --baseline-runs runs/field/c_mw0_s0 runs/field/c_mw0_s1 [--episodes 4] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

RULE_COMMAND = 0.75  # [m/s]
EVALUATION_SEED = 5000  # the study's evaluation seed, not a training seed
SCAN = (1.0, 10.0, 100.0)  # multiples of K₀ trained, one seed each


@dataclass(frozen=True)
class ControlWeight:
    """K₀ and what it was read from."""

    margin_term_abs: float  # the margin variant's mean per-step |margin term|
    acceleration_sq: float  # the baseline's mean per-step |a|² [m²/s⁴]
    k0: float  # margin_term_abs / acceleration_sq [per (m/s²)²]
    scan: tuple[float, ...]  # the weights trained: K₀ times SCAN
    steps: dict[str, int]  # steps averaged per variant


def control_weight(margin_terms: np.ndarray, accelerations: np.ndarray) -> ControlWeight:
    """K₀ from the margin variant's per-step margin terms (n,) and the baseline's per-step CoM accelerations (m, 3).

    Raises:
        ValueError: empty or non-finite inputs, accelerations not (m, 3), or a baseline that never accelerates.
    """
    terms = np.asarray(margin_terms, dtype=float).ravel()
    acc = np.asarray(accelerations, dtype=float)
    if terms.size == 0 or acc.ndim != 2 or acc.shape[1] != 3 or acc.shape[0] == 0:
        raise ValueError(f"need margin terms (n,) and accelerations (m, 3), got {terms.shape} and {acc.shape}")
    if not (np.isfinite(terms).all() and np.isfinite(acc).all()):
        raise ValueError("margin terms and accelerations must be finite")
    magnitude, squared = float(np.mean(np.abs(terms))), float(np.mean(np.sum(acc**2, axis=1)))
    if squared <= 0:
        raise ValueError("the baseline's accelerations are all zero: no penalty weight matches them")
    k0 = magnitude / squared
    steps = {"margin": int(terms.size), "baseline": int(acc.shape[0])}
    return ControlWeight(magnitude, squared, k0, tuple(k0 * m for m in SCAN), steps)


def episode_steps(run: Path, episodes: int) -> tuple[np.ndarray, np.ndarray]:
    """(margin terms (n,), CoM accelerations (n, 3)) of ``episodes`` deterministic nominal episodes of ``run``'s final
    policy at :data:`RULE_COMMAND`, after each episode's warm-up second."""
    from margin_rl.train.analysis.episodes import run_episodes
    from margin_rl.train.artifacts.policies import load_policy
    from margin_rl.train.commands.evaluate import evaluation_target

    policy = load_policy(run / "final_model.pt")
    target = evaluation_target(policy, None, None, RULE_COMMAND)
    weight = target.config.reward_weights.get("margin", 0.0)
    terms, accelerations = [], []
    for k in range(episodes):  # one episode per seed: run_episodes keeps the first episode's trajectory
        evaluation = run_episodes(policy, target, num_episodes=1, seed=EVALUATION_SEED + k)
        kept = evaluation.trajectory["time"] > evaluation.warmup_s
        terms.append(weight * evaluation.trajectory["margin"][kept])
        accelerations.append(evaluation.trajectory["lin_acc"][kept])
    return np.concatenate(terms), np.concatenate(accelerations)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--margin-runs", nargs="+", type=Path, required=True)
    parser.add_argument("--baseline-runs", nargs="+", type=Path, required=True)
    parser.add_argument("--episodes", type=int, default=4, help="evaluation episodes (seeds) per run")
    parser.add_argument("--json", type=Path, help="write the result here")
    args = parser.parse_args(argv)
    missing = [str(r) for r in (*args.margin_runs, *args.baseline_runs) if not (r / "final_model.pt").is_file()]
    if missing:
        parser.error(f"no final_model.pt in {missing}: give finished runs")
    margin = [episode_steps(run, args.episodes) for run in args.margin_runs]
    baseline = [episode_steps(run, args.episodes) for run in args.baseline_runs]
    if any(abs(terms).max() > 0 for terms, _ in baseline):
        parser.error("a baseline run has a margin term in its reward: give runs trained with margin weight 0")
    result = control_weight(np.concatenate([t for t, _ in margin]), np.concatenate([a for _, a in baseline]))
    print(
        f"mean |margin term| {result.margin_term_abs:.3e} per step, baseline mean |a|^2 {result.acceleration_sq:.2f} "
        f"(m/s^2)^2 -> K0 {result.k0:.3e}; train K = {', '.join(f'{k:.3e}' for k in result.scan)}"
    )
    if args.json:
        report = {**asdict(result), "margin_runs": [str(r) for r in args.margin_runs]}
        report["baseline_runs"] = [str(r) for r in args.baseline_runs]
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
