"""The action-noise check: the clipped share of Gaussian samples, the monitor, and both backends reporting it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import norm

from margin_rl.envs.core import ACTION_BOUND
from margin_rl.train.exploration import CLIPPED_SHARE_LIMIT, ExplorationMonitor, NoiseReport, clipped_fraction
from tests.train.conftest import tiny_args


def _clipped_share(mean: float, std: float, bound: float) -> float:
    """P(|mean + std ε| > bound), ε ~ N(0, 1), from the normal CDF (scipy), not erfc."""
    return float(norm.cdf(-bound, loc=mean, scale=std) + norm.sf(bound, loc=mean, scale=std))


@given(
    std=st.floats(0.05, 20.0),
    bound=st.floats(0.1, 5.0),
)
def test_clipped_fraction_is_the_gaussian_tail_outside_the_bound(std: float, bound: float) -> None:
    assert clipped_fraction(std, bound) == pytest.approx(_clipped_share(0.0, std, bound), rel=1e-9, abs=1e-12)


def test_clipped_fraction_against_samples_and_hand_values() -> None:
    rng = np.random.default_rng(0)
    samples = rng.normal(0.0, 2.7, size=400_000)
    assert clipped_fraction(2.7) == pytest.approx(np.mean(np.abs(samples) > ACTION_BOUND), abs=3e-3)
    assert clipped_fraction(1.0) == pytest.approx(0.3173, abs=1e-4)  # outside one sigma
    assert clipped_fraction(0.5) == pytest.approx(0.0455, abs=1e-4)  # outside two sigma


@settings(max_examples=60)
@given(mean=st.floats(-3.0, 3.0), std=st.floats(0.05, 10.0))
def test_a_mean_off_zero_never_clips_less(mean: float, std: float) -> None:
    assert _clipped_share(mean, std, ACTION_BOUND) >= clipped_fraction(std) - 1e-12


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_bad_std_or_bound_is_refused(bad: float) -> None:
    with pytest.raises(ValueError, match="std must be"):
        clipped_fraction(bad)
    with pytest.raises(ValueError, match="bound must be"):
        clipped_fraction(1.0, bad)
    with pytest.raises(ValueError, match="bound must be"):
        ExplorationMonitor(bound=bad)


def test_the_limit_is_half_of_the_samples_clipped() -> None:
    assert clipped_fraction(1.48) < CLIPPED_SHARE_LIMIT < clipped_fraction(1.49)
    reports: list[NoiseReport] = []
    monitor = ExplorationMonitor(warn=reports.append, bound=2.0)  # the limit scales with the bound
    monitor.update(2.96, 1)
    assert not reports
    monitor.update(2.98, 2)
    assert len(reports) == 1


def test_the_monitor_warns_once_at_the_first_std_that_clips_too_often() -> None:
    reports: list[NoiseReport] = []
    monitor = ExplorationMonitor(warn=reports.append)
    for steps, std in [(100, 0.0), (200, 1.0), (300, 1.3), (400, 1.6), (500, 2.5), (600, 0.8)]:
        monitor.update(std, steps)
    assert len(reports) == 1
    assert reports[0].env_steps == 400 and reports[0].mean_std == 1.6
    assert reports[0].clipped_fraction == pytest.approx(clipped_fraction(1.6))
    assert monitor.last_mean_std == 0.8
    assert "entropy_coef" in reports[0].message() and "1.60" in reports[0].message()
    with pytest.raises(ValueError, match="mean action std"):
        monitor.update(math.nan, 600)


@pytest.mark.parametrize("backend", ["rsl", "sb3"])
def test_training_with_noise_that_clips_most_actions_warns_and_rsl_records_the_std(
    backend: str, toy_weights: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from margin_rl.train.commands.train import main

    run_dir = tmp_path / backend
    args = [*tiny_args(backend, run_dir, toy_weights, total=192, every=192), "--ppo-option", "init_noise_std=2.0"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "mean action-noise std is 2.0" in err and err.count("mean action-noise std") == 1
    if backend == "rsl":
        saved = torch.load(run_dir / "final_model.pt", weights_only=True)
        assert saved["infos"]["action_std"] == pytest.approx(2.0, abs=0.1)


def test_an_rsl_run_records_its_last_action_std(rsl_run: Path) -> None:
    saved = torch.load(rsl_run / "final_model.pt", weights_only=True)
    assert 0.9 < saved["infos"]["action_std"] < 1.1  # init_noise_std 1.0, two tiny updates


def test_resuming_a_finished_rsl_run_keeps_its_action_std(rsl_run: Path, toy_weights: str, tmp_path: Path) -> None:
    """A resume that adds no iteration (e.g. to name the learned-margin weights the run started with) saves the
    final model again with the std the run had reached, not without it."""
    import shutil

    from margin_rl.train.commands.train import main

    run_dir = tmp_path / "finished"
    shutil.copytree(rsl_run, run_dir)
    before = torch.load(run_dir / "final_model.pt", weights_only=True)["infos"]["action_std"]
    assert main(["--resume", str(run_dir), "--margin-weights", toy_weights, "--no-progress"]) == 0
    after = torch.load(run_dir / "final_model.pt", weights_only=True)["infos"]["action_std"]
    assert before is not None and after == before
