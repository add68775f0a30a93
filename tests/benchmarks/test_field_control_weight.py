"""benchmarks/studies/field_control_weight.py: K₀ of the control's acceleration penalty, on hand-solvable inputs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.studies.field_control_weight import (
    MATCH_TOLERANCE,
    SCAN,
    choose_control_weight,
    control_weight,
    scan_of_report,
)


def test_k0_is_the_margin_terms_mean_magnitude_over_the_mean_squared_acceleration() -> None:
    terms = np.array([0.002, -0.004, 0.0, 0.006])  # mean |term| 0.003
    accelerations = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]])  # |a|^2 25 and 1: mean 13
    result = control_weight(terms, accelerations)
    assert result.margin_term_abs == pytest.approx(0.003) and result.acceleration_sq == pytest.approx(13.0)
    assert result.k0 == pytest.approx(0.003 / 13.0)
    assert result.scan == pytest.approx(tuple(result.k0 * m for m in SCAN)) and SCAN == (1.0, 10.0, 100.0)
    assert result.steps == {"margin": 4, "baseline": 2}


@pytest.mark.parametrize(
    ("terms", "accelerations", "message"),
    [
        (np.array([]), np.ones((2, 3)), "need margin terms"),
        (np.ones(3), np.ones((2, 2)), "need margin terms"),
        (np.array([np.nan]), np.ones((2, 3)), "finite"),
        (np.ones(3), np.zeros((4, 3)), "all zero"),
    ],
)
def test_bad_inputs_are_refused(terms: np.ndarray, accelerations: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        control_weight(terms, accelerations)


def test_a_scanned_weight_within_the_tolerance_is_kept_the_closest_of_several() -> None:
    choice = choose_control_weight(2.0, {1e-4: 2.5, 1e-3: 2.15, 1e-2: 1.9})  # 1e-3 at +7.5 %, 1e-2 at −5 %
    assert (choice.k, choice.how, choice.measured) == (1e-2, "matched", 1.9)
    assert choice.relative_mismatch == pytest.approx(-0.05)


def test_without_a_match_k_is_interpolated_in_log_k_between_the_bracketing_pair() -> None:
    # a(1e-4) = 3.0, a(1e-2) = 1.0, target 2.0: halfway in acceleration, so halfway in log K -> 1e-3
    choice = choose_control_weight(2.0, {1e-4: 3.0, 1e-2: 1.0})
    assert choice.how == "interpolated" and choice.k == pytest.approx(1e-3)
    assert choice.measured is None and choice.relative_mismatch is None
    # a non-monotonic scan brackets the target twice: the pair with the smaller weights is used
    twice = choose_control_weight(2.0, {1e-4: 3.0, 1e-3: 1.0, 1e-2: 3.0})
    assert twice.k == pytest.approx(10**-3.5)


def test_a_scan_on_one_side_of_the_target_keeps_the_closest_and_reports_the_mismatch() -> None:
    choice = choose_control_weight(2.0, {1e-4: 3.0, 1e-3: 2.6, 1e-2: 2.4})
    assert (choice.k, choice.how) == (1e-2, "closest") and choice.relative_mismatch == pytest.approx(0.2)


@pytest.mark.parametrize(
    ("target", "scan"),
    [(2.0, {}), (0.0, {1e-3: 2.0}), (2.0, {-1e-3: 2.0}), (2.0, {1e-3: float("nan")}), (float("inf"), {1e-3: 2.0})],
)
def test_bad_scans_are_refused(target: float, scan: dict[float, float]) -> None:
    with pytest.raises(ValueError, match=r"scan|positive"):
        choose_control_weight(target, scan)


@settings(max_examples=60, deadline=None)
@given(
    target=st.floats(0.5, 5.0),
    scan=st.dictionaries(st.floats(1e-6, 1.0), st.floats(0.5, 5.0), min_size=1, max_size=4),
)
def test_the_choice_lies_within_the_scanned_range_and_a_match_is_within_the_tolerance(
    target: float, scan: dict[float, float]
) -> None:
    choice = choose_control_weight(target, scan)
    assert min(scan) <= choice.k * (1 + 1e-12) and choice.k <= max(scan) * (1 + 1e-12)
    if choice.how == "matched":
        assert abs(scan[choice.k] - target) <= MATCH_TOLERANCE * target
    else:  # nothing scanned was within the tolerance
        assert all(abs(a - target) > MATCH_TOLERANCE * target for a in scan.values())


def test_the_scan_is_read_from_a_compare_report_and_each_runs_config(tmp_path: Path) -> None:
    runs = []
    for k, acc in ((8e-5, 2.6), (8e-4, 2.4)):
        run = tmp_path / f"ctrl{k}"
        run.mkdir()
        (run / "config.json").write_text(json.dumps({"env_config": {"reward_params": {"base_acceleration": k}}}))
        metrics = {"lin_acc_rms": acc, "fell": 0.0}
        runs.append({"run_dir": str(run), "policy": str(run / "final_model.pt"), "metrics": metrics})
    report = {
        "variants": {"without margin": {"runs": runs}, "with margin": {"mean": {"lin_acc_rms": 2.33}}},
    }
    scan = scan_of_report(report)
    assert (scan.target, scan.accelerations, scan.not_walking) == (2.33, {8e-5: 2.6, 8e-4: 2.4}, {})
    runs[1]["run_dir"] = runs[0]["run_dir"]  # the same weight twice
    with pytest.raises(ValueError, match="scanned twice"):
        scan_of_report(report)


def test_a_weight_whose_policy_does_not_walk_is_set_apart_not_chosen(tmp_path: Path) -> None:
    runs = []
    # 8e-4: closer to the target but falls in 2 % of its episodes; 8e-3: every episode over within the first second
    for k, acc, fell in ((8e-5, 1.93, 0.0), (8e-4, 2.3, 0.02), (8e-3, None, 1.0)):
        run = tmp_path / f"ctrl{k}"
        run.mkdir()
        (run / "config.json").write_text(json.dumps({"env_config": {"reward_params": {"base_acceleration": k}}}))
        metrics = {"lin_acc_rms": acc, "fell": fell, "velocity_error_mean": 0.6 if acc is None else 0.05}
        runs.append({"run_dir": str(run), "policy": str(run / "final_model.pt"), "metrics": metrics})
    report = {"variants": {"without margin": {"runs": runs}, "with margin": {"mean": {"lin_acc_rms": 2.33}}}}
    scan = scan_of_report(report)
    assert scan.accelerations == {8e-5: 1.93} and scan.falls == {8e-5: 0.0, 8e-4: 0.02, 8e-3: 1.0}
    assert scan.not_walking == {
        8e-4: {"fell": 0.02, "velocity_error_mean": 0.05, "lin_acc_rms": 2.3},
        8e-3: {"fell": 1.0, "velocity_error_mean": 0.6, "lin_acc_rms": None},
    }
    assert choose_control_weight(scan.target, scan.accelerations).k == 8e-5
    runs[0]["metrics"]["fell"] = 0.01  # the gate's bound itself still walks
    assert scan_of_report(report).accelerations == {8e-5: 1.93}
    runs.pop(0)  # nothing left that walks
    with pytest.raises(ValueError, match="no scanned weight left a policy that walks"):
        scan_of_report(report)
