"""The field-reward study's control at equal smoothing, estimated from two trained controls that bracket the margin
variant (a secondary analysis of docs/studies/field_reward.md, outside the control's rule as written).

Why: the control asks what the margin term does that a plain acceleration penalty *of equal smoothing* does not.
Of the rule's weights none matched the margin variant's linear acceleration on ANYmal C: K₀ smooths more (1.85
against 2.33 m/s²), K₀ / 10 (outside the rule) less (2.73). Comparing the margin variant with one of them alone mixes
"margin against penalty" with "smoother against rougher". Between two that bracket it, a penalty of equal smoothing
is estimated by interpolation; the study then trained the weight so found (2.3e-5: 2.43 m/s² over five seeds), and
the interpolation between K₀ and that weight checks the reading once more.

Usage (two ``compare`` reports of the two controls, each against the same margin-variant runs and evaluated on the
same grid, and their ``push-recovery`` reports; the weight K of each control's penalty)::

    python benchmarks/studies/field_control_bracket.py \\
        --control "K₀" 8.0e-5 docs/comparison/field/control_c/compare.json \\
            docs/comparison/field/control_c/push_recovery.json \\
        --control "K₀ / 10" 8.0e-6 docs/comparison/field/control_c_k0_10/compare.json \\
            docs/comparison/field/control_c_k0_10/push_recovery.json \\
        [--pushes lateral:30 lateral:45 ...] [--json OUT]

Method. At the primary cell (nominal, the reports' main command, 0.75 m/s in the study), with A_s and A_r the
smoother and the rougher control's mean linear acceleration RMS over their seeds and A_m the margin variant's, the
weight on the smoother control is

    w = (A_r − A_m) / (A_r − A_s),   0 ≤ w ≤ 1 when the two controls bracket the margin variant (else an error),

and the penalty of equal smoothing is estimated, for every measure x in every cell (each command, condition, push),
as x̂ = w x̄_s + (1 − w) x̄_r: every measure taken linear in the linear acceleration between the two controls, one
w for all cells (one penalty weight). That is the same as log-K interpolation when the acceleration and the measure
are both linear in log K; the K it implies, K* = K_s^w K_r^(1 − w), is reported and was never trained. Per measure:

* the difference x̄_m − x̂ (margin variant minus the penalty of equal smoothing);
* a 95 % percentile bootstrap interval: each group's seeds resampled with replacement, w recomputed from the
  resampled primary-cell accelerations of the same seeds (a policy is resampled with all its measures); resamples
  where the controls no longer bracket are kept (w outside [0, 1]: linear extrapolation) and counted, those where
  their accelerations cross (w undefined) dropped and counted too;
* a Welch-type two-sided p: t = d / √(w² s_s²/n_s + (1 − w)² s_r²/n_r + s_m²/n_m), Satterthwaite's degrees of
  freedom. It takes w as exact, so it is optimistic; the bootstrap interval carries w's uncertainty.

The linearity is an assumption with two points per measure: where the two controls differ little it matters little;
where they differ much (pushes, falls) read the estimate as a range between the two controls' values.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

from benchmarks.studies.headline_table import evaluation_cells, policy_survivals
from margin_rl.train.analysis.conditions import DEFAULT_CONDITION

MARGIN_VARIANT = "with margin"
CONTROL_VARIANT = "without margin"  # compare's name for the margin-weight-0 runs: here the control
ACCELERATION = "lin_acc_rms"  # [m/s²], the measure the controls were weighted to match
EPISODE_MEASURES = (
    ("fell", "falls [fraction of episodes]", ".3f"),
    ("velocity_error_mean", "velocity error [m/s]", ".3f"),
    ("lin_acc_rms", "base lin. acc. RMS [m/s²]", ".2f"),
    ("ang_acc_rms", "base ang. acc. RMS [rad/s²]", ".1f"),
    ("stance_width_mean", "stance width [m]", ".3f"),
    ("torque_rms", "joint torque RMS [N m]", ".1f"),
    ("margin_mean", "stability margin [m]", ".3f"),
)
"""(episode metric, label, format) of every cell; falls are reported in every cell of the grid, the rest at the
nominal commands."""
DEFAULT_PUSHES = ("lateral:30", "lateral:45", "lateral:60", "longitudinal:45", "longitudinal:75")
RESAMPLES = 10_000
CONFIDENCE = 0.95


@dataclass(frozen=True)
class Control:
    """One trained control: its label, the weight K of its acceleration penalty, its two reports."""

    label: str
    k: float  # [per (m/s²)²]
    report: dict[str, Any]  # compare.json: the control as "without margin", the margin variant as "with margin"
    push: dict[str, Any]  # push_recovery.json with the same two variants


@dataclass(frozen=True)
class Bracket:
    """Where the margin variant's linear acceleration sits between the two controls at the primary cell."""

    command: float  # [m/s], the primary cell's (nominal condition)
    smoother: str  # label of the control with the lower linear acceleration
    rougher: str
    smoother_acceleration: float  # [m/s²], mean over its seeds
    rougher_acceleration: float
    margin_acceleration: float
    weight: float  # w on the smoother control
    k_equal: float  # K_s^w K_r^(1 − w): the log-K interpolated penalty weight, never trained


