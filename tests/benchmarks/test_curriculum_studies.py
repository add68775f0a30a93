"""benchmarks/studies/curriculum_moves.py and heading_drift.py: the tally by hand, and the bad choices they name."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

from benchmarks.studies import curriculum_moves, heading_drift


def test_the_tally_by_hand() -> None:
    ends = [
        {"row": 2, "next": 3, "fell": False, "command": 1.0},
        {"row": 2, "next": 1, "fell": False, "command": 0.4},
        {"row": 2, "next": 1, "fell": True, "command": 0.6},
        {"row": 2, "next": 2, "fell": True, "command": 0.8},
        {"row": 5, "next": 6, "fell": False, "command": 0.5},
    ]
    two, five = curriculum_moves.tally(ends)
    assert two == {
        "row": 2, "episodes": 4, "promoted": 1, "demoted": 2, "stayed": 1, "demoted_fell": 1, "demoted_timed_out": 1,
        "command_promoted": 1.0, "command_demoted": pytest.approx(0.5),
    }  # fmt: skip
    assert five["promoted"] == 1 and five["demoted"] == 0 and five["command_demoted"] is None


def test_a_run_without_a_policy_is_named(monkeypatch: pytest.MonkeyPatch, capsys, tmp_path: Path) -> None:
    for module, name in ((curriculum_moves, "curriculum_moves.py"), (heading_drift, "heading_drift.py")):
        args = [str(tmp_path)] if module is curriculum_moves else ["--runs", str(tmp_path)]
        monkeypatch.setattr(sys, "argv", [name, *args])
        with pytest.raises(SystemExit) as stopped:
            module.main()
        assert stopped.value.code == 2 and f"no policy at {tmp_path / 'final_model.pt'}" in capsys.readouterr().err
