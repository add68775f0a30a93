"""benchmarks/studies/speed_matched.py: acceleration at matched walking speed, on hand-solvable reports."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.studies.speed_matched import interpolate_curve, main, speed_matched


def _cell(command: float, without: list[tuple[float, float]], with_: list[tuple[float, float]]) -> dict:
    def runs(points: list[tuple[float, float]]) -> dict:
        return {
            "runs": [
                {"seed": seed, "metrics": {"forward_velocity_mean": v, "lin_acc_rms": a}}
                for seed, (v, a) in enumerate(points)
            ]
        }

    return {
        "condition": "nominal",
        "forward_velocity": command,
        "variants": {"without margin": runs(without), "with margin": runs(with_)},
    }


def _report() -> dict:
    """Two baselines with a(v) = 4 v (seed 0) and 4 v + 0.4 (seed 1) at 0.5 and 1.0 m/s: their mean at speed v is
    4 v + 0.2; two margin policies."""
    main_cell = _cell(0.5, [(0.5, 2.0), (0.5, 2.4)], [(0.4, 1.0), (0.75, 2.4)])
    return {
        "settings": {"forward_velocity": 0.5},
        "variants": main_cell["variants"],
        "grid": [
            _cell(1.0, [(1.0, 4.0), (1.0, 4.4)], [(0.9, 3.8), (1.0, 4.2)]),
            {**_cell(1.0, [], []), "condition": "friction_0.4"},  # another condition: not a speed curve's point
        ],
    }


def test_each_margin_policy_is_compared_with_the_baselines_at_its_own_speed() -> None:
    low, high = speed_matched(_report())
    assert low.command == 0.5 and high.command == 1.0
    # 0.4 m/s is slower than every baseline walked: not matched; 0.75 m/s: baselines 3.0 and 3.4, mean 3.2
    assert low.baseline_at_speed == [None, pytest.approx(3.2)] and low.matched == 1
    assert low.relative_differences[1] == pytest.approx((2.4 - 3.2) / 3.2) and low.p_value is None
    # 0.9 m/s: 3.8 against 3.8 (0 %); 1.0 m/s: 4.2 against 4.2 (0 %)
    assert high.baseline_at_speed == [pytest.approx(3.8), pytest.approx(4.2)]
    assert high.mean_relative_difference == pytest.approx(0.0) and high.matched == 2


def test_a_speed_outside_any_baselines_range_is_not_extrapolated() -> None:
    assert interpolate_curve([(0.5, 2.0), (1.0, 4.0)], 0.75) == pytest.approx(3.0)
    assert interpolate_curve([(1.0, 4.0), (0.5, 2.0)], 0.5) == pytest.approx(2.0)  # any order, ends included
    assert interpolate_curve([(0.5, 2.0), (1.0, 4.0)], 1.01) is None
    with pytest.raises(ValueError, match="at least two"):
        interpolate_curve([(0.5, 2.0)], 0.5)
    with pytest.raises(ValueError, match="same speed"):
        interpolate_curve([(0.5, 2.0), (0.5, 3.0)], 0.5)


@settings(max_examples=40, deadline=None)
@given(
    slope=st.floats(0.5, 8.0), offset=st.floats(0.0, 2.0), speeds=st.lists(st.floats(0.3, 1.2), min_size=2, max_size=6)
)
def test_a_policy_on_the_baselines_own_line_differs_by_nothing(slope: float, offset: float, speeds: list) -> None:
    """Margin policies whose accelerations lie on the baselines' (linear) curve: every matched difference is 0."""
    curve = [(0.3, offset + slope * 0.3), (1.2, offset + slope * 1.2)]
    margin = [(v, offset + slope * v) for v in speeds]
    report = {
        "settings": {"forward_velocity": 0.3},
        "variants": _cell(0.3, [curve[0]], margin)["variants"],
        "grid": [_cell(1.2, [curve[1]], margin)],
    }
    for result in speed_matched(report):
        assert result.matched == len(speeds)
        assert all(abs(x) < 1e-9 for x in result.relative_differences)


def test_a_report_with_one_command_or_a_card_is_refused(tmp_path: Path) -> None:
    one = {**_report(), "grid": []}
    with pytest.raises(ValueError, match="two commands"):
        speed_matched(one)
    card = tmp_path / "card.json"
    card.write_text(json.dumps({**_report(), "policies": []}))
    with pytest.raises(SystemExit):
        main([str(card)])


def test_the_command_line_writes_its_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report = tmp_path / "compare.json"
    report.write_text(json.dumps(_report()))
    assert main([str(report), "--json", str(tmp_path / "out.json")]) == 0
    assert "| 0.5 | 0.40, 0.75 | outside, -25 % | 1 / 2 |" in capsys.readouterr().out
    written = json.loads((tmp_path / "out.json").read_text())
    assert [c["command"] for c in written["commands"]] == [0.5, 1.0]