@dataclass(frozen=True)
class EqualSmoothingRow:
    """One measure in one cell: the two controls, the interpolated penalty of equal smoothing and the margin."""

    measure: str  # an episode metric, or "<direction> push <impulse> N s, survived"
    condition: str
    command: float  # [m/s]
    rougher: float  # means over seeds
    equal: float  # w smoother + (1 − w) rougher
    smoother: float
    margin: float
    difference: float  # margin − equal
    ci_low: float | None  # bootstrap, w resampled (None: no variance anywhere)
    ci_high: float | None
    p_value: float | None  # Welch–Satterthwaite with w exact (None: no variance anywhere)
    not_bracketed: float  # share of bootstrap resamples in which the controls did not bracket the margin variant


@dataclass(frozen=True)
class EqualSmoothingEstimate:
    """One measure: the penalty of equal smoothing and the margin variant's difference to it."""

    estimate: float  # x̂ = w x̄_s + (1 − w) x̄_r
    difference: float  # x̄_m − x̂
    ci_low: float | None  # 95 % percentile bootstrap, w recomputed per resample (None: no variance anywhere)
    ci_high: float | None
    p_value: float | None  # Welch–Satterthwaite with w exact (None: no variance anywhere)
    not_bracketed: float  # share of resamples where the controls did not bracket the margin variant


def bracket_weight(smoother: float, rougher: float, margin: float) -> float:
    """w = (rougher − margin) / (rougher − smoother), the weight on the smoother control (module docstring).

    Raises:
        ValueError: the two controls' accelerations equal, or the margin variant's outside them.
    """
    if not rougher > smoother:
        raise ValueError(f"the controls' linear accelerations must differ (got {smoother} and {rougher} m/s²)")
    if not smoother <= margin <= rougher:
        raise ValueError(
            f"the controls ({smoother:.3g}, {rougher:.3g} m/s²) do not bracket the margin variant ({margin:.3g} m/s²):"
            " train a control on the other side of it"
        )
    return (rougher - margin) / (rougher - smoother)


def _welch_satterthwaite_p(difference: float, weights: list[float], groups: list[np.ndarray]) -> float | None:
    """Two-sided p of ``difference`` against 0 with variance Σ c_i² s_i²/n_i over the groups (c_i: ``weights``)."""
    parts = [c * c * g.var(ddof=1) / g.size for c, g in zip(weights, groups, strict=True)]
    total = sum(parts)
    if total <= 0:
        return None
    shares = [p / total for p in parts]  # scale-free: tiny variances would underflow when squared
    df = 1.0 / sum(share * share / (g.size - 1) for share, g in zip(shares, groups, strict=True))
    return float(2 * stats.t.sf(abs(difference) / math.sqrt(total), df))


