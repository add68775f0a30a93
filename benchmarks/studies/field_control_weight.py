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

Once those have trained, ``--choose REPORT`` applies the rule's second half (:func:`choose_control_weight`) to a
``compare`` report of the scanned control runs (margin weight 0: its "without margin" variant) against the margin
variant's runs (its "with margin" variant, whose mean linear acceleration RMS is the target), after setting apart
every scanned K whose policy does not walk (:func:`scan_of_report`)::

    python -m margin_rl.train compare --runs runs/field/c_ctrl*_s0 runs/field/c_mw0.1_s{0,1,2,3,4} \\
        --env margin_rl/AnymalC-v1 --eval-episodes 64 --eval-seed 5000 --forward-velocity 0.75 --out OUT
    python benchmarks/studies/field_control_weight.py --choose OUT/compare.json [--json CHOICE]
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

RULE_COMMAND = 0.75  # [m/s]
EVALUATION_SEED = 5000  # the study's evaluation seed, not a training seed
SCAN = (1.0, 10.0, 100.0)  # multiples of K₀ trained, one seed each
MATCH_TOLERANCE = 0.10  # a scanned K matches when its linear acceleration RMS is within ±10 % of the target's
WALKING_FALLS = 0.01  # the study's gate: a policy walks when at most 1 % of its evaluation episodes end in a fall


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


@dataclass(frozen=True)
class ControlChoice:
    """The control's weight K, chosen from the scan by the rule (:func:`choose_control_weight`)."""

    k: float  # the penalty weight the control's three seeds train with [per (m/s²)²]
    how: str  # "matched" (a scanned K within the tolerance), "interpolated" (log K between two) or "closest"
    target: float  # the margin variant's mean linear acceleration RMS [m/s²]
    measured: float | None  # the chosen K's linear acceleration RMS, when it was scanned (None: interpolated)
    relative_mismatch: float | None  # (measured − target) / target, when scanned


def choose_control_weight(
    target: float, scanned: Mapping[float, float], tolerance: float = MATCH_TOLERANCE
) -> ControlChoice:
    """The control's K from the scan ``scanned`` {K: linear acceleration RMS [m/s²] of its seed-0 policy} and the
    margin variant's mean ``target`` [m/s²], by the rule written before the scan (docs/studies/field_reward.md):

    1. The K whose acceleration lies within ``tolerance`` (relative) of the target; of several, the closest.
    2. Else, K interpolated linearly in log K between the two neighbouring scanned weights (sorted by K) whose
       accelerations bracket the target, a(K₁) and a(K₂) on either side: log K = log K₁ + (target − a₁) / (a₂ − a₁)
       · (log K₂ − log K₁); of several bracketing pairs (a scan that is not monotonic), the one with the smallest K.
    3. Else (every scanned K on one side of the target), the closest, its mismatch reported.

    Raises:
        ValueError: an empty scan, a weight that is not positive, or a non-finite or non-positive acceleration or
            target.
    """
    if not scanned:
        raise ValueError("the scan is empty: give the linear acceleration RMS of at least one scanned weight K")
    values = [target, tolerance, *scanned, *scanned.values()]
    if not all(np.isfinite(v) and v > 0 for v in values):
        raise ValueError(
            f"need a positive target, tolerance, weights and accelerations; got target {target}, tolerance "
            f"{tolerance}, scan {dict(scanned)}"
        )
    ks = sorted(scanned)

    def scanned_choice(k: float, how: str) -> ControlChoice:
        return ControlChoice(k, how, target, scanned[k], (scanned[k] - target) / target)

    closest = min(ks, key=lambda k: abs(scanned[k] - target))
    if abs(scanned[closest] - target) <= tolerance * target:
        return scanned_choice(closest, "matched")
    for low, high in itertools.pairwise(ks):
        a_low, a_high = scanned[low], scanned[high]
        if min(a_low, a_high) <= target <= max(a_low, a_high):
            fraction = (target - a_low) / (a_high - a_low)
            k = float(np.exp(np.log(low) + fraction * (np.log(high) - np.log(low))))
            return ControlChoice(k, "interpolated", target, None, None)
    return scanned_choice(closest, "closest")


@dataclass(frozen=True)
class ControlScan:
    """The scan read off a ``compare`` report (:func:`scan_of_report`)."""

    target: float  # the margin variant's mean linear acceleration RMS [m/s²]
    accelerations: dict[float, float]  # {K: linear acceleration RMS of its seed-0 policy [m/s²]}
    not_walking: dict[float, dict[str, Any]]  # {K: its metrics} of policies that fail the walking gate
    falls: dict[float, float]  # {K: share of its evaluation episodes ending in a fall}, every scanned K


