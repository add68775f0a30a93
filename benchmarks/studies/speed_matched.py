"""Base acceleration at matched walking speed: the margin variant's policies against the baselines' at the speed the
margin policy actually walked (a secondary analysis of the field-reward study, not its primary endpoint).

Why: the comparison's cells are commands, and a policy that walks slower than commanded moves its base less for that
reason alone (the baselines' linear acceleration RMS rises with speed: on ANYmal B under the field's reward from
about 1.6 m/s² at 0.46 m/s to 3.8 m/s² at 0.9 m/s). Where the margin variant walks slower than the baseline at the
same command, "lower acceleration with the margin" may be "slower with the margin".

Usage (a ``compare`` report evaluated at several commands in the nominal condition; a bundle card keeps only the
means of its grid cells, not each policy's)::

    python benchmarks/studies/speed_matched.py docs/comparison/field/b/compare.json [--json OUT]

Method, per command c of the nominal cells and margin policy i (training seed), with v the policy's mean forward
velocity over its evaluation episodes and a its base linear acceleration RMS:

* each baseline policy j gives a curve a_j(v), linear between its own (v, a) points at the report's commands, defined
  only between its slowest and fastest (no extrapolation);
* the speed-matched baseline value of margin policy i is the mean over baseline policies of a_j(v_i), defined only
  where every baseline policy's curve covers v_i (else the pair is counted as outside the baselines' speeds);
* d_i = a_i − that value; per command: the mean relative difference, and a two-sided one-sample t-test of d over the
  matched margin policies (paired with the interpolated baseline; it treats the baselines' curve as exact, so its p is
  optimistic: read it as a description, not a test of the study's hypothesis).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

from benchmarks.studies.headline_table import nominal_cells

SPEED = "forward_velocity_mean"  # [m/s], mean over a policy's evaluation episodes
ACCELERATION = "lin_acc_rms"  # [m/s²]


def interpolate_curve(points: list[tuple[float, float]], speed: float) -> float | None:
    """a(speed) linear between the (speed, acceleration) ``points`` of one policy, None outside their speeds.

    Raises:
        ValueError: fewer than two points, or two points at the same speed with different accelerations.
    """
    if len(points) < 2:
        raise ValueError(f"a speed curve needs at least two commands' evaluations, got {len(points)}")
    ordered = sorted(points)
    speeds = np.array([v for v, _ in ordered])
    if np.any(np.diff(speeds) == 0):
        raise ValueError(f"two commands walked at the same speed {speeds}: the curve is not a function of speed")
    if not speeds[0] <= speed <= speeds[-1]:
        return None
    return float(np.interp(speed, speeds, [a for _, a in ordered]))


@dataclass(frozen=True)
class MatchedCommand:
    """The speed-matched comparison at one command."""

    command: float  # [m/s]
    speeds: list[float]  # each margin policy's mean forward velocity [m/s]
    accelerations: list[float]  # each margin policy's linear acceleration RMS [m/s²]
    baseline_at_speed: list[float | None]  # the baselines' mean a_j(v_i), None outside their speeds
    relative_differences: list[float | None]  # (a_i − baseline) / baseline
    matched: int  # margin policies inside the baselines' speeds
    mean_relative_difference: float | None
    p_value: float | None  # one-sample t-test of a_i − baseline over the matched policies (None: fewer than 2)


def speed_matched(report: dict[str, Any]) -> list[MatchedCommand]:
    """The speed-matched comparison of a ``compare`` report at each of its nominal commands (module docstring; a
    bundle card keeps no policy's grid metrics).

    Raises:
        ValueError: fewer than two nominal commands, or variants whose policies differ between cells.
    """
    cells = nominal_cells(report)
    if len(cells) < 2:
        raise ValueError("need the nominal condition at two commands or more (compare --eval-commands ...)")

    def per_policy(name: str) -> dict[int, list[tuple[float, float]]]:
        curves: dict[int, list[tuple[float, float]]] = {}
        for cell in cells:
            for run in cell["variants"][name]["runs"]:
                curves.setdefault(int(run["seed"]), []).append((run["metrics"][SPEED], run["metrics"][ACCELERATION]))
        if any(len(points) != len(cells) for points in curves.values()):
            raise ValueError(f"{name}: a policy is missing from some nominal cell")
        return curves

    baselines = per_policy("without margin")
    per_policy("with margin")  # the same check for the margin variant
    results = []
    for cell in cells:
        runs = sorted(cell["variants"]["with margin"]["runs"], key=lambda r: r["seed"])
        speeds = [float(r["metrics"][SPEED]) for r in runs]
        accelerations = [float(r["metrics"][ACCELERATION]) for r in runs]
        at_speed: list[float | None] = []
        for v in speeds:
            values = [interpolate_curve(points, v) for points in baselines.values()]
            at_speed.append(None if any(x is None for x in values) else float(np.mean(values)))
        relative = [None if b is None else (a - b) / b for a, b in zip(accelerations, at_speed, strict=True)]
        differences = [a - b for a, b in zip(accelerations, at_speed, strict=True) if b is not None]
        matched = [r for r in relative if r is not None]
        p_value = float(stats.ttest_1samp(differences, 0.0).pvalue) if len(differences) >= 2 else None
        results.append(
            MatchedCommand(
                float(cell["forward_velocity"]),
                speeds,
                accelerations,
                at_speed,
                relative,
                len(matched),
                float(np.mean(matched)) if matched else None,
                p_value if p_value is None or np.isfinite(p_value) else None,
            )
        )
    return results


def markdown(results: list[MatchedCommand]) -> str:
    """One row per command: the margin policies' speeds, their relative difference to the baselines at their speed,
    the count matched and the paired p."""
    lines = [
        "| command [m/s] | margin policies' speed [m/s] | lin. acc. vs baselines at that speed, per seed | matched "
        "| mean | p (paired, optimistic) |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        speeds = ", ".join(f"{v:.2f}" for v in r.speeds)
        per_seed = ", ".join("outside" if x is None else f"{100 * x:+.0f} %" for x in r.relative_differences)
        mean = "–" if r.mean_relative_difference is None else f"{100 * r.mean_relative_difference:+.0f} %"
        p_text = "–" if r.p_value is None else f"{r.p_value:.2g}"
        lines.append(f"| {r.command:g} | {speeds} | {per_seed} | {r.matched} / {len(r.speeds)} | {mean} | {p_text} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("report", type=Path, help="a compare.json")
    parser.add_argument("--json", type=Path, help="write the result here")
    args = parser.parse_args(argv)
    try:
        report = json.loads(args.report.read_text())
        if "policies" in report:
            raise ValueError(
                "a bundle card keeps only each grid cell's means: give the compare.json it was written from"
            )
        results = speed_matched(report)
    except (OSError, KeyError, ValueError) as exc:
        parser.error(f"{args.report}: {exc}")
    print(markdown(results))
    if args.json is not None:
        from margin_rl.train.runs import write_json  # atomic

        write_json(args.json, {"report": str(args.report), "commands": [asdict(r) for r in results]})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
