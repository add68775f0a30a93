"""Pickled and deep-copied environments step to exactly the same numbers as the originals (single env through
Gymnasium's wrappers, vector env in both autoreset modes, the core), with every kind of state in play: random
generator, commands, filters, pushes, friction and added masses, episode counters, rough terrain."""

from __future__ import annotations

import copy
import pickle
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import margin_rl  # noqa: F401 - registers the ids
from margin_rl.envs.config import CommandConfig, EnvConfig, RandomizationConfig
from margin_rl.envs.core import AnymalCore

EVERYTHING = RandomizationConfig(
    friction=(0.4, 1.0), added_base_mass=(-1.0, 2.0), push_interval_s=0.1, observation_noise=1.0
)
COMMANDS = CommandConfig(forward_velocity=(0.2, 1.0), lateral_velocity=(-0.3, 0.3), yaw_rate=(-0.5, 0.5))
COPIES: dict[str, Callable[[Any], Any]] = {
    "pickle": lambda env: pickle.loads(pickle.dumps(env)),
    "deepcopy": copy.deepcopy,
}


def assert_same_steps(original: Any, copies: list[Any], actions: np.ndarray) -> None:
    """Every copy returns bit-identical outputs to ``original`` for every action (and info entry)."""
    for action in actions:
        expected = original.step(action)
        for clone in copies:
            got = clone.step(action)
            for a, b in zip(expected[:4], got[:4], strict=True):
                np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
            assert set(expected[4]) == set(got[4])
            for key, value in expected[4].items():
                if isinstance(value, dict):
                    for k, v in value.items():
                        np.testing.assert_array_equal(v, got[4][key][k])
                elif isinstance(value, np.ndarray) and value.dtype == object:
                    for a, b in zip(value, got[4][key], strict=True):
                        np.testing.assert_array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
                else:
                    np.testing.assert_array_equal(value, got[4][key])


@pytest.mark.parametrize("env_id", ["margin_rl/AnymalB-v1", "margin_rl/AnymalC-Rough-v1"])
def test_single_env_copies_through_its_wrappers_step_identically(env_id: str) -> None:
    env = gym.make(env_id, randomization=EVERYTHING, command=COMMANDS, max_episode_steps=40)
    assert isinstance(env, gym.Wrapper)  # TimeLimit, OrderEnforcing, PassiveEnvChecker around AnymalEnv
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for action in rng.uniform(-1, 1, (7, 12)):  # mid-episode: filters, air times and pushes are running
        env.step(action)
    copies = [copy_(env) for copy_ in COPIES.values()]
    assert all(type(c) is type(env) and c.unwrapped is not env.unwrapped for c in copies)
    assert_same_steps(env, copies, rng.uniform(-1.5, 1.5, (33, 12)))  # up to the TimeLimit's truncation
    reset = [e.reset()[0] for e in (env, *copies)]  # no seed: the copied generators draw the same numbers
    for obs in reset[1:]:
        np.testing.assert_array_equal(obs, reset[0])
    env.close()


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_vector_env_copies_step_identically_across_episode_ends(mode: AutoresetMode) -> None:
    vec = gym.make_vec(
        "margin_rl/AnymalB-v1",
        num_envs=4,
        autoreset_mode=mode,
        randomization=EVERYTHING,
        command=COMMANDS,
        episode_length_s=0.3,  # 15 steps: the copies cross several autoresets
        seed=5,
    )
    vec.reset(seed=1)
    rng = np.random.default_rng(1)
    for action in rng.uniform(-1, 1, (9, 4, 12)):
        vec.step(action)
    copies = [copy_(vec) for copy_ in COPIES.values()]
    assert all(c.metadata["autoreset_mode"] is mode for c in copies)
    assert_same_steps(vec, copies, rng.uniform(-1.5, 1.5, (40, 4, 12)))
    seeded = [env.reset(seed=9)[0] for env in (vec, *copies)]
    for obs in seeded[1:]:
        np.testing.assert_array_equal(obs, seeded[0])
    vec.close()


def test_copied_core_keeps_running_pushes_and_its_state() -> None:
    core = AnymalCore(EnvConfig(robot="anymal_b", margin="none", randomization=EVERYTHING), 3, seed=2)
    core.reset(seed=4)
    core.push(np.array([0, 2]), np.array([[80.0, 0.0, 0.0], [0.0, -60.0, 0.0]]), 0.3, frame="heading")
    core.step(np.zeros((3, 12)))
    clone = pickle.loads(pickle.dumps(core))
    assert clone.physics is not core.physics and clone.terrain.is_flat
    for name in ("command", "mu", "_added_mass", "_push_steps_left", "_push_force", "_next_push", "episode_step"):
        np.testing.assert_array_equal(getattr(clone, name), getattr(core, name))
    masses = core.physics.per_env_field("body_mass")
    np.testing.assert_array_equal(clone.physics.per_env_field("body_mass"), masses)
    for action in np.random.default_rng(3).uniform(-1, 1, (20, 3, 12)):
        a, b = core.step(action), clone.step(action)
        np.testing.assert_array_equal(a.observation, b.observation)
        np.testing.assert_array_equal(a.reward, b.reward)
        np.testing.assert_array_equal(a.info["lambda"], b.info["lambda"])


def test_a_copy_is_independent_of_the_original() -> None:
    env = gym.make("margin_rl/AnymalB-v1", margin="none")
    env.reset(seed=0)
    clone = copy.deepcopy(env)
    before = clone.unwrapped.core.physics.qpos.copy()
    for _ in range(5):
        env.step(np.ones(12))
    np.testing.assert_array_equal(clone.unwrapped.core.physics.qpos, before)
    assert clone.unwrapped.core.rng is not env.unwrapped.core.rng


def test_a_diverged_state_is_copied_as_it_is_and_flagged_by_both() -> None:
    """MuJoCo's forward pass would reset a NaN state: the copy keeps it, so both flag the divergence."""
    core = AnymalCore(EnvConfig(robot="anymal_b", margin="none"), 2, seed=0)
    core.reset()
    core.step(np.zeros((2, 12)))
    core.physics.qvel[1, :] = np.nan
    clone = copy.deepcopy(core)
    assert np.isnan(clone.physics.qvel[1]).all()
    a, b = core.step(np.zeros((2, 12))), clone.step(np.zeros((2, 12)))
    assert a.info["diverged"].tolist() == b.info["diverged"].tolist() == [0.0, 1.0]
    np.testing.assert_array_equal(a.observation, b.observation)
