"""Bad input at the public surface of the ANYmal environments: every one gets a clear error naming what was wrong.

Property-based (hypothesis) fuzzing of configs, actions and seeds, plus the cases of the issue. The fuzz
counts every input tried, every clear error and every crash (an exception other than the documented ones,
or one whose message does not name the input); ``MARGIN_RL_FUZZ_EXAMPLES=N`` scales the examples per test
and ``MARGIN_RL_FUZZ_REPORT=path`` writes the counts as JSON (the command is in BENCHMARKS.md).
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import margin_rl  # noqa: F401 - registers the ids
from margin_rl.envs import anymal as anymal_module
from margin_rl.envs.anymal import AnymalEnv
from margin_rl.envs.config import (
    REWARD_PRESETS,
    CommandConfig,
    EnvConfig,
    RandomizationConfig,
    RewardParams,
    TerminationConfig,
)
from margin_rl.envs.margin_kinds import MARGIN_KINDS
from margin_rl.envs.terrain import TerrainConfig
from margin_rl.envs.vector import AnymalVectorEnv

EXAMPLES = int(os.environ.get("MARGIN_RL_FUZZ_EXAMPLES", "25"))
FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=True,  # the same inputs on every CI run
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
COUNTS = {"inputs": 0, "accepted": 0, "errors": 0, "crashes": 0}
CLEAR_ERRORS = (TypeError, ValueError, ResetNeeded, FloatingPointError)
README = Path(__file__).resolve().parents[2] / "README.md"


@pytest.fixture(scope="module", autouse=True)
def fuzz_report() -> Iterator[None]:
    yield
    path = os.environ.get("MARGIN_RL_FUZZ_REPORT")
    if path:
        Path(path).write_text(json.dumps({"examples_per_test": EXAMPLES, **COUNTS}, indent=2) + "\n")


def attempt(call: Callable[[], Any], must_name: str) -> Any:
    """Run ``call`` on one fuzz input: its result, or None after a clear error whose message names ``must_name``.

    Anything else (another exception type, or a message that does not say what was wrong) counts as a crash
    and fails the test.
    """
    COUNTS["inputs"] += 1
    try:
        result = call()
    except CLEAR_ERRORS as exc:
        if must_name not in str(exc):
            COUNTS["crashes"] += 1
            raise AssertionError(f"error does not name {must_name!r}: {type(exc).__name__}: {exc}") from exc
        COUNTS["errors"] += 1
        return None
    except Exception:
        COUNTS["crashes"] += 1
        raise
    COUNTS["accepted"] += 1
    return result


def assert_finite_or_flagged(observation: np.ndarray, reward: Any, info: dict[str, Any]) -> None:
    """No NaN reaches a reward or an observation without a flag (the surface raises for the rest)."""
    flagged = np.any(np.asarray(info.get("diverged", 0.0)) > 0)
    assert flagged or (np.all(np.isfinite(observation)) and np.all(np.isfinite(reward)))


# ---------------------------------------------------------------------------------------------------------------------
# the cases
# ---------------------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("value", "error", "message"),
    [
        (float("nan"), ValueError, r"EnvConfig.margin_weight must be a finite number >= 0 .*got nan"),
        (-0.5, ValueError, r"EnvConfig.margin_weight must be a finite number >= 0 .*got -0.5"),
        ("0.2", TypeError, r"EnvConfig.margin_weight must be .*got '0.2' \(str\); pass a number such as"),
        (True, TypeError, r"EnvConfig.margin_weight must be a finite number"),
    ],
)
def test_bad_margin_weight_is_refused_at_make(value: object, error: type, message: str) -> None:
    with pytest.raises(error, match=message):
        gym.make("margin_rl/AnymalB-v1", margin_weight=value)


@pytest.mark.parametrize(
    ("build", "error", "message"),
    [
        (lambda: EnvConfig(decimation=4.0), TypeError, r"EnvConfig.decimation must be an int >= 1"),
        (lambda: EnvConfig(decimation=0), ValueError, r"EnvConfig.decimation must be an int >= 1"),
        (lambda: EnvConfig(action_scale=float("inf")), ValueError, r"EnvConfig.action_scale must be a finite"),
        (lambda: EnvConfig(episode_length_s=0), ValueError, r"EnvConfig.episode_length_s must be .* > 0"),
        (
            lambda: EnvConfig(reward_params={"logistic_gain": -8.0}),
            ValueError,
            r"EnvConfig.reward_params: RewardParams.logistic_gain must be .* > 0",
        ),
        (lambda: RewardParams(alive_bonus=-0.1), ValueError, r"RewardParams.alive_bonus must be a finite number >= 0"),
        (
            lambda: EnvConfig(reward_params={"alive_bonsu": 0.1}),
            TypeError,
            r"EnvConfig.reward_params: unknown key\(s\) \['alive_bonsu'\]; the known keys are alive_bonus, "
            r"knee_clearance, knee_clearance_height, base_height, base_height_fraction, termination_penalty, "
            r"yaw_tracking, base_acceleration, logistic_gain",
        ),
        (
            lambda: EnvConfig(reward_params=0.1),
            TypeError,
            r"EnvConfig.reward_params must be a RewardParams.*pass a mapping such as reward_params=\{'alive_bonus'",
        ),
        (lambda: EnvConfig(acceleration_filter=1.0), ValueError, r"EnvConfig.acceleration_filter .* < 1"),
        (lambda: EnvConfig(robot="anymal_d"), ValueError, r"EnvConfig.robot must be one of \['anymal_b'"),
        (lambda: EnvConfig(terrain="hills"), ValueError, r"EnvConfig.terrain must be one of"),
        (lambda: EnvConfig(margin_weights=3), TypeError, r"EnvConfig.margin_weights must be None or a path"),
        (lambda: EnvConfig(privileged_observations="yes"), TypeError, r"privileged_observations must be True or"),
        (
            lambda: EnvConfig(randomization={"friction": (0.5, 1.0)}),
            TypeError,
            r"EnvConfig.randomization must be a RandomizationConfig.*pass randomization=RandomizationConfig\(\*\*",
        ),
        (lambda: RandomizationConfig(friction=(1.0, 0.5)), ValueError, r"friction must be a \(low, high\) pair"),
        (lambda: RandomizationConfig(friction=(-0.1, 0.5)), ValueError, r"friction .* low >= 0"),
        (lambda: RandomizationConfig(push_interval_s=0.0), ValueError, r"push_interval_s must be .* > 0"),
        (lambda: RandomizationConfig(observation_noise=-1), ValueError, r"observation_noise must be .* >= 0"),
        (lambda: RandomizationConfig(reset_joint_noise=10.0), ValueError, r"reset_joint_noise .* <= 3.14159"),
        (lambda: CommandConfig(forward_velocity=0.75), TypeError, r"CommandConfig.forward_velocity must be a \(low"),
        (lambda: TerminationConfig(max_tilt_rad=57.0), ValueError, r"TerminationConfig.max_tilt_rad .* <= 3.14159"),
        (
            lambda: EnvConfig(terrain_config=TerrainConfig(tile=5.0)),
            ValueError,
            r"TerrainConfig: size / tile must be a whole number",
        ),
        (
            lambda: EnvConfig(terrain_config=TerrainConfig(resolution=1e-4)),
            ValueError,
            r"heightfield, more than 4001 per side",
        ),
        (
            lambda: EnvConfig(terrain_config=TerrainConfig(max_height=0.4)),
            ValueError,
            r"TerrainConfig.max_height must be .* > 0.5",
        ),
    ],
)
def test_every_numeric_option_is_checked_with_the_field_named(
    build: Callable[[], object], error: type, message: str
) -> None:
    with pytest.raises(error, match=message):
        build()


def test_valid_configs_are_stored_unchanged() -> None:
    """Validation only rejects: lists (JSON round trips), ints and numpy numbers pass as given."""
    config = EnvConfig(margin_weight=1, decimation=np.int64(4), randomization=RandomizationConfig(friction=[0.4, 1.0]))
    assert config.margin_weight == 1 and type(config.margin_weight) is int
    assert config.randomization.friction == [0.4, 1.0]
    assert EnvConfig(margin_weight=np.float32(0.25)).margin_weight == np.float32(0.25)


@pytest.fixture(scope="module")
def single() -> AnymalEnv:
    return gym.make("margin_rl/AnymalB-v1", margin="none").unwrapped


@pytest.fixture(scope="module")
def batch() -> AnymalVectorEnv:
    return gym.make_vec("margin_rl/AnymalB-v1", num_envs=2, margin="none")


def test_step_before_reset_is_an_error() -> None:
    env = gym.make("margin_rl/AnymalB-v1", margin="none").unwrapped
    with pytest.raises(ResetNeeded, match=r"step\(\) was called before reset\(\)"):
        env.step(np.zeros(12))
    vec = gym.make_vec("margin_rl/AnymalB-v1", num_envs=2, margin="none")
    with pytest.raises(ResetNeeded, match=r"step\(\) was called before reset\(\)"):
        vec.step(np.zeros((2, 12)))


def test_wrong_action_shapes_name_the_expected_shape(single: AnymalEnv, batch: AnymalVectorEnv) -> None:
    single.reset(seed=0)
    batch.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(12,\) .*got shape \(11,\)"):
        single.step(np.zeros(11))
    with pytest.raises(ValueError, match=r"shape \(12,\) .*got shape \(1, 12\).*gymnasium.make_vec"):
        single.step(np.zeros((1, 12)))
    with pytest.raises(ValueError, match=r"shape \(2, 12\) .*got shape \(12,\).*num_envs=2"):
        batch.step(np.zeros(12))
    with pytest.raises(TypeError, match=r"got dtype <U"):
        single.step(["0.1"] * 12)
    with pytest.raises(ValueError, match=r"NaN or inf at \[\[3\]\]"):
        single.step(np.where(np.arange(12) == 3, np.inf, 0.0))


def test_clipping_policy_is_documented() -> None:
    assert "clipped" in AnymalEnv.__doc__ + anymal_module.__doc__
    section = README.read_text().split("## Environments (seed 000 §V-C)")[1].split("\n## ")[0]
    assert "clipped" in section and "step()` before `reset()`" in section


def test_every_margin_kind_is_documented() -> None:
    """The error for a bad ``margin`` names every kind, so the docs must describe every kind too."""
    section = README.read_text().split("## Environments (seed 000 §V-C)")[1].split("\n## ")[0]
    for kind in MARGIN_KINDS:
        assert f'margin="{kind}"' in section, kind
        assert f'``"{kind}"``' in anymal_module.__doc__, kind


def test_reset_options_are_refused_not_ignored(single: AnymalEnv) -> None:
    single.reset(options={})
    with pytest.raises(ValueError, match="takes no options"):
        single.reset(options={"margin_weight": 0.0})


def test_a_value_too_large_for_floats_raises_instead_of_returning_inf() -> None:
    env = gym.make("margin_rl/AnymalB-v1", margin="none", randomization=RandomizationConfig(observation_noise=1e41))
    with pytest.raises(FloatingPointError, match=r"observation is not finite.*observation_noise=1e"):
        env.reset(seed=0)


def test_the_core_itself_refuses_non_finite_outputs_for_every_adapter() -> None:
    """The check sits in AnymalCore, which the SB3 and rsl-rl adapters step directly."""
    from margin_rl.envs.config import EnvConfig
    from margin_rl.envs.core import AnymalCore

    noise = RandomizationConfig(observation_noise=1e41)  # float32 observations overflow to inf
    core = AnymalCore(EnvConfig(robot="anymal_b", margin="none", randomization=noise), 2)
    core.reset(seed=0)
    with pytest.raises(FloatingPointError, match=r"observation is not finite"):
        core.observe_all()
    with pytest.raises(FloatingPointError, match=r"observation is not finite"):
        core.step(np.zeros((2, 12)))


# ---------------------------------------------------------------------------------------------------------------------
# fuzzing
# ---------------------------------------------------------------------------------------------------------------------
ANYTHING = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
    st.tuples(st.floats(allow_nan=True), st.floats(allow_nan=True)),
    st.lists(st.floats(-10, 10), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)
NUMERIC_FIELDS: dict[type, list[str]] = {
    EnvConfig: [
        "decimation",
        "action_scale",
        "episode_length_s",
        "margin_weight",
        "reward_params",
        "acceleration_filter",
        "privileged_observations",
        "robot",
        "terrain",
        "reward_preset",
        "margin",
        "margin_weights",
        "command",
        "randomization",
        "termination",
        "terrain_config",
    ],
    RandomizationConfig: [
        "friction",
        "added_base_mass",
        "push_interval_s",
        "push_force",
        "push_duration_s",
        "observation_noise",
        "reset_joint_noise",
        "reset_velocity_noise",
    ],
    CommandConfig: ["forward_velocity", "lateral_velocity", "yaw_rate"],
    RewardParams: [
        "alive_bonus",
        "knee_clearance",
        "knee_clearance_height",
        "base_height",
        "base_height_fraction",
        "termination_penalty",
        "yaw_tracking",
        "logistic_gain",
    ],
    TerminationConfig: ["min_base_height", "max_tilt_rad"],
    TerrainConfig: ["size", "resolution", "tile", "step_height", "max_slope_deg", "pad", "base_level", "max_height"],
}
NUMBER_FIELDS = {
    "decimation", "action_scale", "episode_length_s", "margin_weight", "alive_bonus", "knee_clearance",
    "knee_clearance_height", "base_height", "base_height_fraction", "termination_penalty", "yaw_tracking",
    "logistic_gain", "acceleration_filter", "push_force", "push_duration_s", "observation_noise", "reset_joint_noise",
    "reset_velocity_noise", "min_base_height", "max_tilt_rad", "size", "resolution", "tile", "max_slope_deg",
    "pad", "base_level", "max_height",
}  # fmt: skip
FIELD_CHOICES = [(cls, name) for cls, names in NUMERIC_FIELDS.items() for name in names]


@FUZZ
@given(choice=st.sampled_from(FIELD_CHOICES), value=ANYTHING)
def test_fuzz_config_fields(choice: tuple[type, str], value: object) -> None:
    cls, name = choice
    nested = {TerrainConfig: "terrain_config", CommandConfig: "command", RandomizationConfig: "randomization"}
    nested[TerminationConfig], nested[RewardParams] = "termination", "reward_params"

    def build() -> object:
        config = cls(**{name: value})
        return config if cls is EnvConfig else getattr(EnvConfig(**{nested[cls]: config}), nested[cls])

    config = attempt(build, name)
    if config is not None and name == "reward_params" and isinstance(value, dict):
        assert config.reward_params == RewardParams.from_mapping(value)  # the one field a mapping is converted for
    elif config is not None:
        assert getattr(config, name) is value  # stored as given
        # What was accepted is a sane value: no NaN/inf, and no str, bool or dict where a number belongs.
        assert not (isinstance(value, float) and not math.isfinite(value)), (name, value)
        if name in NUMBER_FIELDS:
            assert not isinstance(value, (str, bool, dict, list, tuple)), (name, value)


@FUZZ
@given(params=st.dictionaries(st.sampled_from([*RewardParams.keys_known(), "alive", "gain", ""]), ANYTHING, max_size=3))
def test_fuzz_reward_params_mapping(params: dict[str, object]) -> None:
    """Any mapping given as reward_params: accepted with its keys' values, or an error naming the mapping."""
    config = attempt(lambda: EnvConfig(reward_params=params), "reward_params")
    if config is not None:
        assert set(params) <= set(RewardParams.keys_known())
        for key, value in params.items():
            assert config.reward_params[key] is value  # each value stored as given
        assert dict(config.reward_params) == {**dict(RewardParams()), **params}


