"""The field-reward pilot's rule (benchmarks/studies/field_weight_rule.py) on hand-made reports: each branch of the
rule written before the runs, at its thresholds."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from benchmarks.studies.field_weight_rule import judge, main


def _variant(fell: float, error: float, acc: float, share: float | None) -> dict[str, Any]:
    metrics = {"fell": fell, "velocity_error_mean": error, "lin_acc_rms": acc}
    runs = [
        {"seed": s, "metrics": {**metrics, **({} if share is None else {"margin_reward_share": share})}} for s in (0, 1)
    ]
    return {"mean": metrics, "runs": runs}


def _report(margin_falls: float = 0.0, baseline_error: float = 0.02, share: float | None = 0.05, acc: float = 3.0):
    """Baseline: no falls, linear acceleration 5 m/s²; the margin variant as given, at every command."""

    def cell(command: float) -> dict[str, Any]:
        return {
            "condition": "nominal",
            "forward_velocity": command,
            "variants": {
                "without margin": _variant(0.0, baseline_error, 5.0, None),
                "with margin": _variant(margin_falls, 0.02, acc, share),
            },
            "statistics": {},
        }

    main_cell = cell(0.75)
    settings = {"forward_velocity": 0.75, "eval_episodes": 64}
    return {"settings": settings, "variants": main_cell["variants"], "grid": [cell(0.5), cell(1.0)]}


@pytest.mark.parametrize(
    ("report", "decision"),
    [
        (_report(), "keep"),
        (_report(margin_falls=0.01), "keep"),  # at the threshold: 1 % and the baseline + 1 point
        (_report(margin_falls=0.02), "halve"),
        (_report(baseline_error=0.06), "fix the recipe"),
        (_report(share=0.019, acc=4.9), "triple"),  # 2 % of the reward, acceleration 2 % lower
        (_report(share=0.019, acc=4.7), "keep"),  # a small term that still moved the acceleration 6 %
    ],
)
def test_each_branch_of_the_rule(report: dict[str, Any], decision: str) -> None:
    assert judge(report).decision == decision


def test_the_share_and_the_change_are_read_at_0_75(tmp_path: Path) -> None:
    verdict = judge(_report(share=0.05, acc=3.0))
    assert verdict.margin_share == pytest.approx(0.05) and verdict.lin_acc_change == pytest.approx(-0.4)
    assert [c["command"] for c in verdict.cells] == [0.5, 0.75, 1.0]
    path = tmp_path / "compare.json"
    path.write_text(json.dumps(_report()))
    assert main([str(path), "--json", str(tmp_path / "verdict.json")]) == 0
    assert json.loads((tmp_path / "verdict.json").read_text())["decision"] == "keep"


def test_a_report_without_the_share_says_what_to_do() -> None:
    with pytest.raises(ValueError, match=r"evaluate the pilot with --forward-velocity 0\.75"):
        judge(_report(share=None))
