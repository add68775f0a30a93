"""benchmarks/studies/bench_margin_rough_levels.py: how it chooses its policies, and the bad choices it names."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

from benchmarks.studies import bench_margin_rough_levels as study


def _fails(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], *args: str) -> str:
    monkeypatch.setattr(sys, "argv", ["bench_margin_rough_levels.py", *args])
    with pytest.raises(SystemExit) as stopped:
        study.main()
    assert stopped.value.code == 2
    return capsys.readouterr().err


def test_runs_and_bundle_seeds_are_one_choice(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    error = _fails(monkeypatch, capsys, "--runs", "runs/a", "--bundle-seeds", "0")
    assert "--runs and --bundle-seeds choose the policies two ways" in error


def test_a_run_without_a_policy_is_named(monkeypatch: pytest.MonkeyPatch, capsys, tmp_path: Path) -> None:
    unfinished = tmp_path / "c_mw0_s0"
    unfinished.mkdir()
    error = _fails(monkeypatch, capsys, "--runs", str(unfinished))
    assert f"no policy at {unfinished / 'final_model.pt'}" in error


def test_a_policy_of_the_other_robot_is_refused(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    from margin_rl.train.artifacts.bundle import load_bundle

    policy = load_bundle("anymal_b").runs[0].policy  # a shipped ANYmal B policy
    error = _fails(monkeypatch, capsys, "--robot", "anymal_c", "--runs", str(policy))
    assert "was trained on anymal_b, not --robot anymal_c" in error


def test_the_tail_statistics_set_the_largest_errors_aside_and_describe_them() -> None:
    import numpy as np

    from margin_rl.stability import LAMBDA_DIM, LAMBDA_SLICES

    class Shifted:
        """A stand-in network: the target plus a known error per state."""

        def __init__(self, error: np.ndarray) -> None:
            self.error = error

        def __call__(self, lam: np.ndarray) -> np.ndarray:
            return lam[:, 0] + self.error

        def out_of_distribution(self, lam: np.ndarray) -> np.ndarray:
            return np.zeros(len(lam), dtype=bool)

    rng = np.random.default_rng(0)
    lam = rng.normal(size=(50, LAMBDA_DIM))
    lam[:, LAMBDA_SLICES["contacts"]] = rng.integers(0, 2, size=(50, 4))
    error = rng.normal(0.0, 0.01, size=50)
    error[[7, 30, 41]] = [0.5, -0.9, 0.3]  # three outliers: the tail
    result = study.compare(lam, lam[:, 0], Shifted(error))
    assert result["rmse_m"] == pytest.approx(np.sqrt(np.mean(error**2)))
    kept = np.delete(error, [7, 30, 41])
    assert result[f"rmse_without_largest_{study.LARGEST}_m"] == pytest.approx(np.sqrt(np.mean(kept**2)))
    assert result["median_abs_error_m"] == pytest.approx(np.median(np.abs(error)))
    worst = result["largest"][0]  # largest first: state 30
    assert worst["learned_m"] - worst["analytic_m"] == pytest.approx(-0.9)
    assert worst["com_acc"] == pytest.approx(lam[30, LAMBDA_SLICES["com_acc"]].tolist())
    assert worst["contacts"] == int(lam[30, LAMBDA_SLICES["contacts"]].sum())
    assert [round(e["learned_m"] - e["analytic_m"], 6) for e in result["largest"]] == [-0.9, 0.5, 0.3]
