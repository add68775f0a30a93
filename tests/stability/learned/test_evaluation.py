"""The paper's evaluation protocol: two-sigma subset, classification rates, acceleration sweeps, CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from margin_rl.robot import load_robot
from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES, from_lambda
from margin_rl.stability.analytic.margin import AnalyticSettings, analytic_margin
from margin_rl.stability.learned.evaluation import (
    acceleration_sweep_states,
    acceleration_sweeps,
    main,
    nominal_sweep_bases,
    reliability,
    within_two_sigma,
)
from margin_rl.stability.learned.model import LearnedMargin

COM_ACC = LAMBDA_SLICES["com_acc"].start
CONTACTS = LAMBDA_SLICES["contacts"].start


def test_two_sigma_subset_by_hand() -> None:
    mean, std = np.zeros(47), np.ones(47)
    lam = np.zeros((4, 47))
    lam[1, 3] = 1.99  # inside
    lam[2, 12] = -2.01  # one entry outside
    lam[3, CONTACTS] = 5.0  # contact flags are exempt (module docstring)
    np.testing.assert_array_equal(within_two_sigma(lam, mean, std), [True, True, False, True])
    assert within_two_sigma(lam[2], mean, std, k=3.0) is True
    with pytest.raises(ValueError, match="k must be positive"):
        within_two_sigma(lam, mean, std, k=0.0)
    with pytest.raises(ValueError, match="47"):
        within_two_sigma(np.zeros(46), mean, std)


def test_reliability_rates_by_hand() -> None:
    analytic = np.array([0.05, 0.02, -0.01, -0.20, -0.30])  # stable, stable, unstable x3
    learned = np.array([0.10, -0.10, 0.20, -0.30, -0.25])  # called stable, unstable, stable, unstable x2
    r = reliability(learned, analytic)
    assert r.n == 5 and r.stable_fraction == pytest.approx(0.4)
    assert r.true_positive_rate == pytest.approx(1 / 2)
    assert r.true_negative_rate == pytest.approx(2 / 3)
    assert r.sign_agreement == pytest.approx(3 / 5)
    assert r.rmse_cm == pytest.approx(100 * np.sqrt(np.mean((learned - analytic) ** 2)))
    with pytest.raises(ValueError, match=r"\(N,\) arrays"):
        reliability(learned, analytic[:3])


def test_sweep_states_change_one_acceleration_entry_only() -> None:
    base = nominal_sweep_bases("anymal_b")["2 feet (LF+RH)"]
    before = base.copy()
    values = np.linspace(-2, 2, 5)
    states = acceleration_sweep_states(base, 1, values)
    np.testing.assert_array_equal(base, before)  # no mutation of the input
    np.testing.assert_array_equal(states[:, COM_ACC + 1], values)
    others = np.delete(np.arange(47), COM_ACC + 1)
    np.testing.assert_array_equal(states[:, others], np.repeat(base[None, others], 5, axis=0))
    np.testing.assert_array_equal(from_lambda(base).contacts, [1, 0, 0, 1])
    with pytest.raises(ValueError, match="axis 0 or 1"):
        acceleration_sweep_states(base, 2, values)


def test_sweeps_agree_with_direct_evaluations_two_ways() -> None:
    """The sweep's analytic values are those of analytic_margin state by state, and its learned slopes
    (backpropagation) match central differences of the learned values along the grid."""
    model = LearnedMargin.load("anymal_c")
    bases = {"double": nominal_sweep_bases("anymal_c")["2 feet (LF+RH)"]}
    result = acceleration_sweeps("anymal_c", model, bases, points=9, workers=1)
    assert result.analytic.shape == result.learned.shape == (1, 2, 9)
    robot = load_robot("anymal_c")
    for axis in (0, 1):
        states = acceleration_sweep_states(bases["double"], axis, result.values)
        direct = [analytic_margin(robot, s).margin for s in states[::4]]
        np.testing.assert_allclose(result.analytic[0, axis, ::4], direct, atol=1e-9)
        np.testing.assert_allclose(result.learned[0, axis], model(states), atol=1e-5)
    h = 1e-4
    for axis in (0, 1):
        states = acceleration_sweep_states(bases["double"], axis, result.values)
        plus, minus = states.copy(), states.copy()
        plus[:, COM_ACC + axis] += h
        minus[:, COM_ACC + axis] -= h
        fd = (np.array([model(s) for s in plus]) - np.array([model(s) for s in minus])) / (2 * h)
        np.testing.assert_allclose(result.learned_slope[0, axis], fd, atol=1e-6)
    summary = result.summary()
    assert summary["sweeps"] == 2 and summary["points_ok"] == 18
    assert 0 <= summary["fraction_of_points_within_tolerance"] <= 1
    assert np.isnan(result.analytic_slope[..., 0]).all()  # no central difference at the ends


def test_cli_writes_report_and_figure(tmp_path: Path) -> None:
    out, figure = tmp_path / "report.json", tmp_path / "sweeps.png"
    args = ["--robot", "anymal_b", "--n", "60", "--sweeps", "1", "--workers", "1", "--out", str(out)]
    assert main([*args, "--figure", str(figure)]) == 0
    report = json.loads(out.read_text())
    rel = report["reliability"]
    assert rel["states_drawn"] == 60 and rel["within_2_sigma"]["n"] <= rel["all"]["n"] == rel["states_ok"]
    assert set(report["acceleration_sweeps"]["nominal"]) == {"4 feet", "3 feet (LH lifted)", "2 feet (LF+RH)"}
    assert report["acceleration_sweeps"]["table_i"]["sweeps"] == 2
    assert figure.stat().st_size > 10_000


def test_cli_update_card_keeps_the_weights_loadable(tmp_path: Path) -> None:
    import shutil

    from margin_rl.stability.learned.model import weights_path

    bundled = weights_path("anymal_b")
    for suffix in (".npz", ".json"):
        shutil.copy(bundled.with_suffix(suffix), tmp_path / f"b{suffix}")
    args = ["--robot", "anymal_b", "--weights", str(tmp_path / "b.npz"), "--n", "20", "--sweeps", "0"]
    assert main([*args, "--workers", "1", "--update-card"]) == 0
    card = LearnedMargin.load(tmp_path / "b.npz").card  # checksum still verified
    assert card["paper_protocol"]["reliability"]["states_drawn"] == 20
    # The same settings (the report names the labelling path, which settings recorded before it imply).
    recorded = AnalyticSettings.from_dict(card["analytic_settings"])
    assert AnalyticSettings.from_dict(card["paper_protocol"]["analytic_settings"]) == recorded
    assert "table_i" not in card["paper_protocol"]["acceleration_sweeps"]


def test_cli_gradient_check_goes_into_the_card(tmp_path: Path) -> None:
    import shutil

    from margin_rl.stability.learned.model import weights_path

    bundled = weights_path("anymal_c")
    for suffix in (".npz", ".json"):
        shutil.copy(bundled.with_suffix(suffix), tmp_path / f"c{suffix}")
    args = ["--robot", "anymal_c", "--weights", str(tmp_path / "c.npz"), "--n", "10", "--sweeps", "0"]
    assert main([*args, "--workers", "1", "--gradient-states", "3", "--update-card"]) == 0
    card = LearnedMargin.load(tmp_path / "c.npz").card
    check = card["gradient_check"]
    assert check["states"] == "fresh Table I" and "--gradient-states 3" in check["command"]
    # 43 continuous entries (the four contact flags are skipped), each perturbed both ways, per state.
    assert check["analytic_calls"] == 3 * 43 * 2 and 0 < check["n_states"] <= 3
    assert -1.0 <= check["median_cosine"] <= 1.0
    assert "gradient_check" not in card["paper_protocol"]


def test_cli_refuses_weights_of_another_robot(capsys: pytest.CaptureFixture[str]) -> None:
    from margin_rl.stability.learned.model import weights_path

    with pytest.raises(SystemExit):
        main(["--robot", "anymal_b", "--weights", str(weights_path("anymal_c")), "--n", "5"])
    assert "learned margin of 'anymal_c', not of --robot 'anymal_b'" in capsys.readouterr().err
