"""``python -m margin_rl.train kernels``: its bad input refused in one line before anything is compiled (the
compilation itself: tests/envs/test_warp_kernels.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from margin_rl.train.__main__ import COMMANDS
from margin_rl.train.commands.kernels import main


def test_the_command_is_listed() -> None:
    assert COMMANDS["kernels"] == "margin_rl.train.commands.kernels"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--steps", "1"], "--steps >= 2"),
        (["--num-envs", "0"], "--num-envs must be >= 1"),
        (["--env", "margin_rl/NoSuchRobot-v1"], "error:"),
        (["--physics-option", "nconmax"], "error:"),
    ],
)
def test_bad_input_is_one_line_and_compiles_nothing(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("mujoco_warp")
    assert main([*argv, "--cache", str(tmp_path / "cache")]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "cache").exists()