def scan_of_report(report: Mapping[str, Any]) -> ControlScan:
    """The scan in a ``compare`` report of the scanned control runs ("without margin") against the margin variant
    ("with margin"), main cell: the target is the margin variant's mean ``lin_acc_rms``, each control run's K its
    ``reward_params.base_acceleration`` (read from its ``config.json``).

    A K whose policy does not walk is set apart in ``not_walking``, reported and never chosen: a control is compared
    with the margin variant on falls, pushes and gait, so it must pass the study's walking gate (at most
    :data:`WALKING_FALLS` of its episodes ending in a fall; a policy that falls in every episode before the warm-up
    second ends has no acceleration at all). The rule as first written did not say this; it was added when the
    scan's 10 K₀ and 100 K₀ policies fell in every episode (docs/studies/field_reward.md, "The control").

    Raises:
        ValueError: a control run without a penalty, two runs with the same K, a run without its folder, or no
            scanned K whose policy walks.
    """
    target = float(report["variants"]["with margin"]["mean"]["lin_acc_rms"])
    accelerations: dict[float, float] = {}
    not_walking: dict[float, dict[str, Any]] = {}
    falls: dict[float, float] = {}
    for run in report["variants"]["without margin"]["runs"]:
        if run["run_dir"] is None:
            raise ValueError(f"{run['policy']}: not a training run's folder, so its penalty weight is unknown")
        config = json.loads((Path(run["run_dir"]) / "config.json").read_text())
        k = float(config["env_config"]["reward_params"].get("base_acceleration", 0.0))
        if k <= 0 or k in falls:
            raise ValueError(f"{run['run_dir']}: penalty weight {k} is not positive, or was scanned twice")
        metrics = run["metrics"]
        falls[k] = float(metrics["fell"])
        if metrics["lin_acc_rms"] is None or not falls[k] <= WALKING_FALLS:
            not_walking[k] = {name: metrics.get(name) for name in ("fell", "velocity_error_mean", "lin_acc_rms")}
        else:
            accelerations[k] = float(metrics["lin_acc_rms"])
    if not accelerations:
        raise ValueError(
            f"no scanned weight left a policy that walks (falls ≤ {WALKING_FALLS:.0%}): {sorted(not_walking)}"
        )
    return ControlScan(target, accelerations, not_walking, falls)


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
    parser.add_argument("--margin-runs", nargs="+", type=Path)
    parser.add_argument("--baseline-runs", nargs="+", type=Path)
    parser.add_argument("--episodes", type=int, default=4, help="evaluation episodes (seeds) per run")
    parser.add_argument("--choose", type=Path, metavar="REPORT", help="choose K from a compare report of the scan")
    parser.add_argument("--json", type=Path, help="write the result here")
    args = parser.parse_args(argv)
    if args.choose is not None:
        if args.margin_runs or args.baseline_runs:
            parser.error("--choose reads a compare report: give it alone (with --json)")
        try:
            scan = scan_of_report(json.loads(args.choose.read_text()))
            choice = choose_control_weight(scan.target, scan.accelerations)
        except (OSError, KeyError, ValueError) as exc:
            parser.error(f"--choose {args.choose}: {exc}")
        apart = f"; set apart (fails the walking gate): {scan.not_walking}" if scan.not_walking else ""
        print(f"target {scan.target:.3f} m/s^2; scan {scan.accelerations}{apart}; K = {choice.k:.3e} ({choice.how})")
        record = {
            **asdict(choice),
            "scan": {str(k): a for k, a in scan.accelerations.items()},
            "not_walking": {str(k): m for k, m in scan.not_walking.items()},
            "falls": {str(k): f for k, f in scan.falls.items()},
        }
        _write_json(args.json, record)
        return 0
    if not (args.margin_runs and args.baseline_runs):
        parser.error("give --margin-runs and --baseline-runs (K₀), or --choose REPORT (the control's K)")
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
    report = {**asdict(result), "margin_runs": [str(r) for r in args.margin_runs]}
    _write_json(args.json, {**report, "baseline_runs": [str(r) for r in args.baseline_runs]})
    return 0


def _write_json(path: Path | None, report: dict[str, Any]) -> None:
    if path is not None:
        from margin_rl.train.runs import write_json  # atomic

        write_json(path, report)


if __name__ == "__main__":
    raise SystemExit(main())
