"""benchmarks/studies/field_control_bracket.py: the penalty of equal smoothing between two controls, on hand-solvable
inputs and against Welch's test where the interpolation degenerates to one control."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from benchmarks.studies.field_control_bracket import (
    Control,
    bracket_weight,
    equal_smoothing,
    equal_smoothing_difference,
    main,
)


def test_the_weight_places_the_margin_variant_between_the_two_controls() -> None:
    assert bracket_weight(1.0, 3.0, 2.0) == pytest.approx(0.5)
    assert bracket_weight(1.0, 3.0, 1.0) == pytest.approx(1.0)  # at the smoother control: all its weight
    assert bracket_weight(1.0, 3.0, 3.0) == pytest.approx(0.0)
    assert bracket_weight(1.85, 2.73, 2.33) == pytest.approx(0.40 / 0.88)
    with pytest.raises(ValueError, match="do not bracket"):
        bracket_weight(1.0, 3.0, 3.5)
    with pytest.raises(ValueError, match="must differ"):
        bracket_weight(2.0, 2.0, 2.0)


def test_the_estimate_is_the_controls_blend_at_the_margin_variants_smoothing() -> None:
    smoother = (np.array([1.0, 1.0]), np.array([10.0, 12.0]))
    rougher = (np.array([3.0, 3.0]), np.array([20.0, 22.0]))
    margin = (np.array([2.5, 2.5, 2.5]), np.array([17.0, 18.0, 19.0]))  # w = 0.25: 0.25 × 11 + 0.75 × 21 = 18.5
    found = equal_smoothing_difference(smoother, rougher, margin)
    assert found.estimate == pytest.approx(18.5) and found.difference == pytest.approx(-0.5)
    assert found.ci_low < found.difference < found.ci_high and 0 < found.p_value < 1
    assert found.not_bracketed == 0.0  # every seed of each group has the same acceleration: w never moves


def test_at_one_control_the_p_value_is_welchs_between_that_control_and_the_margin_variant() -> None:
    """w = 1 (the margin variant as smooth as the smoother control): the estimate is that control, the rougher one
    carries no weight, and Satterthwaite's degrees of freedom are Welch's."""
    smoother = (np.array([1.0, 2.0, 3.0]), np.array([0.40, 0.55, 0.47]))
    rougher = (np.array([4.0, 5.0]), np.array([9.0, 1.0]))
    margin = (np.array([1.5, 2.5, 2.0, 2.0]), np.array([0.30, 0.35, 0.41, 0.28]))
    found = equal_smoothing_difference(smoother, rougher, margin)
    assert found.estimate == pytest.approx(smoother[1].mean())
    assert found.difference == pytest.approx(margin[1].mean() - smoother[1].mean())
    assert found.p_value == pytest.approx(stats.ttest_ind(margin[1], smoother[1], equal_var=False).pvalue, rel=1e-9)


@settings(max_examples=40, deadline=None)
@given(
    intercept=st.floats(-1.0, 1.0),
    slope=st.floats(-2.0, 2.0),
    accelerations=st.lists(st.floats(1.0, 4.0), min_size=9, max_size=9, unique=True),
)
def test_a_margin_variant_on_the_controls_line_differs_by_nothing(
    intercept: float, slope: float, accelerations: list[float]
) -> None:
    """Every policy's measure linear in its acceleration, x = a + b A: the blend at the margin variant's smoothing is
    its own value, in the data and in every bootstrap resample."""
    ordered = np.sort(accelerations)
    groups = [ordered[:3], ordered[6:], ordered[3:6]]  # smoother, rougher, margin: bracketed by construction
    smoother, rougher, margin = ((acc, intercept + slope * acc) for acc in groups)
    found = equal_smoothing_difference(smoother, rougher, margin, resamples=2000)
    assert found.difference == pytest.approx(0.0, abs=1e-9)
    if found.ci_low is not None:
        assert found.ci_low == pytest.approx(0.0, abs=1e-9) and found.ci_high == pytest.approx(0.0, abs=1e-9)


def test_bad_groups_are_named() -> None:
    two = (np.array([1.0, 1.1]), np.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="smoother: need two seeds"):
        equal_smoothing_difference((np.array([1.0]), np.array([0.0])), two, two)
    with pytest.raises(ValueError, match="margin: a seed without a value"):
        equal_smoothing_difference(
            two, (np.array([3.0, 3.0]), np.array([0.0, 1.0])), (two[0] + 1, np.array([np.nan, 1.0]))
        )


# -- reports ----------------------------------------------------------------------------------------------------------


def _runs(values: list[dict[str, float]]) -> dict:
    return {"runs": [{"seed": seed, "metrics": metrics} for seed, metrics in enumerate(values)]}


def _metrics(acc: float, fell: float = 0.0, stance: float = 0.38) -> dict[str, float]:
    return {
        "lin_acc_rms": acc,
        "fell": fell,
        "velocity_error_mean": 0.07,
        "ang_acc_rms": 8 * acc,
        "stance_width_mean": stance,
        "torque_rms": 15.0,
        "margin_mean": -0.05,
    }


def _control(label: str, k: float, acc: list[float], survival: list[float]) -> Control:
    """A control at 0.75 m/s (main cell) and 1.0 m/s with the margin variant (2.0 and 2.2 m/s², seeds 0–2)."""
    margin = [_metrics(2.0 + d, stance=0.40) for d in (-0.1, 0.0, 0.1)]
    margin_fast = [_metrics(2.6 + d, fell=0.0) for d in (-0.1, 0.0, 0.1)]
    report = {
        "settings": {"forward_velocity": 0.75},
        "variants": {"without margin": _runs([_metrics(a) for a in acc]), "with margin": _runs(margin)},
        "grid": [
            {
                "condition": "nominal",
                "forward_velocity": 1.0,
                "variants": {
                    "without margin": _runs([_metrics(a + 0.5, fell=0.02) for a in acc]),
                    "with margin": _runs(margin_fast),
                },
            }
        ],
    }

    def curves(values: list[float]) -> dict:
        return {
            "policies": [
                {
                    "seed": seed,
                    "curves": [
                        {"direction": "lateral", "forward_velocity": v, "impulses": [0.0, 45.0], "survival": [1.0, s]}
                        for v in (0.75, 1.0)
                    ],
                }
                for seed, s in enumerate(values)
            ]
        }

    push = {"variants": {"without margin": curves(survival), "with margin": curves([0.3, 0.3, 0.3])}}
    return Control(label, k, report, push)


def test_equal_smoothing_over_two_reports_in_either_order() -> None:
    strong = _control("strong", 1e-4, [1.4, 1.5, 1.6], [0.7, 0.7, 0.7])  # mean 1.5 m/s²
    weak = _control("weak", 1e-5, [2.9, 3.0, 3.1], [0.5, 0.5, 0.5])  # mean 3.0 m/s²: w = 1 / 1.5 on "strong"
    for order in ((strong, weak), (weak, strong)):
        bracket, rows = equal_smoothing(order, [("lateral", 45.0)], resamples=1000)
        assert (bracket.smoother, bracket.rougher) == ("strong", "weak")
        assert bracket.weight == pytest.approx(2 / 3) and bracket.command == 0.75
        assert bracket.k_equal == pytest.approx(1e-4 ** (2 / 3) * 1e-5 ** (1 / 3))
        by_key = {(r.measure, r.condition, r.command): r for r in rows}
        primary = by_key[("lin_acc_rms", "nominal", 0.75)]
        assert primary.difference == pytest.approx(0.0, abs=1e-12) and primary.p_value is None
        stance = by_key[("stance_width_mean", "nominal", 0.75)]
        assert stance.equal == pytest.approx(0.38) and stance.difference == pytest.approx(0.02)
        falls = by_key[("fell", "nominal", 1.0)]
        assert falls.equal == pytest.approx(0.02) and falls.difference == pytest.approx(-0.02)
        push = by_key[("lateral push 45 N s, survived", "nominal", 0.75)]
        assert push.equal == pytest.approx(2 / 3 * 0.7 + 1 / 3 * 0.5) and push.margin == pytest.approx(0.3)


def test_reports_with_different_margin_variants_are_refused() -> None:
    strong = _control("strong", 1e-4, [1.4, 1.5, 1.6], [0.7, 0.7, 0.7])
    other = _control("weak", 1e-5, [2.9, 3.0, 3.1], [0.5, 0.5, 0.5])
    other.report["variants"]["with margin"]["runs"][0]["metrics"]["lin_acc_rms"] = 2.05
    with pytest.raises(ValueError, match="differ in their margin variant"):
        equal_smoothing((strong, other), [])
    moved = _control("weak", 1e-5, [2.9, 3.0, 3.1], [0.5, 0.5, 0.5])  # the same margin policies, read elsewhere
    moved.report["variants"]["with margin"]["runs"][0]["policy"] = "bundle/with_margin__s0/policy.pt"
    moved.report["variants"]["with margin"]["runs"][1]["metrics"]["margin_mean"] *= 1 + 2e-7  # float32 network
    equal_smoothing((strong, moved), [], resamples=1000)
    unbracketed = _control("weak", 1e-5, [1.7, 1.8, 1.9], [0.5, 0.5, 0.5])
    with pytest.raises(ValueError, match="do not bracket"):
        equal_smoothing((strong, unbracketed), [])


def _write(tmp_path: Path, control: Control) -> list[str]:
    compare, push = tmp_path / f"{control.label}_compare.json", tmp_path / f"{control.label}_push.json"
    compare.write_text(json.dumps(control.report))
    push.write_text(json.dumps(control.push))
    return ["--control", control.label, str(control.k), str(compare), str(push)]


def test_the_command_line_prints_the_table_and_writes_the_json(tmp_path: Path, capsys) -> None:
    strong = _write(tmp_path, _control("strong", 1e-4, [1.4, 1.5, 1.6], [0.7, 0.7, 0.7]))
    weak = _write(tmp_path, _control("weak", 1e-5, [2.9, 3.0, 3.1], [0.5, 0.5, 0.5]))
    out = tmp_path / "bracket.json"
    assert main([*strong, *weak, "--pushes", "lateral:45", "--resamples", "1000", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "w = 0.67 on strong" in printed and "(by construction)" in printed
    assert "lateral push 45 N s, survived" in printed
    written = json.loads(out.read_text())
    assert written["bracket"]["weight"] == pytest.approx(2 / 3) and len(written["controls"]) == 2


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--pushes", "sideways:45"], "DIRECTION:IMPULSE"),
        (["--pushes", "lateral:many"], "impulse must be a number"),
        (["--resamples", "10"], "at least 1,000"),
    ],
)
def test_bad_options_are_named(tmp_path: Path, capsys, extra: list[str], message: str) -> None:
    strong = _write(tmp_path, _control("strong", 1e-4, [1.4, 1.5, 1.6], [0.7, 0.7, 0.7]))
    weak = _write(tmp_path, _control("weak", 1e-5, [2.9, 3.0, 3.1], [0.5, 0.5, 0.5]))
    with pytest.raises(SystemExit):
        main([*strong, *weak, *extra])
    assert message in capsys.readouterr().err


def test_one_control_a_bad_weight_or_a_missing_file_is_named(tmp_path: Path, capsys) -> None:
    strong = _write(tmp_path, _control("strong", 1e-4, [1.4, 1.5, 1.6], [0.7, 0.7, 0.7]))
    with pytest.raises(SystemExit):
        main(strong)
    assert "exactly twice" in capsys.readouterr().err
    bad_k = [*strong[:2], "-1", *strong[3:]]
    with pytest.raises(SystemExit):
        main([*strong, *bad_k])
    assert "K must be a positive number" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*strong, "--control", "gone", "1e-5", str(tmp_path / "none.json"), str(tmp_path / "none.json")])
    assert "--control gone" in capsys.readouterr().err