@FUZZ
@given(
    margin_weight=st.floats(0, 1e308),
    alive_bonus=st.floats(0, 1e308),
    observation_noise=st.floats(0, 1e40),
    reset_velocity_noise=st.floats(0, 1e300),
    push_force=st.floats(0, 1e9),
    action_scale=st.floats(1e-6, 1e3),
    preset=st.sampled_from(sorted(REWARD_PRESETS)),
    seed=st.integers(0, 2**32),
)
def test_fuzz_valid_configs_never_return_nan(
    margin_weight: float,
    alive_bonus: float,
    observation_noise: float,
    reset_velocity_noise: float,
    push_force: float,
    action_scale: float,
    preset: str,
    seed: int,
) -> None:
    """Accepted settings, however extreme, give finite outputs, a divergence flag, or a clear error."""
    randomization = RandomizationConfig(
        observation_noise=observation_noise,
        reset_velocity_noise=reset_velocity_noise,
        push_force=push_force,
        push_interval_s=0.05,
    )
    env = gym.make(
        "margin_rl/AnymalB-v1",
        margin="none",
        margin_weight=margin_weight,
        reward_params={"alive_bonus": alive_bonus},
        action_scale=action_scale,
        reward_preset=preset,
        randomization=randomization,
    )
    if attempt(lambda: env.reset(seed=seed), "not finite") is None:
        return
    rng = np.random.default_rng(seed)
    for _ in range(3):
        out = attempt(lambda: env.step(rng.uniform(-2, 2, 12)), "not finite")
        if out is None:
            return
        observation, reward, terminated, truncated, info = out
        assert_finite_or_flagged(observation, reward, info)
        if terminated or truncated:
            return


