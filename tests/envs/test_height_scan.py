"""The actor's optional height scan (EnvConfig.height_scan, observations.HEIGHT_SCAN): its layout in the observation,
its values on flat ground and on a step seen from a turned base (the heading frame), and its bad inputs."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import margin_rl  # noqa: F401 - registers the ids
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.observations import HEIGHT_SCAN, HEIGHT_SCAN_CLIP, HEIGHT_SCAN_POINTS, POLICY_OBSERVATIONS
from margin_rl.envs.terrain import Terrain
from margin_rl.robot import mjcf_names as names

BLIND = sum(t.size for t in POLICY_OBSERVATIONS)


def test_the_scan_follows_the_blind_terms_in_every_adapter() -> None:
    env = gym.make("margin_rl/AnymalC-v1", height_scan=True)
    observation, _ = env.reset(seed=0)
    assert observation.shape == (BLIND + HEIGHT_SCAN.size,) == env.observation_space.shape
    assert list(env.unwrapped.observation_structure)[-1] == "height_scan" and HEIGHT_SCAN.size == 17 * 11
    envs = gym.make_vec("margin_rl/AnymalC-v1", num_envs=3, height_scan=True)
    observations, _ = envs.reset(seed=0)
    assert observations.shape == (3, BLIND + HEIGHT_SCAN.size)
    # Flat ground, robots dropped 2 cm above their standing height: every point reads +2 cm (times the scale).
    np.testing.assert_allclose(observations[:, BLIND:] / HEIGHT_SCAN.scale, 0.02, atol=1e-5)
    assert gym.make("margin_rl/AnymalC-v1").observation_space.shape == (BLIND,)  # blind by default


def test_a_step_ahead_of_a_turned_robot_appears_in_the_cells_ahead() -> None:
    """A robot turned to face world +y in front of a 10 cm step at y >= 0.25 m: the scan points at x_H >= 0.3 m (in
    the heading frame, x forwards) read the step, the others the ground; values equal to base height - ground -
    standing height, point by point."""
    core = AnymalCore(EnvConfig(robot="anymal_c", height_scan=True), num_envs=1, seed=0)
    core.reset(seed=0)
    grid = np.arange(81) * 0.05 - 2.0  # nodes every 5 cm: every scan point falls on one
    core.terrain = Terrain(
        heights=np.where(grid[:, None] >= 0.25 - 1e-9, 0.1, 0.0) * np.ones((1, 81)),
        origin=(-2.0, -2.0),
        resolution=0.05,
        spawn_points=np.zeros((1, 3)),
    )
    yaw = math.pi / 2
    core.physics.qpos[0, names.BASE_POSITION_QPOS] = [0.0, 0.0, 0.6]
    core.physics.qpos[0, names.BASE_QUATERNION_QPOS] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
    core.physics.forward()
    scan = core._policy_values(core._read(), slice(None))["height_scan"][0]
    heading = np.array(HEIGHT_SCAN_POINTS)
    world_y = heading[:, 0]  # facing +y: the heading frame's x axis is the world's y axis
    expected = np.clip(0.6 - np.where(world_y >= 0.25, 0.1, 0.0) - core.robot.standing_height, -1.0, 1.0)
    np.testing.assert_allclose(scan, expected, atol=1e-9)
    assert np.all(scan[heading[:, 0] >= 0.3] < scan[heading[:, 0] <= 0.2].min())


def test_a_cliff_reads_as_the_clip() -> None:
    core = AnymalCore(EnvConfig(robot="anymal_c", height_scan=True), num_envs=1, seed=0)
    core.reset(seed=0)
    core.terrain = Terrain(heights=np.full((81, 81), -5.0), origin=(-2.0, -2.0), resolution=0.05,
                           spawn_points=np.zeros((1, 3)))  # fmt: skip
    np.testing.assert_allclose(core._policy_values(core._read(), slice(None))["height_scan"], HEIGHT_SCAN_CLIP)


def test_bad_inputs_name_the_field() -> None:
    with pytest.raises(TypeError, match="height_scan must be True or False"):
        EnvConfig(height_scan="yes")
    core = AnymalCore(EnvConfig(robot="anymal_c"), num_envs=1)
    with pytest.raises(ValueError, match="height_scan cannot change in a running environment"):
        core.reconfigure(core.config.replace(height_scan=True))
