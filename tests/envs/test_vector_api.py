"""The native vector env's Gymnasium API: autoreset modes, get_attr / set_attr / call, seed errors, and the stock
wrapper stacks (CleanRL's Gymnasium vector wrappers; skrl's wrapper when skrl is installed)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from hypothesis import given, settings
from hypothesis import strategies as st

import margin_rl  # noqa: F401 - registers the ids
from margin_rl.envs.anymal import SeedError, SeedTypeError
from margin_rl.envs.config import RandomizationConfig, RewardParams
from margin_rl.envs.vector import AUTORESET_MODES, check_autoreset_mode

ENV_ID = "margin_rl/AnymalB-v1"
FAST = {"margin": "none"}


# ---------------------------------------------------------------------------------------------------------------------
# autoreset modes
# ---------------------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("given_mode", "expected"),
    [
        (AutoresetMode.NEXT_STEP, AutoresetMode.NEXT_STEP),
        (AutoresetMode.SAME_STEP, AutoresetMode.SAME_STEP),
        ("NextStep", AutoresetMode.NEXT_STEP),
        ("SameStep", AutoresetMode.SAME_STEP),
        ("SAME_STEP", AutoresetMode.SAME_STEP),
    ],
)
def test_autoreset_mode_arrives_as_a_make_vec_keyword(given_mode: object, expected: AutoresetMode) -> None:
    vec = gym.make_vec(ENV_ID, num_envs=2, autoreset_mode=given_mode, **FAST)
    assert vec.metadata["autoreset_mode"] is expected and vec.autoreset_mode is expected
    assert type(vec).metadata["autoreset_mode"] is AUTORESET_MODES[0] is AutoresetMode.NEXT_STEP  # the default
    vec.close()


def test_disabled_and_unknown_modes_are_refused_with_the_accepted_ones_named() -> None:
    with pytest.raises(ValueError, match=r"DISABLED is not offered .*NEXT_STEP \('NextStep'\), .*SAME_STEP"):
        gym.make_vec(ENV_ID, num_envs=2, autoreset_mode=AutoresetMode.DISABLED, **FAST)
    with pytest.raises(ValueError, match=r"autoreset_mode must be one of .*got 'next'"):
        gym.make_vec(ENV_ID, num_envs=2, autoreset_mode="next", **FAST)


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(mode=st.one_of(st.none(), st.integers(), st.floats(), st.text(max_size=10), st.booleans(), st.lists(st.text())))
def test_fuzz_autoreset_mode(mode: object) -> None:
    """Anything but a mode offered is a ValueError that names autoreset_mode."""
    try:
        found = check_autoreset_mode(mode)
    except ValueError as exc:
        assert "autoreset_mode" in str(exc)
    else:
        assert found in AUTORESET_MODES and mode in (found.value, found.name)


def test_next_step_ignores_the_action_of_the_reset_step_and_masks_its_info() -> None:
    vec = gym.make_vec(ENV_ID, num_envs=2, episode_length_s=0.06, **FAST)  # 3 steps per episode
    vec.reset(seed=0)
    for _ in range(3):
        _, _, _, truncated, _ = vec.step(np.zeros((2, 12)))
    assert truncated.all()
    core = vec.unwrapped.core
    obs, reward, terminated, truncated, infos = vec.step(np.ones((2, 12)))  # ignored: the envs are reset
    assert reward.tolist() == [0.0, 0.0] and not terminated.any() and not truncated.any()
    assert core.episode_step.tolist() == [0, 0] and core.last_action.tolist() == np.zeros((2, 12)).tolist()
    np.testing.assert_array_equal(obs, core.observe(np.arange(2)))  # the reset observation (no noise: no draw)
    assert not infos["_margin"].any() and not infos["_termination_tilt"].any()
    assert np.all(infos["lambda"] == 0.0)
    obs, reward, _, _, infos = vec.step(np.zeros((2, 12)))
    assert infos["_margin"].all() and core.episode_step.tolist() == [1, 1] and np.all(reward != 0.0)
    vec.close()


# ---------------------------------------------------------------------------------------------------------------------
# get_attr, set_attr, call
# ---------------------------------------------------------------------------------------------------------------------
def test_get_attr_gives_one_value_per_environment() -> None:
    noisy = RandomizationConfig(friction=(0.4, 1.0), added_base_mass=(-1.0, 1.0))
    vec = gym.make_vec(ENV_ID, num_envs=3, randomization=noisy, margin_weight=0.4, seed=1, **FAST)
    vec.reset(seed=2)
    core = vec.unwrapped.core
    friction = vec.get_attr("friction")
    assert len(friction) == 3 and list(friction) == core.mu.tolist() and len(set(friction)) == 3
    assert list(vec.get_attr("added_base_mass")) == core._added_mass.tolist()
    commands = vec.get_attr("command")
    np.testing.assert_array_equal(np.stack(commands), core.command)
    commands[0][0] = 99.0  # copies, not views
    assert core.command[0, 0] != 99.0
    assert vec.get_attr("margin_weight") == (0.4, 0.4, 0.4)
    assert vec.get_attr("reward_params") == (RewardParams(),) * 3
    assert vec.get_attr("observation_space") == (vec.single_observation_space,) * 3
    assert vec.get_attr("render_mode") == (None, None, None) and vec.get_attr("dt") == (0.02,) * 3
    with pytest.raises(AttributeError, match=r"no attribute 'frictoin'.*per-environment attributes: command"):
        vec.get_attr("frictoin")
    vec.close()


def test_set_attr_sets_commands_per_environment_and_shared_config_fields() -> None:
    vec = gym.make_vec(ENV_ID, num_envs=2, **FAST)
    vec.reset(seed=0)
    vec.set_attr("command", [np.array([0.3, 0.0, 0.0]), np.array([1.0, 0.1, -0.2])])
    np.testing.assert_array_equal(vec.unwrapped.core.command, [[0.3, 0.0, 0.0], [1.0, 0.1, -0.2]])
    vec.set_attr("command", np.array([0.5, 0.0, 0.0]))  # not a list: the same value for every environment
    np.testing.assert_array_equal(vec.unwrapped.core.command, [[0.5, 0.0, 0.0]] * 2)
    obs = vec.step(np.zeros((2, 12)))[0]
    np.testing.assert_allclose(obs[:, 9:12], [[1.0, 0.0, 0.0]] * 2)  # the command in the observation (scale 2)

    vec.set_attr("reward_params", {"alive_bonus": 0.25})
    vec.set_attr("margin_weight", [0.0, 0.0])
    config = vec.unwrapped.core.config
    assert config is vec.unwrapped.config and config.reward_params.alive_bonus == 0.25 and config.margin_weight == 0
    info = vec.step(np.zeros((2, 12)))[4]
    np.testing.assert_array_equal(info["reward_alive"], [0.25, 0.25])

    with pytest.raises(ValueError, match="share one EnvConfig"):
        vec.set_attr("margin_weight", [0.1, 0.2])
    with pytest.raises(ValueError, match=r"Got `3` values for 2 environments"):
        vec.set_attr("margin_weight", [0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match="robot cannot change in a running environment"):
        vec.set_attr("robot", "anymal_c")
    with pytest.raises(ValueError, match=r"randomization.added_base_mass cannot change"):
        vec.set_attr("randomization", RandomizationConfig(added_base_mass=(0.0, 1.0)))
    with pytest.raises(ValueError, match=r"EnvConfig.margin_weight must be a finite number >= 0"):
        vec.set_attr("margin_weight", -1.0)
    with pytest.raises(TypeError, match=r"unknown key\(s\) \['bonus'\]"):
        vec.set_attr("reward_params", {"bonus": 1.0})
    with pytest.raises(ValueError, match="command values must be 3 finite numbers"):
        vec.set_attr("command", [np.array([0.1, 0.2]), np.array([np.nan, 0, 0])])
    with pytest.raises(AttributeError, match=r"'episode_step' cannot be set; settable: command"):
        vec.set_attr("episode_step", [0, 0])
    assert vec.unwrapped.config.margin_weight == 0  # nothing changed by the refused calls
    vec.close()


VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-5, 5),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=4),
    st.lists(st.floats(-2, 2), max_size=4).map(np.array),
    st.dictionaries(st.sampled_from(["alive_bonus", "knee_clearance", "gain"]), st.floats(-1, 1), max_size=2),
)


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(
    name=st.sampled_from(["command", "margin_weight", "reward_params", "robot", "episode_step", "nonsense"]),
    values=st.one_of(VALUES, st.lists(VALUES, min_size=1, max_size=3), st.tuples(VALUES, VALUES)),
)
def test_fuzz_set_attr(vector_env: gym.vector.VectorEnv, name: str, values: object) -> None:
    """Whatever is set: accepted, or a clear error that names the attribute."""
    try:
        vector_env.set_attr(name, values)
    except (TypeError, ValueError, AttributeError) as exc:
        assert name in str(exc), f"{type(exc).__name__}: {exc}"
    else:
        assert name in ("command", "margin_weight", "reward_params", "robot")
    assert np.all(np.isfinite(vector_env.unwrapped.core.command))
    vector_env.step(np.zeros((2, 12)))  # the env still steps after any of them


@pytest.fixture(scope="module")
def vector_env() -> gym.vector.VectorEnv:
    vec = gym.make_vec(ENV_ID, num_envs=2, **FAST)
    vec.reset(seed=0)
    return vec


def test_call_reads_attributes_and_renders_per_environment() -> None:
    vec = gym.make_vec(ENV_ID, num_envs=2, **FAST)
    vec.reset(seed=0)
    assert vec.call("margin_weight") == (1.0, 1.0)
    assert vec.call("render") == (None, None)  # no render mode: like SyncVectorEnv over envs that render nothing
    with pytest.raises(AttributeError, match=r"call\('reset'\) would reset each environment on its own"):
        vec.call("reset")
    with pytest.raises(TypeError, match="is an attribute, not a method"):
        vec.call("margin_weight", 1)
    vec.close()


# ---------------------------------------------------------------------------------------------------------------------
# seeds: Gymnasium's error types
# ---------------------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("seed", "error"), [(-1, SeedError), (1.5, SeedTypeError), ("3", SeedTypeError)])
def test_bad_seeds_raise_gymnasiums_error_type(seed: object, error: type) -> None:
    single = gym.make(ENV_ID, **FAST)
    vec = gym.make_vec(ENV_ID, num_envs=2, **FAST)
    for reset in (single.reset, vec.reset):
        with pytest.raises(gym.error.Error, match="seed must be an int >= 0"):
            reset(seed=seed)
        with pytest.raises(error):
            reset(seed=seed)
    with pytest.raises(gym.error.Error):  # what Gymnasium itself raises for the same seed
        gym.utils.seeding.np_random(seed)
    with pytest.raises(error, match="seed must be"):
        gym.make_vec(ENV_ID, num_envs=2, seed=seed, **FAST)


# ---------------------------------------------------------------------------------------------------------------------
# stock wrapper stacks
# ---------------------------------------------------------------------------------------------------------------------
def test_cleanrl_wrapper_stack_runs_with_episode_ends() -> None:
    """CleanRL's continuous-control stack on the native vector env (its wrappers need NEXT_STEP, the default)."""
    from gymnasium.wrappers import vector as vw

    envs = gym.make_vec(ENV_ID, num_envs=4, episode_length_s=0.5, **FAST)  # 25-step episodes
    envs = vw.RecordEpisodeStatistics(envs)
    envs = vw.ClipAction(envs)
    envs = vw.NormalizeObservation(envs)
    envs = vw.TransformObservation(envs, lambda obs: np.clip(obs, -10, 10))
    envs = vw.NormalizeReward(envs, gamma=0.99)
    envs = vw.TransformReward(envs, lambda reward: np.clip(reward, -10, 10))
    obs, _ = envs.reset(seed=1)
    rng = np.random.default_rng(0)
    episodes = []
    for _ in range(300):
        obs, reward, terminated, truncated, infos = envs.step(rng.uniform(-2, 2, (4, 12)))
        assert obs.shape == (4, 48) and np.all(np.isfinite(obs)) and np.all(np.abs(obs) <= 10)
        assert np.all(np.isfinite(reward))
        if "episode" in infos:
            done = infos["_episode"]
            assert np.array_equal(done, terminated | truncated)
            episodes += infos["episode"]["l"][done].tolist()
    assert len(episodes) >= 40 and max(episodes) == 25 and min(episodes) >= 1
    assert envs.unwrapped.get_attr("margin_weight") == (1.0,) * 4
    envs.close()


def test_skrl_gymnasium_wrapper_drives_the_native_vector_env() -> None:
    torch = pytest.importorskip("torch")
    wrappers = pytest.importorskip("skrl.envs.wrappers.torch")
    envs = wrappers.wrap_env(gym.make_vec(ENV_ID, num_envs=3, episode_length_s=0.2, **FAST), wrapper="gymnasium")
    assert envs.num_envs == 3 and envs.observation_space.shape == (48,) and envs.action_space.shape == (12,)
    obs, _ = envs.reset()
    assert tuple(obs.shape) == (3, 48)
    ends = 0
    for _ in range(30):
        obs, reward, terminated, truncated, _ = envs.step(torch.zeros(3, 12))
        assert tuple(obs.shape) == (3, 48) and tuple(reward.shape) == (3, 1) and torch.isfinite(reward).all()
        ends += int((terminated | truncated).sum())
    assert ends >= 3  # 10-step episodes: each environment ended at least once
    assert envs.render() == (None, None, None)  # skrl renders through call("render")
    envs.close()
