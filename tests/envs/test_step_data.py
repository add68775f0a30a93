"""The step's records (envs.step_data): the finite-difference accelerations against their formulas written out, and
the heading frame a state computes once."""

from __future__ import annotations

import numpy as np
import torch

from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.stability_input import heading_rotation
from margin_rl.envs.step_data import estimate_accelerations


def test_the_accelerations_are_the_differences_over_the_step_and_their_filter_the_ema() -> None:
    rng = np.random.default_rng(0)
    velocities, previous, filtered = rng.normal(size=(5, 18)), rng.normal(size=(5, 18)), rng.normal(size=(5, 6))
    alpha, dt = 0.5, 0.02
    for kind in (np.asarray, torch.from_numpy):
        acc, new_filtered = estimate_accelerations(kind(velocities), kind(previous), kind(filtered), alpha, dt)
        difference = (velocities - previous) / dt
        np.testing.assert_array_equal(np.asarray(acc.com_measured), difference[:, 0:3])
        np.testing.assert_array_equal(np.asarray(acc.base_angular_measured), difference[:, 3:6])
        np.testing.assert_array_equal(np.asarray(acc.joints), difference[:, 6:])
        ema = alpha * filtered + (1 - alpha) * difference[:, :6]
        np.testing.assert_array_equal(np.asarray(new_filtered), ema)
        np.testing.assert_array_equal(np.asarray(acc.com), ema[:, :3])
        np.testing.assert_array_equal(np.asarray(acc.base_angular), ema[:, 3:])
    # a constant acceleration of 1 m/s^2 along x over one 20 ms step, from rest, with no filter
    still, moving = np.zeros((1, 18)), np.zeros((1, 18))
    moving[0, 0] = 0.02
    acc, _ = estimate_accelerations(moving, still, np.zeros((1, 6)), 0.0, 0.02)
    np.testing.assert_allclose(acc.com, [[1.0, 0.0, 0.0]])


def test_a_state_computes_its_heading_frame_once() -> None:
    core = AnymalCore(EnvConfig(robot="anymal_c"), 3, seed=0)
    core.reset(seed=0)
    core.step(np.random.default_rng(1).uniform(-1, 1, (3, 12)))
    state = core._read()
    np.testing.assert_array_equal(state.heading_rot, heading_rotation(state.base_rot))
    assert state.heading_rot is state.heading_rot
