"""Where a reset starts an episode (envs.reset_state): the draws in numpy's order of old, the standing state built
from them, the same on numpy and torch."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.arrays import TorchRandom
from margin_rl.envs.config import CommandConfig, EnvConfig, RandomizationConfig
from margin_rl.envs.reset_state import SPAWN_CLEARANCE, StandingStart, draw_reset

KEY_QPOS = np.concatenate([[0.1, -0.2, 0.55], [0.9, 0.1, 0.0, np.sqrt(1 - 0.82)], np.linspace(-0.8, 0.8, 12)])
COMMAND = CommandConfig(forward_velocity=(0.2, 1.0), lateral_velocity=(-0.3, 0.3), yaw_rate=(-0.5, 0.5))


def _config(friction: bool) -> EnvConfig:
    rnd = RandomizationConfig(friction=(0.4, 1.0) if friction else None, reset_joint_noise=0.2)
    return EnvConfig(robot="anymal_c", command=COMMAND, randomization=rnd)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 9), st.booleans())
def test_numpy_draws_are_the_calls_a_reset_always_made_in_their_order(seed: int, n: int, friction: bool) -> None:
    draws = draw_reset(np.random.default_rng(seed), n, _config(friction))
    rng = np.random.default_rng(seed)  # the calls one after another, as the reset made them before
    joint, velocity = rng.uniform(-1, 1, size=(n, 12)), rng.uniform(-1, 1, size=(n, 6))
    mu = rng.uniform(0.4, 1.0, size=n) if friction else None
    ranges = (COMMAND.forward_velocity, COMMAND.lateral_velocity, COMMAND.yaw_rate)
    command = np.stack([rng.uniform(*bounds, n) for bounds in ranges], axis=1)
    assert draws.joint_noise.tobytes() == joint.tobytes() and draws.velocity_noise.tobytes() == velocity.tobytes()
    assert (draws.friction is None) == (not friction)
    if friction:
        assert draws.friction.tobytes() == mu.tobytes()
    assert draws.command.tobytes() == command.tobytes()


def test_torch_draws_have_the_shapes_and_bounds_of_numpys() -> None:
    draws = draw_reset(TorchRandom(0, "cpu"), 500, _config(True))
    assert draws.joint_noise.shape == (500, 12) and draws.velocity_noise.shape == (500, 6)
    assert draws.friction.shape == (500,) and draws.command.shape == (500, 3)
    for values, low, high in [(draws.joint_noise, -1, 1), (draws.friction, 0.4, 1.0)]:
        assert float(values.min()) >= low and float(values.max()) < high
    for k, (low, high) in enumerate((COMMAND.forward_velocity, COMMAND.lateral_velocity, COMMAND.yaw_rate)):
        column = draws.command[:, k]
        assert float(column.min()) >= low and float(column.max()) < high
        assert float(column.max() - column.min()) > 0.9 * (high - low)  # spread over the range, not a constant


@pytest.mark.parametrize("kind", [np.asarray, torch.as_tensor])
def test_the_standing_state_is_the_keyframe_on_the_spawn_point_with_the_noise(kind) -> None:
    config, n, nv = _config(False), 5, 18
    draws = draw_reset(np.random.default_rng(3), n, config)
    spawn = np.random.default_rng(4).normal(size=(n, 3))
    start = StandingStart.of(kind(KEY_QPOS), nv)
    as_kind = type(draws)(*(kind(v) if v is not None else None for v in vars(draws).values()))
    qpos, qvel = (np.asarray(a) for a in start.state(kind(spawn), as_kind, config))
    assert qpos.shape == (n, 19) and qvel.shape == (n, nv) and qpos.dtype == qvel.dtype == np.float64
    np.testing.assert_array_equal(qpos[:, :2], spawn[:, :2])
    np.testing.assert_array_equal(qpos[:, 2], spawn[:, 2] + KEY_QPOS[2] + SPAWN_CLEARANCE)
    np.testing.assert_array_equal(qpos[:, 3:7], np.broadcast_to(KEY_QPOS[3:7], (n, 4)))
    np.testing.assert_array_equal(qpos[:, 7:], KEY_QPOS[7:] + draws.joint_noise * 0.2)
    np.testing.assert_array_equal(qvel[:, :6], draws.velocity_noise * config.randomization.reset_velocity_noise)
    assert (qvel[:, 6:] == 0).all()
