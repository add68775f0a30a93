"""The field-reward study's pilot, judged by the rule written before its runs (docs/studies/field_reward.md).

Usage (a ``compare`` report of the pilot's runs, evaluated at the three commands in the nominal condition)::

    python -m margin_rl.train compare --runs runs/field/c_mw0_s0 runs/field/c_mw0_s1 runs/field/c_mw0.1_s0 \\
        runs/field/c_mw0.1_s1 --env margin_rl/AnymalC-v1 --eval-episodes 64 --eval-seed 5000 \\
        --forward-velocity 0.75 --eval-commands 0.5 1.0 --eval-conditions nominal --out docs/comparison/field/pilot_c
    python benchmarks/studies/field_weight_rule.py docs/comparison/field/pilot_c/compare.json [--json OUT]

The gate: both variants, pooled over seeds, fall in ≤ 1 % of the nominal episodes at every command with a
heading-velocity error ≤ 0.05 m/s, and the margin variant falls no more than the baseline + 1 point in every cell.
The rule, in order: (1) a baseline that fails the gate means the recipe is wrong for both variants; (2) a margin
variant that fails its part of the gate (falls) halves the weight; (3) a margin term under 2 % of the reward
(``margin_reward_share`` at 0.75 m/s) whose linear acceleration is within 5 % of the baseline's triples it; (4)
otherwise the weight stays. Prints the evidence and the decision.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

from benchmarks.studies.headline_table import as_report, nominal_cells

BASELINE, MARGIN = "without margin", "with margin"
GATE_FALLS = 0.01  # share of episodes, pooled over seeds
GATE_VELOCITY_ERROR = 0.05  # [m/s]
FALLS_TOLERANCE = 0.01  # the margin variant's falls over the baseline's, per cell
MIN_MARGIN_SHARE = 0.02  # of the reward: below it the term is too small to act...
MIN_ACCELERATION_CHANGE = 0.05  # ...when the linear acceleration moved less than this (relative)
RULE_COMMAND = 0.75  # [m/s]: where the share and the acceleration are read


@dataclass(frozen=True)
class Verdict:
    """What the rule decided, and on what."""

    decision: str  # "keep", "halve", "triple" or "fix the recipe"
    reasons: list[str] = field(default_factory=list)
    cells: list[dict[str, Any]] = field(default_factory=list)  # per command: falls, velocity error per variant
    margin_share: float | None = None  # mean over the margin variant's seeds at RULE_COMMAND
    lin_acc_change: float | None = None  # (with - without) / without at RULE_COMMAND


def judge(report: dict[str, Any]) -> Verdict:
    """The rule applied to a ``compare`` report (or a bundle card read as one) of both variants."""
    report = as_report(report)
    cells, baseline_fails, margin_fails, reasons = [], [], [], []
    share = change = None
    for cell in nominal_cells(report):
        command, variants = cell["forward_velocity"], cell["variants"]
        falls = {name: variants[name]["mean"]["fell"] for name in (BASELINE, MARGIN)}
        error = {name: variants[name]["mean"]["velocity_error_mean"] for name in (BASELINE, MARGIN)}
        cells.append({"command": command, "falls": falls, "velocity_error": error})
        if falls[BASELINE] > GATE_FALLS or error[BASELINE] > GATE_VELOCITY_ERROR:
            baseline_fails.append(f"{command:g} m/s: falls {falls[BASELINE]:.1%}, velocity error {error[BASELINE]:.3f}")
        if falls[MARGIN] > GATE_FALLS or falls[MARGIN] > falls[BASELINE] + FALLS_TOLERANCE:
            margin_fails.append(f"{command:g} m/s: falls {falls[MARGIN]:.1%} (baseline {falls[BASELINE]:.1%})")
        if abs(command - RULE_COMMAND) < 1e-9:
            shares = [run["metrics"].get("margin_reward_share") for run in variants[MARGIN]["runs"]]
            if all(s is not None for s in shares):
                share = sum(shares) / len(shares)
            a, b = (variants[name]["mean"]["lin_acc_rms"] for name in (BASELINE, MARGIN))
            change = (b - a) / a
    if baseline_fails:
        return Verdict(
            "fix the recipe", [f"the baseline fails the gate at {'; '.join(baseline_fails)}"], cells, share, change
        )
    if margin_fails:
        return Verdict(
            "halve", [f"the margin variant fails the gate at {'; '.join(margin_fails)}"], cells, share, change
        )
    if share is None or change is None:
        raise ValueError(
            f"the report has no {RULE_COMMAND:g} m/s cell with the margin variant's margin_reward_share: evaluate the "
            "pilot with --forward-velocity 0.75 after the metric existed"
        )
    reasons.append(f"both variants pass the gate; margin share {share:.1%}, linear acceleration {change:+.1%}")
    if share < MIN_MARGIN_SHARE and abs(change) < MIN_ACCELERATION_CHANGE:
        return Verdict("triple", reasons, cells, share, change)
    return Verdict("keep", reasons, cells, share, change)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("report", type=Path, help="compare.json of the pilot (or a bundle card)")
    parser.add_argument("--json", type=Path, help="write the verdict here")
    args = parser.parse_args(argv)
    verdict = judge(json.loads(args.report.read_text()))
    print("| command [m/s] | falls without → with | velocity error without → with [m/s] |\n|---|---|---|")
    for cell in verdict.cells:
        falls, error = cell["falls"], cell["velocity_error"]
        print(
            f"| {cell['command']:g} | {falls[BASELINE]:.1%} → {falls[MARGIN]:.1%} "
            f"| {error[BASELINE]:.3f} → {error[MARGIN]:.3f} |"
        )
    print(f"\ndecision: {verdict.decision} ({'; '.join(verdict.reasons)})")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(asdict(verdict), indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
