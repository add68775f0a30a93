"""The learned-margin figure CLI writes both PNGs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from margin_rl.robot import load_robot
from margin_rl.stability.analytic.lambda_state import from_lambda
from margin_rl.stability.analytic.sampling import nominal_feet
from margin_rl.stability.learned.figures import main, offset_grid_states


def test_offset_grid_moves_the_feet_opposite_to_the_base() -> None:
    lam = offset_grid_states("anymal_b", np.array([0.1]), np.array([-0.05]))
    feet = from_lambda(lam[0]).feet
    np.testing.assert_allclose(feet, nominal_feet(load_robot("anymal_b")) - [0.1, -0.05, 0.0])


def test_cli_writes_the_figures(tmp_path: Path) -> None:
    assert main(["--robot", "anymal_b", "--out", str(tmp_path), "--n", "30", "--workers", "1"]) == 0
    for name in ("anymal_b_margin_map.png", "anymal_b_learned_vs_analytic.png"):
        assert (tmp_path / name).stat().st_size > 10_000
