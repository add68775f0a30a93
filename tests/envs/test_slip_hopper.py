"""SLIP hopper environment: Gymnasium API, reward terms, determinism, failures, action handling, margin term."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import margin_rl  # noqa: F401 - registers the ids
from margin_rl.envs import SLIP_HOPPER_ENV_ID, SLIP_HOPPER_EPISODE_HOPS
from margin_rl.envs.slip_hopper import ACTION_HIGH, ACTION_LOW, SlipHopperEnv, action_to_physical
from margin_rl.slip.dynamics import Status, simulate_hop
from margin_rl.slip.models import load_bundle

# A hop that returns to an apex inside the eq. (13) box: s = [1.1, 0.3], alpha = 0.1, delta_L = 0.03.
GOOD_STATE = np.array([1.1, 0.3])
GOOD_ACTION = np.array([0.1 / 0.6, (0.03 - 0.05) / 0.1])


def make(**kwargs: object) -> gym.Env:
    return gym.make(SLIP_HOPPER_ENV_ID, **kwargs)


@pytest.mark.parametrize("render_mode", [None, "rgb_array"])
def test_check_env(render_mode: str | None) -> None:
    env = make(render_mode=render_mode)
    check_env(env.unwrapped)
    assert env.spec.max_episode_steps == SLIP_HOPPER_EPISODE_HOPS == 50
    assert env.observation_space.shape == (3,) and env.observation_space.dtype == np.float32
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(np.isfinite(env.observation_space.high))
    assert env.action_space.shape == (2,) and np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)
    env.close()


def test_registration_is_idempotent() -> None:
    from margin_rl.envs import register_envs, register_slip_envs

    spec = gym.spec(SLIP_HOPPER_ENV_ID)
    register_envs()
    register_slip_envs()
    assert gym.spec(SLIP_HOPPER_ENV_ID) is spec


def test_action_mapping_is_the_eq13_action_box() -> None:
    np.testing.assert_allclose(action_to_physical([-1.0, -1.0]), [-0.6, -0.05])
    np.testing.assert_allclose(action_to_physical([1.0, 1.0]), [0.6, 0.15])
    np.testing.assert_allclose(action_to_physical([0.0, 0.0]), 0.5 * (ACTION_LOW + ACTION_HIGH))


def test_reward_is_the_sum_of_the_terms() -> None:
    env = make(margin_weight=0.7)
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    steps = 0
    for _ in range(30):
        _, reward, terminated, truncated, info = env.step(rng.uniform(-0.4, 0.4, 2))
        terms = {k: v for k, v in info.items() if k.startswith("reward_")}
        assert set(terms) == {"reward_tracking", "reward_margin", "reward_failure"}
        assert reward == pytest.approx(sum(terms.values()), abs=1e-12)
        steps += 1
        if terminated or truncated:
            env.reset()
    assert steps == 30


def test_successful_hop_tracks_the_next_apex_velocity() -> None:
    env = make(goal_velocity=0.5, margin_weight=0.0)
    obs, _ = env.reset(seed=0, options={"state": GOOD_STATE})
    np.testing.assert_allclose(obs, [1.1, 0.3, 0.5], rtol=1e-6)
    obs, reward, terminated, truncated, info = env.step(GOOD_ACTION)
    ref = simulate_hop(GOOD_STATE, [0.1, 0.03])
    assert ref.ok and info["status"] is Status.OK and not terminated and not truncated
    np.testing.assert_allclose(info["apex_state"], ref.next_apex[1:], atol=1e-12)
    np.testing.assert_allclose(obs, [*ref.next_apex[1:], 0.5], rtol=1e-6)
    assert info["dx"] == pytest.approx(ref.next_apex[0]) and info["x"] == pytest.approx(ref.next_apex[0])
    expected = np.exp(-(((ref.next_apex[2] - 0.5) / 0.25) ** 2))
    assert info["reward_tracking"] == pytest.approx(expected, abs=1e-12)
    assert info["reward_failure"] == 0.0
    assert reward == pytest.approx(expected, abs=1e-12)


def test_same_seed_same_rollout() -> None:
    def rollout(seed: int) -> tuple[np.ndarray, np.ndarray]:
        env = make()
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        observations, rewards = [obs], []
        for _ in range(12):
            obs, reward, terminated, truncated, _ = env.step(rng.uniform(-0.3, 0.3, 2))
            observations.append(obs)
            rewards.append(reward)
            if terminated or truncated:
                obs, _ = env.reset()
                observations.append(obs)
        return np.array(observations), np.array(rewards)

    a, b, c = rollout(5), rollout(5), rollout(6)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0][0], c[0][0])


@pytest.mark.parametrize(
    ("state", "action", "status"),
    [
        ([1.1, 0.0], [1.0, 0.0], Status.SLIP),  # alpha = 0.6 rad: |tan(alpha)| > mu = 0.5 at touchdown
        ([0.8, 0.0], [1.0, 0.0], Status.NO_TOUCHDOWN),  # cos(0.6) = 0.825 > y
    ],
)
def test_failure_terminates_with_a_status(state: list[float], action: list[float], status: Status) -> None:
    env = make(margin_weight=0.0, failure_reward=-2.0)
    obs0, _ = env.reset(seed=0, options={"state": state, "goal_velocity": 0.0})
    obs, reward, terminated, truncated, info = env.step(np.array(action))
    assert terminated and not truncated
    assert info["status"] is status and info["failed"]
    assert simulate_hop(state, action_to_physical(action)).status is status
    np.testing.assert_array_equal(obs, obs0)  # no next apex: the state is kept
    assert info["reward_tracking"] == 0.0 and info["reward_failure"] == -2.0
    assert reward == -2.0


def test_leaving_the_box_terminates_unless_disabled() -> None:
    action = np.array([0.0, 1.0])  # alpha = 0, delta_L = 0.15 from y = 1.15: the next apex is above 1.2
    for flag in (True, False):
        env = make(terminate_out_of_box=flag, failure_reward=-1.0)
        env.reset(seed=0, options={"state": [1.15, 0.0]})
        obs, reward, terminated, _, info = env.step(action)
        assert info["status"] is Status.OK and info["out_of_box"] and not info["failed"]
        assert info["apex_state"][0] > 1.2 and obs[0] == pytest.approx(info["apex_state"][0])
        assert terminated is flag
        assert info["reward_failure"] == (-1.0 if flag else 0.0)
        assert reward == pytest.approx(info["reward_tracking"] + info["reward_margin"] + info["reward_failure"])
        assert env.observation_space.contains(obs)


def test_nan_action_raises() -> None:
    env = make()
    env.reset(seed=0)
    for bad in ([np.nan, 0.0], [0.0, np.inf]):
        with pytest.raises(ValueError, match="finite"):
            env.step(np.array(bad, dtype=np.float32))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))


def test_out_of_range_action_is_clipped() -> None:
    def step(action: list[float]) -> tuple[np.ndarray, float, dict]:
        env = make()
        env.reset(seed=0, options={"state": GOOD_STATE, "goal_velocity": 0.2})
        obs, reward, _, _, info = env.step(np.array(action))
        return obs, reward, info

    for wild, edge in (([5.0, -7.0], [1.0, -1.0]), ([-3.0, 0.5], [-1.0, 0.5])):
        obs_w, rew_w, info_w = step(wild)
        obs_e, rew_e, info_e = step(edge)
        np.testing.assert_array_equal(obs_w, obs_e)
        assert rew_w == rew_e and info_w["status"] == info_e["status"]
        assert (info_w["alpha"], info_w["delta_l"]) == (info_e["alpha"], info_e["delta_l"])
    assert info_w["alpha"] == pytest.approx(-0.6) and info_w["delta_l"] == pytest.approx(0.1)


def test_margin_weight_zero_has_a_zero_margin_term() -> None:
    env = make(margin_weight=0.0)
    env.reset(seed=0, options={"state": GOOD_STATE})
    _, _, _, _, info = env.step(GOOD_ACTION)
    assert info["reward_margin"] == 0.0
    assert info["margin"] != 0.0  # the margin itself is still reported


@pytest.mark.parametrize("weight", [1.0, 2.5])
def test_margin_term_is_the_bundled_learned_margin(weight: float) -> None:
    model = load_bundle().margin
    env = make(margin_weight=weight)
    env.reset(seed=1)
    rng = np.random.default_rng(1)
    for _ in range(6):
        state = env.unwrapped.state
        action = rng.uniform(-1, 1, 2)
        _, _, terminated, truncated, info = env.step(action)
        z = np.concatenate([state, action_to_physical(action)])
        expected = float(model(z[None])[0, 0])
        assert info["margin"] == pytest.approx(expected, abs=1e-12)
        assert info["reward_margin"] == pytest.approx(weight * expected, abs=1e-12)
        if terminated or truncated:
            env.reset()


def test_goal_sampling_and_options() -> None:
    env = make(goal_range=(-0.5, 0.25))
    goals = [env.reset(seed=s)[0][2] for s in range(20)]
    assert min(goals) >= -0.5 and max(goals) <= 0.25 and len(set(goals)) > 1
    obs, info = env.reset(seed=0, options={"goal_velocity": 0.1})
    assert obs[2] == pytest.approx(0.1) and info["goal_velocity"] == 0.1
    with pytest.raises(ValueError, match="goal_range"):
        env.reset(options={"goal_velocity": 0.9})
    with pytest.raises(ValueError, match="goal_range"):
        SlipHopperEnv(goal_velocity=2.0)
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(options={"speed": 0.1})
    fixed = make(goal_velocity=-0.3)
    assert {fixed.reset(seed=s)[0][2] for s in range(3)} == {np.float32(-0.3)}


def test_initial_state_distribution() -> None:
    env = make()
    states = np.array([env.reset(seed=s)[1]["apex_state"] for s in range(30)])
    assert np.all(states[:, 0] >= 1.0) and np.all(states[:, 0] <= 1.2)
    assert np.all(np.abs(states[:, 1]) <= 1.0)


def test_render_rgb_array() -> None:
    env = make(render_mode="rgb_array", width=320, height=240)
    env.reset(seed=0, options={"state": GOOD_STATE})
    first = env.render()
    env.step(GOOD_ACTION)
    image = env.render()
    assert image.shape == first.shape == (240, 320, 3) and image.dtype == np.uint8
    assert not np.array_equal(image, first)
