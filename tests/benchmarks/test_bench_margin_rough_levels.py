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
