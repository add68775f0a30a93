"""The README's headline tables from measured records: flat ground at every command, and push survival.

Usage (per robot a bundle card or ``compare`` report evaluated with ``--eval-commands``, and a ``push-recovery``
report)::

    python benchmarks/studies/headline_table.py \\
        --robot B train/bundled/anymal_b/card.json docs/comparison/robust/push_anymal_b.json \\
        --robot C train/bundled/anymal_c/card.json docs/comparison/robust/push_anymal_c.json

Prints two Markdown tables. **Flat ground** (the nominal condition): one row per robot and command, the falls of
both variants as counts over all their episodes (seeds × episodes), then velocity error, base linear and angular
acceleration RMS as "without → with" means over training seeds, with the relative change and Welch's two-sided p
over seeds (the ``compare`` report's statistics, recomputed nowhere). **Pushes** at ``--push-command``: one row per
robot and direction, survival "without → with" (mean over seeds) at each impulse of ``--impulses`` with Welch's p
over seeds of the per-seed survival (:func:`margin_rl.train.analysis.significance.compare_seeds`). p < 0.05 is
printed in bold.

``--per-robot lateral:45 longitudinal:75`` prints instead one table per robot, the README's: a column per command, a
row per measure (falls, velocity error, accelerations, stance width, push survival at the pushes named, the model
mismatch conditions summarised), each with its p; ``--cost-rows`` adds joint-torque RMS, the share of steps with a
joint at its torque limit and the margin term's share of the reward (the field-reward study's tables).

``--rough D REPORT`` (repeatable; no ``--robot`` needed) prints the README's **rough-ground** table instead: one row
per evaluation terrain difficulty ``D`` and command of a ``compare`` report or bundle card evaluated on that terrain
(``compare --runs ... --terrain-difficulty D --eval-commands ...``), with the falls as counts, the fall causes as
counts (several causes can end one episode), velocity error, both accelerations and the feet landing on step
edges, each "without → with" with Welch's p over seeds::

    python benchmarks/studies/headline_table.py --rough 0.5 d0.5/compare.json --rough 0.75 d0.75/compare.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from margin_rl.train.analysis.conditions import DEFAULT_CONDITION
from margin_rl.train.analysis.significance import GRID_VARIANTS as VARIANTS
from margin_rl.train.analysis.significance import compare_seeds
from margin_rl.train.artifacts.bundle import card_report, policy_seeds

FLAT_METRICS = (("velocity_error_mean", ".3f", False), ("lin_acc_rms", ".2f", True), ("ang_acc_rms", ".0f", True))
"""(metric, format, show the relative change) of the flat-ground table."""


def _p_text(p_value: float | None) -> str:
    if p_value is None:  # no test: fewer than two seeds, or no variance in either variant
        return "–"
    text = f"p = {p_value:.2g}" if p_value >= 0.001 else "p < 0.001"
    return f"**{text}**" if p_value < 0.05 else text


def as_report(data: dict[str, Any]) -> dict[str, Any]:
    """A ``compare`` report, or a bundle card read as one: settings, main-cell variants and statistics, grid, and
    the number of training seeds per variant."""
    if "table" in data and "policies" in data:  # a bundle card (margin_rl.train.artifacts.bundle)
        seeds = {name: len(found) for name, found in policy_seeds(data["policies"]).items()}
        return {**card_report(data), "seeds": seeds}
    seeds = {name: len(variant["runs"]) for name, variant in data["variants"].items()}
    return {
        "settings": data["settings"],
        "variants": data["variants"],
        "statistics": data.get("statistics", {}),
        "grid": data.get("grid", []),
        "seeds": seeds,
    }


def evaluation_cells(report: dict[str, Any]) -> list[dict[str, Any]]:
    """Every evaluation cell of a report: the main cell first (the nominal condition at the report's command, whose
    variants and statistics are the report's own, not in its grid), then the grid's cells."""
    main = {"condition": DEFAULT_CONDITION, "forward_velocity": report["settings"]["forward_velocity"], **report}
    return [main, *report.get("grid", [])]


def nominal_cells(report: dict[str, Any]) -> list[dict[str, Any]]:
    """The nominal-condition cells of a report (the main cell among them), commands ascending."""
    cells = [c for c in evaluation_cells(report) if c["condition"] == DEFAULT_CONDITION]
    return sorted(cells, key=lambda c: c["forward_velocity"])


def falls_text(cell: dict[str, Any], seeds: dict[str, int], episodes: int) -> str:
    """Falls of both variants as "a / n → b / m" over all seeds' episodes (each seed evaluates ``episodes``)."""
    parts = []
    for name in VARIANTS:
        total = episodes * seeds[name]
        parts.append(f"{round(cell['variants'][name]['mean']['fell'] * total)} / {total}")
    return " → ".join(parts)


def flat_rows(robot: str, report: dict[str, Any]) -> list[str]:
    episodes = int(report["settings"]["eval_episodes"])
    rows = []
    for cell in nominal_cells(report):
        seeds = report["seeds"][VARIANTS[1]]
        row = f"| {robot} | {cell['forward_velocity']:g} | {seeds} | {falls_text(cell, report['seeds'], episodes)} |"
        for metric, fmt, relative in FLAT_METRICS:
            a, b = (cell["variants"][name]["mean"][metric] for name in VARIANTS)
            row += f" {_change_text(a, b, fmt, cell['statistics'][metric], relative)} |"
        rows.append(row)
    return rows


ROUGH_METRICS = (
    ("velocity_error_mean", ".3f", False),
    ("lin_acc_rms", ".2f", True),
    ("ang_acc_rms", ".0f", True),
    ("edge_landing_fraction", ".3f", False),
)
"""(metric, format, show the relative change) of the rough-ground table, after the falls and their causes."""
ROUGH_CAUSES = ("thigh_contact", "base_contact", "tilt", "base_height")
"""The fall causes the rough table counts (``termination/<cause>``), in its order."""
ROUGH_HEADER = (
    "| terrain difficulty | command [m/s] | seeds per variant | falls "
    "| falls by thigh / base contact / tilt / low base | velocity error [m/s] | base lin. acc. RMS [m/s²] "
    "| base ang. acc. RMS [rad/s²] | landings on step edges |"
)


def causes_text(cell: dict[str, Any], seeds: dict[str, int], episodes: int) -> str:
    """Per variant the episodes each of :data:`ROUGH_CAUSES` ended, "t / b / i / h", as counts over all seeds'
    episodes, "without → with"."""
    parts = []
    for name in VARIANTS:
        total, mean = episodes * seeds[name], cell["variants"][name]["mean"]
        parts.append(" / ".join(str(round(mean[f"termination/{cause}"] * total)) for cause in ROUGH_CAUSES))
    return " → ".join(parts)


def rough_rows(difficulty: str, report: dict[str, Any]) -> list[str]:
    """The rough-ground table's rows of one report evaluated at terrain ``difficulty``, commands ascending."""
    episodes = int(report["settings"]["eval_episodes"])
    rows = []
    for cell in nominal_cells(report):
        missing = [
            f"termination/{c}" for c in ROUGH_CAUSES if f"termination/{c}" not in cell["variants"][VARIANTS[0]]["mean"]
        ]
        if missing:
            raise ValueError(
                f"the report at difficulty {difficulty} has no {missing[0]!r}: it was not evaluated on rough ground "
                "(compare --terrain-difficulty D) or predates the terrain columns; evaluate it again"
            )
        seeds = report["seeds"][VARIANTS[1]]
        row = (
            f"| {difficulty} | {cell['forward_velocity']:g} | {seeds} | {falls_text(cell, report['seeds'], episodes)} "
            f"| {causes_text(cell, report['seeds'], episodes)} |"
        )
        for metric, fmt, relative in ROUGH_METRICS:
            a, b = (cell["variants"][name]["mean"][metric] for name in VARIANTS)
            row += f" {_change_text(a, b, fmt, cell['statistics'][metric], relative)} |"
        rows.append(row)
    return rows


def push_rows(robot: str, report: dict[str, Any], command: float, impulses: list[float]) -> list[str]:
    rows = []
    for direction in report["protocol"]["directions"]:
        cells = [_push_survival(report, direction, command, impulse) for impulse in impulses]
        rows.append(f"| {robot} | {direction} | " + " | ".join(cells) + " |")
    return rows


ROBOT_TABLE_METRICS = (
    ("velocity error [m/s]", "velocity_error_mean", ".3f", False),
    ("base lin. acc. RMS [m/s²]", "lin_acc_rms", ".2f", True),
    ("base ang. acc. RMS [rad/s²]", "ang_acc_rms", ".0f", True),
    ("stance width [m]", "stance_width_mean", ".3f", True),
)
"""(row label, metric, format, show the relative change) of :func:`robot_table`'s flat-ground rows."""
COST_ROWS = (
    ("joint torque RMS [N m]", "torque_rms", ".1f", True),
    ("steps with a joint at its torque limit", "torque_limit_fraction", ".4f", False),
    ("margin term's share of the reward", "margin_reward_share", ".3f", False),
)
"""(row label, episode metric, format, show the relative change) of ``--cost-rows``: what the gait costs and how large
the margin term is in the reward, read from each run's episode metrics (the report's statistics hold only the table's
columns) and tested over seeds here."""
FALLS_TOLERANCE = 0.01
"""The comparison's falls tolerance: the margin variant falls in no more than the baseline's share + 1 point."""


def _change_text(a: float, b: float, fmt: str, stats: dict[str, Any], relative: bool) -> str:
    change = f"{_signed_percent(stats['relative'])}, " if relative and stats.get("relative") is not None else ""
    return f"{a:{fmt}} → {b:{fmt}} ({change}{_p_text(stats['p_value'])})"


def policy_survivals(
    push: dict[str, Any], variant: str, direction: str, command: float, impulse: float
) -> list[tuple[Any, float]]:
    """(training seed or None, survival) of each policy of ``variant`` in a push-recovery report, pushed
    ``direction`` with ``impulse`` [N s] at ``command`` [m/s], in the report's policy order.

    Raises:
        ValueError: a policy without that push.
    """
    found = []
    for policy in push["variants"][variant]["policies"]:
        curve = [
            c for c in policy["curves"] if c["direction"] == direction and abs(c["forward_velocity"] - command) < 1e-9
        ]
        if not curve or impulse not in curve[0]["impulses"]:
            raise ValueError(f"push-recovery report has no {direction} push of {impulse:g} N s at {command:g} m/s")
        found.append((policy.get("seed"), float(curve[0]["survival"][curve[0]["impulses"].index(impulse)])))
    return found


def _push_survival(push: dict[str, Any], direction: str, command: float, impulse: float) -> str:
    per_seed = [
        [survival for _, survival in policy_survivals(push, name, direction, command, impulse)] for name in VARIANTS
    ]
    test = compare_seeds(f"survival at {impulse:g} N s", per_seed[0], per_seed[1], names=VARIANTS)
    return f"{test.mean_a:.2f} → {test.mean_b:.2f} ({_p_text(test.p_value)})"


def _signed_percent(fraction: float) -> str:
    return f"{'−' if fraction < 0 else '+'}{abs(fraction) * 100:.0f} %"


def _mismatch_text(report: dict[str, Any], command: float) -> str:
    """The off-nominal cells at ``command``: how many keep the falls tolerance, the linear-acceleration change's
    range and how many of those changes have p < 0.05."""
    cells = [
        c for c in report["grid"] if c["condition"] != DEFAULT_CONDITION and abs(c["forward_velocity"] - command) < 1e-9
    ]
    if not cells:
        return "–"
    falls = [[c["variants"][name]["mean"]["fell"] for name in VARIANTS] for c in cells]
    kept = sum(with_margin <= without + FALLS_TOLERANCE + 1e-12 for without, with_margin in falls)
    changes = sorted((c["statistics"]["lin_acc_rms"]["relative"] for c in cells), key=abs)
    significant = sum((c["statistics"]["lin_acc_rms"]["p_value"] or 1.0) < 0.05 for c in cells)
    weakest, strongest = _signed_percent(changes[0]), _signed_percent(changes[-1])
    span = weakest if weakest == strongest else f"{weakest} to {strongest}"
    return f"falls within +1 pt in {kept} / {len(cells)}; lin. acc. {span} (p < 0.05 in {significant} / {len(cells)})"


def _run_metric_text(cell: dict[str, Any], metric: str, fmt: str, relative: bool) -> str:
    """ "without → with" of episode metric ``metric`` in one evaluation cell, from each run's metrics: the means over
    seeds, the relative change where asked, Welch's p over seeds (:func:`compare_seeds`)."""
    per_seed = [[run["metrics"][metric] for run in cell["variants"][name]["runs"]] for name in VARIANTS]
    test = compare_seeds(metric, per_seed[0], per_seed[1], names=VARIANTS)
    stats = {"relative": test.relative, "p_value": test.p_value}
    return _change_text(test.mean_a, test.mean_b, fmt, stats, relative)


def robot_table(
    report: dict[str, Any], push: dict[str, Any], pushes: list[tuple[str, float]], cost_rows: bool = False
) -> list[str]:
    """One robot's table for the README: a column per evaluated command, a row per measure ("without → with",
    mean over seeds, the relative change where it reads as one, Welch's p over seeds): falls (counts over all
    episodes), the flat-ground metrics, with ``cost_rows`` those of :data:`COST_ROWS`, push survival at each
    (direction, impulse) of ``pushes``, and the model mismatch conditions summarised (:func:`_mismatch_text`)."""
    cells = nominal_cells(report)
    commands = [c["forward_velocity"] for c in cells]
    episodes = int(report["settings"]["eval_episodes"])
    without, with_margin = (report["seeds"][name] for name in VARIANTS)
    seeds = f"{with_margin} seeds each" if without == with_margin else f"{without} → {with_margin} seeds"
    lines = [
        "| " + " | ".join([f"without → with margin, {seeds}", *(f"{v:g} m/s" for v in commands)]) + " |",
        "|---|" + "---|" * len(commands),
        "| falls (episodes) | " + " | ".join(falls_text(c, report["seeds"], episodes) for c in cells) + " |",
    ]
    for label, metric, fmt, relative in ROBOT_TABLE_METRICS:
        values = []
        for cell in cells:
            a, b = (cell["variants"][name]["mean"][metric] for name in VARIANTS)
            values.append(_change_text(a, b, fmt, cell["statistics"][metric], relative))
        lines.append(f"| {label} | " + " | ".join(values) + " |")
    for label, metric, fmt, relative in COST_ROWS if cost_rows else ():
        values = [_run_metric_text(cell, metric, fmt, relative) for cell in cells]
        lines.append(f"| {label} | " + " | ".join(values) + " |")
    for direction, impulse in pushes:
        values = [
            _push_survival(push, direction, v, impulse) if v in push["protocol"]["forward_velocities"] else "–"
            for v in commands
        ]
        lines.append(f"| {direction} push {impulse:g} N s, survived | " + " | ".join(values) + " |")
    conditions = sorted({c["condition"] for c in report["grid"]} - {DEFAULT_CONDITION})
    if conditions:
        label = f"model mismatch ({', '.join(conditions)})"
        lines.append(f"| {label} | " + " | ".join(_mismatch_text(report, v) for v in commands) + " |")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--rough",
        nargs=2,
        action="append",
        metavar=("DIFFICULTY", "CARD_OR_COMPARE_JSON"),
        help="print the rough-ground table instead: a terrain difficulty and the report evaluated there (repeatable)",
    )
    parser.add_argument(
        "--robot",
        nargs=3,
        action="append",
        metavar=("LABEL", "CARD_OR_COMPARE_JSON", "PUSH_JSON"),
        help="a robot's label, its bundle card.json or compare.json, and its push_recovery.json",
    )
    parser.add_argument("--push-command", type=float, default=0.75, help="command of the push table [m/s]")
    parser.add_argument("--impulses", type=float, nargs="+", default=[30.0, 45.0, 60.0, 75.0])
    parser.add_argument(
        "--cost-rows", action="store_true", help="with --per-robot: rows of joint torques and the margin term's share"
    )
    parser.add_argument(
        "--per-robot",
        nargs="+",
        metavar="DIRECTION:IMPULSE",
        help="print one table per robot instead (a column per command, a row per measure), with push survival at "
        "these pushes, e.g. lateral:45 longitudinal:75",
    )
    args = parser.parse_args(argv)
    if args.rough:
        print(ROUGH_HEADER)
        print("|---|---|---|---|---|---|---|---|---|")
        for difficulty, path in args.rough:
            print("\n".join(rough_rows(difficulty, as_report(json.loads(Path(path).read_text())))))
        return 0
    if not args.robot:
        parser.error("give --robot LABEL REPORT PUSH_JSON (the flat and push tables) or --rough D REPORT")
    loaded = [
        (label, as_report(json.loads(Path(c).read_text())), json.loads(Path(p).read_text()))
        for label, c, p in args.robot
    ]
    if args.per_robot:
        pushes = [(d, float(i)) for d, i in (item.split(":") for item in args.per_robot)]
        for label, compare, push in loaded:
            print(f"{label}:\n")
            print("\n".join(robot_table(compare, push, pushes, args.cost_rows)) + "\n")
        return 0
    for _, _, push in loaded:
        missing = [i for i in args.impulses if i not in push["protocol"]["impulses"]]
        if missing or args.push_command not in push["protocol"]["forward_velocities"]:
            parser.error(f"--impulses {missing} or --push-command {args.push_command:g} not in a push report")
    print("| robot | command [m/s] | seeds per variant | falls | velocity error [m/s] | base lin. acc. RMS [m/s²] "
          "| base ang. acc. RMS [rad/s²] |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for label, compare, _ in loaded:
        print("\n".join(flat_rows(label, compare)))
    print()
    impulse_headers = " | ".join(f"{impulse:g} N s" for impulse in args.impulses)
    print(f"| robot | push at {args.push_command:g} m/s | {impulse_headers} |")
    print("|---|---|" + "---|" * len(args.impulses))
    for label, _, push in loaded:
        print("\n".join(push_rows(label, push, args.push_command, args.impulses)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
