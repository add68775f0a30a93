"""benchmarks/studies/bench_terrain_normals.py: the states it changes and the margin change it reports."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

from benchmarks.studies import bench_terrain_normals as study
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES


def standing_states() -> np.ndarray:
    """lambda of ANYmal C standing on flat ground (all four feet in contact, vertical normals), 2 environments."""
    core = AnymalCore(EnvConfig(robot="anymal_c", margin="none"), 2, seed=0)
    core.reset()
    for _ in range(25):
        out = core.step(np.zeros((2, 12)))
    lam = np.asarray(out.info["lambda"])
    assert np.all(lam[:, LAMBDA_SLICES["contacts"]] == 1)
    return lam


def test_vertical_normals_change_only_the_normals_and_only_tilted_states_move() -> None:
    lam = standing_states()
    tilted = lam.copy()
    angle = np.radians(20.0)
    normals = tilted[1, LAMBDA_SLICES["normals"]].reshape(4, 3)
    normals[0] = [0.0, -np.sin(angle), np.cos(angle)]  # LF stands on a 20 degree side slope
    tilted[1, LAMBDA_SLICES["normals"]] = normals.ravel()
    assert study.tilted(tilted, 1.0).tolist() == [False, True]
    vertical = study.with_vertical_normals(tilted)
    others = np.ones(lam.shape[1], dtype=bool)
    others[LAMBDA_SLICES["normals"]] = False
    np.testing.assert_array_equal(vertical[:, others], tilted[:, others])
    np.testing.assert_array_equal(vertical, study.with_vertical_normals(lam))  # flat ground: nothing to change
    np.testing.assert_allclose(study.with_vertical_normals(lam), lam, atol=1e-9)
    effect = study.normals_effect("anymal_c", tilted, 1.0)
    assert effect["states"] == 2 and effect["tilted_share"] == 0.5
    assert abs(effect["change_mean_m"]) > 1e-4  # a 20 degree cone under one foot moves the margin