def equal_smoothing_difference(
    smoother: tuple[np.ndarray, np.ndarray],
    rougher: tuple[np.ndarray, np.ndarray],
    margin: tuple[np.ndarray, np.ndarray],
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> EqualSmoothingEstimate:
    """The margin variant against a penalty of equal smoothing on one measure (module docstring).

    Each argument: (the group's per-seed primary-cell linear accelerations, the same seeds' values of the measure),
    aligned by seed, two seeds or more.

    Raises:
        ValueError: a group with fewer than two seeds, arrays not aligned or not finite, or controls that do not
            bracket the margin variant.
    """
    for name, (acc, values) in (("smoother", smoother), ("rougher", rougher), ("margin", margin)):
        if acc.shape != values.shape or acc.ndim != 1 or acc.size < 2:
            raise ValueError(f"{name}: need two seeds or more, accelerations and values aligned, got {acc}, {values}")
        if not (np.all(np.isfinite(acc)) and np.all(np.isfinite(values))):
            raise ValueError(f"{name}: a seed without a value ({acc}, {values}): every policy needs this measure")
    w = bracket_weight(smoother[0].mean(), rougher[0].mean(), margin[0].mean())
    estimate = w * smoother[1].mean() + (1 - w) * rougher[1].mean()
    difference = float(margin[1].mean() - estimate)
    p_value = _welch_satterthwaite_p(difference, [w, 1 - w, 1.0], [smoother[1], rougher[1], margin[1]])

    rng = np.random.default_rng(seed)

    def resampled(group: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        picks = rng.integers(0, group[0].size, size=(resamples, group[0].size))
        return group[0][picks].mean(axis=1), group[1][picks].mean(axis=1)

    (acc_s, x_s), (acc_r, x_r), (acc_m, x_m) = resampled(smoother), resampled(rougher), resampled(margin)
    defined = acc_r > acc_s  # w undefined where the resampled controls' accelerations cross
    w_b = (acc_r[defined] - acc_m[defined]) / (acc_r[defined] - acc_s[defined])
    differences = x_m[defined] - (w_b * x_s[defined] + (1 - w_b) * x_r[defined])
    not_bracketed = 1.0 - float(np.count_nonzero((w_b >= 0) & (w_b <= 1))) / resamples
    if differences.size == 0 or np.ptp(differences) == 0:
        low = high = None
    else:
        tail = 50 * (1 - CONFIDENCE)
        low, high = (float(v) for v in np.percentile(differences, [tail, 100 - tail]))
    return EqualSmoothingEstimate(float(estimate), difference, low, high, p_value, not_bracketed)


def _cells(report: dict[str, Any]) -> dict[tuple[str, float], dict[str, Any]]:
    """Every evaluation cell of a compare report, the main one included, by (condition, command)."""
    return {(c["condition"], round(float(c["forward_velocity"]), 6)): c for c in evaluation_cells(report)}


def _mean(values: dict[int, float]) -> float:
    return float(np.mean(list(values.values())))


def _episode_values(cell: dict[str, Any], variant: str, metric: str) -> dict[int, float]:
    return {int(run["seed"]): float(run["metrics"].get(metric, math.nan)) for run in cell["variants"][variant]["runs"]}


def _push_values(
    push: dict[str, Any], variant: str, direction: str, command: float, impulse: float
) -> dict[int, float]:
    found = policy_survivals(push, variant, direction, command, impulse)
    if any(seed is None for seed, _ in found):
        raise ValueError(f"{variant}: a push-recovery policy without its training seed; the seeds pair it with compare")
    return {int(seed): survival for seed, survival in found}


def _margin_evaluations(control: Control) -> tuple[Any, Any]:
    """What the margin variant measured in a control's two reports, by seed: every cell's metrics and every push
    curve (not where its files lay: the same policies may be evaluated from their runs or from a bundle)."""
    cells = {
        f"{condition}@{command}": {int(r["seed"]): r["metrics"] for r in cell["variants"][MARGIN_VARIANT]["runs"]}
        for (condition, command), cell in _cells(control.report).items()
    }
    pushes = {int(p["seed"]): p["curves"] for p in control.push["variants"][MARGIN_VARIANT]["policies"]}
    return cells, pushes


MARGIN_NETWORK_RTOL = 1e-6
"""Relative tolerance between two evaluations of the same policies: the learned margin's network runs in float32, and
a run folder's and a bundle's evaluation of one policy were seen to differ by up to 2e-7 relative in the margin's
metrics, every other metric bit-identical."""


def _same_numbers(a: Any, b: Any) -> bool:
    """Equal structure, equal strings, numbers equal to :data:`MARGIN_NETWORK_RTOL`."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same_numbers(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same_numbers(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return math.isclose(a, b, rel_tol=MARGIN_NETWORK_RTOL, abs_tol=1e-12) or (math.isnan(a) and math.isnan(b))
    return a == b


def _check_same_margin_variant(first: Control, second: Control) -> None:
    """Both controls must be compared with the same margin-variant policies evaluated the same way: the same seeds
    with the same metrics in every cell and the same push curves (numbers to :data:`MARGIN_NETWORK_RTOL`)."""
    if set(_cells(first.report)) != set(_cells(second.report)):
        raise ValueError(f"{first.label} and {second.label} were evaluated on different grids")
    for what, a, b in zip(
        ("compare", "push-recovery"), _margin_evaluations(first), _margin_evaluations(second), strict=True
    ):
        if not _same_numbers(a, b):
            raise ValueError(
                f"the two {what} reports of {first.label} and {second.label} differ in their margin variant: evaluate "
                "both controls against the same margin policies with the same settings"
            )


def equal_smoothing(
    controls: tuple[Control, Control], pushes: list[tuple[str, float]], resamples: int = RESAMPLES
) -> tuple[Bracket, list[EqualSmoothingRow]]:
    """The bracket at the primary cell and one row per measure and cell (module docstring)."""
    _check_same_margin_variant(*controls)
    primary = (DEFAULT_CONDITION, round(float(controls[0].report["settings"]["forward_velocity"]), 6))
    accelerations = [_episode_values(_cells(c.report)[primary], CONTROL_VARIANT, ACCELERATION) for c in controls]
    order = np.argsort([_mean(a) for a in accelerations])
    smoother, rougher = controls[order[0]], controls[order[1]]
    acc_s, acc_r = accelerations[order[0]], accelerations[order[1]]
    acc_m = _episode_values(_cells(smoother.report)[primary], MARGIN_VARIANT, ACCELERATION)
    w = bracket_weight(_mean(acc_s), _mean(acc_r), _mean(acc_m))
    bracket = Bracket(
        primary[1],
        smoother.label,
        rougher.label,
        _mean(acc_s),
        _mean(acc_r),
        _mean(acc_m),
        w,
        float(smoother.k**w * rougher.k ** (1 - w)),
    )

    def aligned(acc: dict[int, float], values: dict[int, float], who: str) -> tuple[np.ndarray, np.ndarray]:
        if set(acc) != set(values):
            raise ValueError(f"{who}: the seeds of its compare and push-recovery reports differ ({acc}, {values})")
        seeds = sorted(acc)
        return np.array([acc[s] for s in seeds]), np.array([values[s] for s in seeds])

    def row(measure: str, condition: str, command: float, values: list[dict[int, float]]) -> EqualSmoothingRow:
        groups = (
            aligned(acc_s, values[0], smoother.label),
            aligned(acc_r, values[1], rougher.label),
            aligned(acc_m, values[2], MARGIN_VARIANT),
        )
        found = equal_smoothing_difference(*groups, resamples)
        if (measure, condition, command) == (ACCELERATION, *primary):  # equal by construction: nothing to test
            found = dataclasses.replace(found, ci_low=None, ci_high=None, p_value=None)
        return EqualSmoothingRow(
            measure,
            condition,
            command,
            float(groups[1][1].mean()),
            found.estimate,
            float(groups[0][1].mean()),
            float(groups[2][1].mean()),
            found.difference,
            found.ci_low,
            found.ci_high,
            found.p_value,
            found.not_bracketed,
        )

    rows = []
    cells_s, cells_r = _cells(smoother.report), _cells(rougher.report)
    for key in sorted(cells_s, key=lambda k: (k[0] != DEFAULT_CONDITION, k)):
        condition, command = key
        for metric, _, _ in EPISODE_MEASURES:
            if condition != DEFAULT_CONDITION and metric != "fell":
                continue
            values = [
                _episode_values(cells_s[key], CONTROL_VARIANT, metric),
                _episode_values(cells_r[key], CONTROL_VARIANT, metric),
                _episode_values(cells_s[key], MARGIN_VARIANT, metric),
            ]
            rows.append(row(metric, condition, command, values))
    commands = sorted(command for condition, command in cells_s if condition == DEFAULT_CONDITION)
    for direction, impulse in pushes:
        for command in commands:
            values = [
                _push_values(smoother.push, CONTROL_VARIANT, direction, command, impulse),
                _push_values(rougher.push, CONTROL_VARIANT, direction, command, impulse),
                _push_values(smoother.push, MARGIN_VARIANT, direction, command, impulse),
            ]
            rows.append(row(f"{direction} push {impulse:g} N s, survived", DEFAULT_CONDITION, command, values))
    return bracket, rows


def _format(value: float | None, spec: str) -> str:
    return "–" if value is None else f"{value:{spec}}"


def markdown(bracket: Bracket, rows: list[EqualSmoothingRow]) -> str:
    """The bracket in a sentence, then one table row per measure and cell (falls only where any policy fell off the
    nominal condition)."""
    specs = {metric: (label, spec) for metric, label, spec in EPISODE_MEASURES}
    lines = [
        f"Linear acceleration at {bracket.command:g} m/s, nominal: {bracket.smoother} "
        f"{bracket.smoother_acceleration:.2f}, margin variant {bracket.margin_acceleration:.2f}, {bracket.rougher} "
        f"{bracket.rougher_acceleration:.2f} m/s²: "
        f"w = {bracket.weight:.2f} on {bracket.smoother}; a penalty of equal smoothing ≈ K = {bracket.k_equal:.2g} "
        "(log-K interpolated, not trained). The controls no longer bracket the margin variant in "
        f"{100 * (rows[0].not_bracketed if rows else 0.0):.0f} % of the bootstrap resamples (extrapolated there).",
        "",
        f"| measure | condition | command [m/s] | {bracket.rougher} | equal smoothing (interpolated) | "
        f"{bracket.smoother} | margin variant | margin − equal [95 % bootstrap] | p (w exact) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        label, spec = specs.get(r.measure, (r.measure, ".2f"))
        if r.condition != DEFAULT_CONDITION and max(r.rougher, r.smoother, r.margin) == 0:
            continue  # an off-nominal cell where nobody fell
        interval = "" if r.ci_low is None else f" [{r.ci_low:+{spec}}, {r.ci_high:+{spec}}]"
        p_text = _format(r.p_value, ".2g")
        if (r.measure, r.condition, r.command) == (ACCELERATION, DEFAULT_CONDITION, bracket.command):
            interval, p_text = " (by construction)", "–"
        lines.append(
            f"| {label} | {r.condition} | {r.command:g} | {r.rougher:{spec}} | {r.equal:{spec}} | {r.smoother:{spec}} "
            f"| {r.margin:{spec}} | {r.difference:+{spec}}{interval} | {p_text} |"
        )
    return "\n".join(lines)


def _push_spec(text: str) -> tuple[str, float]:
    direction, _, impulse = text.partition(":")
    if direction not in ("lateral", "longitudinal") or not impulse:
        raise argparse.ArgumentTypeError(f"a push is DIRECTION:IMPULSE, e.g. lateral:45 (got {text!r})")
    try:
        return direction, float(impulse)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a push's impulse must be a number of N s (got {impulse!r})") from None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--control",
        nargs=4,
        action="append",
        required=True,
        metavar=("LABEL", "K", "COMPARE_JSON", "PUSH_JSON"),
        help="a control's label, its penalty weight K, its compare.json and push_recovery.json (exactly twice)",
    )
    parser.add_argument("--pushes", nargs="+", type=_push_spec, default=[_push_spec(p) for p in DEFAULT_PUSHES])
    parser.add_argument("--resamples", type=int, default=RESAMPLES, help="bootstrap resamples (at least 1,000)")
    parser.add_argument("--json", type=Path, help="write the bracket and every row here")
    args = parser.parse_args(argv)
    if len(args.control) != 2:
        parser.error(
            f"give --control exactly twice (the two controls that bracket the margin variant), got {len(args.control)}"
        )
    if args.resamples < 1000:
        parser.error(f"--resamples must be at least 1,000, got {args.resamples}")
    controls = []
    for label, k_text, compare_path, push_path in args.control:
        try:
            k = float(k_text)
            if not k > 0:
                raise ValueError
        except ValueError:
            parser.error(f"--control {label}: K must be a positive number, got {k_text!r}")
        try:
            controls.append(
                Control(label, k, json.loads(Path(compare_path).read_text()), json.loads(Path(push_path).read_text()))
            )
        except (OSError, json.JSONDecodeError) as exc:
            parser.error(f"--control {label}: {exc}")
    try:
        bracket, rows = equal_smoothing((controls[0], controls[1]), args.pushes, args.resamples)
    except (KeyError, ValueError) as exc:
        parser.error(str(exc))
    print(markdown(bracket, rows))
    if args.json is not None:
        from margin_rl.train.runs import write_json  # atomic

        write_json(
            args.json,
            {
                "controls": [{"label": c.label, "k": c.k} for c in controls],
                "bracket": asdict(bracket),
                "rows": [asdict(r) for r in rows],
            },
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