SHAPES = st.lists(st.integers(0, 13), min_size=0, max_size=3).map(tuple)
DTYPES = st.sampled_from(["float64", "float32", "float16", "int64", "uint8", "bool", "complex128", "<U3", "object"])
VALUES = st.floats(allow_nan=True, allow_infinity=True, width=64)


@st.composite
def action_arrays(draw: st.DrawFn, valid_shape: tuple[int, ...]) -> object:
    shape = draw(st.one_of(st.just(valid_shape), SHAPES))
    dtype = draw(DTYPES)
    fill = draw(st.one_of(st.floats(-3, 3), VALUES))
    size = math.prod(shape)
    values = (
        np.full(size, fill) if draw(st.booleans()) else np.array(draw(st.lists(VALUES, min_size=size, max_size=size)))
    )
    with np.errstate(all="ignore"):
        array = values.reshape(shape).astype(dtype) if dtype != "<U3" else values.reshape(shape).astype(str)
    return array.tolist() if draw(st.booleans()) and array.dtype != object else array


@FUZZ
@given(data=st.data())
def test_fuzz_actions_single_env(single: AnymalEnv, data: st.DataObject) -> None:
    single.reset(seed=0)
    action = data.draw(action_arrays((12,)))
    out = attempt(lambda: single.step(action), "action")
    if out is not None:
        assert_finite_or_flagged(out[0], out[1], out[4])


@FUZZ
@given(data=st.data())
def test_fuzz_actions_batched_env(batch: AnymalVectorEnv, data: st.DataObject) -> None:
    batch.reset(seed=0)
    actions = data.draw(action_arrays((2, 12)))
    out = attempt(lambda: batch.step(actions), "action")
    if out is not None:
        assert_finite_or_flagged(out[0], out[1], out[4])


SEEDS = st.one_of(
    ANYTHING,
    st.integers(0, 2**128),
    st.integers(0, 2**31).map(np.int64),
    st.lists(st.one_of(st.none(), st.integers(-3, 2**40)), min_size=0, max_size=4),
)


@FUZZ
@given(seed=SEEDS)
def test_fuzz_seeds(single: AnymalEnv, batch: AnymalVectorEnv, seed: object) -> None:
    for env in (single, batch):
        out = attempt(lambda env=env: env.reset(seed=seed), "seed")
        if out is not None:
            assert np.all(np.isfinite(out[0])) and re.match(r"^\{\}$", json.dumps(out[1]))
