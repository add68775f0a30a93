"""What the -v1 ids changed: named termination causes, the reward-parameter mapping (and the one translation of
stored v0 configs), the ids and the retired -v0 ones, the robot names module and the physics seam."""

from __future__ import annotations

import json
import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import margin_rl  # noqa: F401 - registers the ids
from margin_rl.envs import anymal as anymal_module
from margin_rl.envs.config import (
    LEGACY_FIELDS,
    EnvConfig,
    RandomizationConfig,
    RewardParams,
    TerminationConfig,
    upgrade_stored_env_config,
)
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.terminations import CAUSE_NAMES, INFO_KEYS, TERMINATION_CAUSES, any_cause, termination_causes
from margin_rl.registration import ANYMAL_ENV_IDS, LEGACY_ANYMAL_IDS, current_env_id
from margin_rl.robot import LEGS, load_robot
from margin_rl.robot import mjcf_names as names

NO_NOISE = RandomizationConfig(reset_joint_noise=0.0, reset_velocity_noise=0.0)


# ---------------------------------------------------------------------------------------------------------------------
# termination causes
# ---------------------------------------------------------------------------------------------------------------------
def test_the_causes_are_declared_once_with_their_info_keys() -> None:
    assert CAUSE_NAMES == ("base_contact", "thigh_contact", "base_height", "tilt", "diverged")
    assert tuple(f"termination_{name}" for name in CAUSE_NAMES) == INFO_KEYS
    assert all(c.description for c in TERMINATION_CAUSES)


def _inputs(n: int = 1, **changes: np.ndarray) -> dict[str, np.ndarray]:
    inputs = {
        "base_contact": np.zeros(n, dtype=bool),
        "thigh_contacts": np.zeros((n, 4), dtype=bool),
        "base_height": np.full(n, 0.5),
        "tilt_cos": np.ones(n),
        "diverged": np.zeros(n, dtype=bool),
    }
    return {**inputs, **changes}


@pytest.mark.parametrize(
    ("cause", "changes"),
    [
        ("base_contact", {"base_contact": np.array([True])}),
        ("thigh_contact", {"thigh_contacts": np.array([[False, False, True, False]])}),
        ("base_height", {"base_height": np.array([0.2])}),
        ("tilt", {"tilt_cos": np.array([math.cos(1.2)])}),
        ("diverged", {"diverged": np.array([True])}),
    ],
)
def test_each_cause_is_computed_on_its_own(cause: str, changes: dict[str, np.ndarray]) -> None:
    causes = termination_causes(_inputs(**changes), TerminationConfig())
    assert [name for name, flags in causes.items() if flags[0]] == [cause]
    assert any_cause(causes).tolist() == [True]
    assert any_cause(termination_causes(_inputs(), TerminationConfig())).tolist() == [False]


def test_a_diverged_environment_reports_only_diverged() -> None:
    """Its state was zeroed for the bookkeeping: height 0 and tilt cos 0 would otherwise read as causes."""
    inputs = _inputs(2, base_height=np.zeros(2), tilt_cos=np.zeros(2), diverged=np.array([True, False]))
    causes = termination_causes(inputs, TerminationConfig())
    assert {name: flags.tolist() for name, flags in causes.items()} == {
        "base_contact": [False, False],
        "thigh_contact": [False, False],
        "base_height": [False, True],
        "tilt": [False, True],
        "diverged": [True, False],
    }


def test_step_info_reports_every_cause_and_their_or_is_terminated() -> None:
    core = AnymalCore(EnvConfig(robot="anymal_b", margin="none", randomization=NO_NOISE), 4, seed=0)
    core.reset()
    quarter = np.array([math.cos(0.65), math.sin(0.65), 0.0, 0.0])  # rolled by 1.3 rad
    core.physics.qpos[1, names.BASE_QUATERNION_QPOS] = quarter
    core.physics.qpos[1, 2] += 0.3  # tilted but high: tilt only
    core.physics.qpos[2, 2] = 0.15  # too low
    core.physics.forward()
    core.physics.qvel[3, :] = np.nan  # diverged (written after the forward pass, which would reset it)
    out = core.step(np.zeros((4, 12)))
    flags = {name: out.info[f"termination_{name}"] for name in CAUSE_NAMES}
    assert all(v.dtype == np.float64 and v.shape == (4,) for v in flags.values())
    assert [flags[name][0] for name in CAUSE_NAMES] == [0.0] * 5  # standing
    assert flags["tilt"][1] == 1.0 and flags["base_contact"][1] == 0.0 and flags["diverged"][1] == 0.0
    assert flags["base_height"][2] == 1.0
    assert [flags[name][3] for name in CAUSE_NAMES] == [0.0, 0.0, 0.0, 0.0, 1.0]
    union = np.logical_or.reduce([flags[name] > 0 for name in CAUSE_NAMES])
    np.testing.assert_array_equal(out.terminated, union)
    np.testing.assert_array_equal(out.info["fell"], (out.terminated & (flags["diverged"] == 0)).astype(float))
    np.testing.assert_array_equal(out.info["diverged"], flags["diverged"])


def test_training_metrics_log_the_fraction_of_episodes_each_cause_ended() -> None:
    from margin_rl.train.metrics import EpisodeStatistics, split_episodes, summarize, tensorboard_tags

    core = AnymalCore(EnvConfig(robot="anymal_b", margin="none", randomization=NO_NOISE), 2, seed=0, autoreset=False)
    core.reset()
    core.physics.qpos[0, 2] = 0.15
    core.physics.forward()
    stats = EpisodeStatistics(2, core.dt)
    out = core.step(np.zeros((2, 12)))
    finished = stats.update(out.reward, out.info, out.terminated, np.array([False, True]))
    assert finished["termination/base_height"].tolist() == [1.0, 0.0]  # env 1 timed out
    assert finished["termination/tilt"].tolist() == [0.0, 0.0]
    tags = tensorboard_tags(finished)
    for name in CAUSE_NAMES:
        assert f"Episode_Termination/{name}" in tags
    np.testing.assert_array_equal(tags["Episode_Termination/diverged"], finished["diverged"])
    assert summarize(split_episodes(finished))["termination/base_height"]["mean"] == 0.5  # fraction of episodes


# ---------------------------------------------------------------------------------------------------------------------
# reward parameters: one mapping
# ---------------------------------------------------------------------------------------------------------------------
def test_reward_params_is_one_checked_mapping() -> None:
    params = RewardParams(alive_bonus=0.1)
    assert dict(params) == {
        "alive_bonus": 0.1,
        "knee_clearance": 0.0,
        "knee_clearance_height": 0.2,
        "base_height": 0.0,
        "base_height_fraction": 0.9,
        "termination_penalty": 0.0,
        "yaw_tracking": 0.0,
        "base_acceleration": 0.0,
        "logistic_gain": 8.0,
    }
    assert params["alive_bonus"] == params.alive_bonus == 0.1 and len(params) == 9
    with pytest.raises(KeyError, match="the reward parameters are alive_bonus"):
        params["bonus"]
    assert EnvConfig(reward_params={"alive_bonus": 0.1}).reward_params == params
    # every v0 top-level reward field lives in the mapping (keys added since v1 never were top-level)
    assert set(LEGACY_FIELDS) <= set(RewardParams.keys_known())


def test_keyword_use_changes_only_the_named_keys() -> None:
    base = EnvConfig(reward_params={"knee_clearance": 5.0})
    changed = base.replace(reward_params={"alive_bonus": 0.1})
    assert changed.reward_params == RewardParams(alive_bonus=0.1, knee_clearance=5.0)
    env = gym.make("margin_rl/AnymalB-v1", config=base, reward_params={"alive_bonus": 0.1}, margin="none")
    assert env.unwrapped.config.reward_params == RewardParams(alive_bonus=0.1, knee_clearance=5.0)
    weights = env.unwrapped.config.reward_weights
    assert weights["alive"] == 0.1 and weights["knee_clearance"] == -5.0


@pytest.mark.parametrize("legacy", sorted(LEGACY_FIELDS))
def test_a_v0_keyword_is_refused_with_the_v1_spelling(legacy: str) -> None:
    message = rf"unexpected keyword argument '{legacy}'.*{legacy} is now reward_params=\{{'{legacy}': \.\.\.\}}"
    with pytest.raises(TypeError, match=message + r".*--env-option reward_params\." + legacy):
        gym.make("margin_rl/AnymalB-v1", margin="none", **{legacy: 0.1})


def test_stored_v0_configs_are_translated_in_one_place() -> None:
    from margin_rl.train.config import from_dict, to_dict

    stored = to_dict(EnvConfig(robot="anymal_b"))
    params = {key: value for key, value in stored.pop("reward_params").items() if key in LEGACY_FIELDS}
    v0 = {**stored, **params, "alive_bonus": 0.1, "knee_clearance": 5.0}  # the v0 layout: top-level fields
    upgraded = upgrade_stored_env_config(v0)
    assert "alive_bonus" not in upgraded and upgraded["reward_params"]["knee_clearance"] == 5.0
    config = from_dict(EnvConfig, v0, "env_config")
    assert config.reward_params == RewardParams(alive_bonus=0.1, knee_clearance=5.0)
    assert from_dict(EnvConfig, to_dict(config)) == config  # the v1 layout reads back unchanged
    with pytest.raises(ValueError, match=r"alive_bonus=0.1 \(EnvConfig v0\) and reward_params.alive_bonus=0.3"):
        upgrade_stored_env_config({**v0, "reward_params": {"alive_bonus": 0.3}})


def test_every_bundled_config_reads_back_with_its_reward_parameters() -> None:
    from margin_rl.train.artifacts.bundle import BUNDLE_ROOT
    from margin_rl.train.config import from_dict

    configs = sorted(BUNDLE_ROOT.glob("*/*/config.json"))
    assert len(configs) >= 10
    for path in configs:
        stored = json.loads(path.read_text())
        config = from_dict(EnvConfig, stored["env_config"], "env_config")
        stored_params = stored["env_config"].get("reward_params", {})  # v1 configs nest them, v0 ones did not
        for key in LEGACY_FIELDS:  # the oldest bundle predates knee_clearance: the default applies
            expected = stored_params.get(key, stored["env_config"].get(key, RewardParams()[key]))
            assert config.reward_params[key] == expected, (path, key)
        assert current_env_id(stored["env_id"]) in ANYMAL_ENV_IDS


def test_command_line_spelling_of_the_mapping() -> None:
    from margin_rl.train.config import apply_overrides, parse_assignments

    parsed = parse_assignments(
        ["reward_params.alive_bonus=0.1", 'reward_params={"knee_clearance": 5}', "margin_weight=0.2"], "--env-option"
    )
    assert parsed == {"reward_params": {"alive_bonus": 0.1, "knee_clearance": 5}, "margin_weight": 0.2}
    config = apply_overrides(EnvConfig(reward_params={"logistic_gain": 6.0}), parsed)
    assert config.reward_params == RewardParams(alive_bonus=0.1, knee_clearance=5, logistic_gain=6.0)
    with pytest.raises(TypeError, match=r"unknown option 'alive_bonus'.*reward_params.alive_bonus=VALUE"):
        apply_overrides(EnvConfig(), parse_assignments(["alive_bonus=0.1"], "--env-option"))
    with pytest.raises(ValueError, match=r"a dotted KEY must be FIELD\.ENTRY"):
        parse_assignments(["reward_params..x=1"], "--env-option")


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(data=st.dictionaries(st.sampled_from([*LEGACY_FIELDS, "margin_weight", "x"]), st.floats(0, 10), max_size=4))
def test_fuzz_stored_dicts_translate_to_the_same_config(data: dict[str, float]) -> None:
    """A v0 dict and its v1 form build the same config (or both fail, naming the field)."""
    legacy = {k: v for k, v in data.items() if k in LEGACY_FIELDS}
    other = {k: v for k, v in data.items() if k not in LEGACY_FIELDS}
    v0, v1 = {**other, **legacy}, ({**other, "reward_params": legacy} if legacy else other)
    assert upgrade_stored_env_config(v0) == upgrade_stored_env_config(v1) == v1
    assert upgrade_stored_env_config(v1) is not v1  # a new dict, the stored one untouched


# ---------------------------------------------------------------------------------------------------------------------
# ids
# ---------------------------------------------------------------------------------------------------------------------
def test_v1_ids_are_registered_and_v0_ids_raise_gymnasiums_deprecation() -> None:
    assert sorted(ANYMAL_ENV_IDS) == sorted(
        f"margin_rl/{name}-v1" for name in ("AnymalB", "AnymalC", "AnymalB-Rough", "AnymalC-Rough")
    )
    for old, new in LEGACY_ANYMAL_IDS.items():
        assert old.endswith("-v0") and old not in gym.registry and new in gym.registry
        with pytest.raises(gym.error.DeprecatedEnv, match=f"Please use `{new}` instead"):
            gym.make(old)
        assert current_env_id(old) == new and current_env_id(new) == new
    assert current_env_id("margin_rl/SLIPHopper-v0") == "margin_rl/SLIPHopper-v0"


def test_the_training_package_reads_a_stored_v0_id_as_v1() -> None:
    from margin_rl.train.environments import anymal_id, env_target, registered_spec

    assert registered_spec("margin_rl/AnymalC-Rough-v0").id == "margin_rl/AnymalC-Rough-v1"
    assert anymal_id("margin_rl/AnymalB-v0") == "margin_rl/AnymalB-v1"
    assert env_target("margin_rl/AnymalB-v0", {"margin": "none"}).env_id == "margin_rl/AnymalB-v1"


def test_the_version_history_names_both_versions() -> None:
    doc = anymal_module.__doc__
    history = doc.split("Version history:")[1]
    assert "* v1:" in history and "* v0:" in history and "DeprecatedEnv" in history


# ---------------------------------------------------------------------------------------------------------------------
# robot names, physics seam
# ---------------------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot_name", ["anymal_b", "anymal_c"])
def test_every_mjcf_name_is_in_both_robots(robot_name: str) -> None:
    robot = load_robot(robot_name)
    model = mujoco.MjModel.from_xml_path(str(robot.scene_path))
    model.body(names.BASE_BODY)
    model.geom(names.FLOOR_GEOM)
    model.key(names.STANDING_KEYFRAME)
    for sensor in (names.COM_SENSOR, names.COM_VELOCITY_SENSOR, names.BASE_CONTACT_SENSOR):
        model.sensor(sensor)
    for leg in LEGS:
        model.body(names.shank_body(leg))
        model.sensor(names.foot_contact_sensor(leg))
        model.sensor(names.thigh_contact_sensor(leg))
        model.geom(names.foot_geom(leg))
    # the state layout: a free joint first, then the 12 joints
    assert model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE and model.nq == 19 and model.nv == 18
    assert len(range(model.nq)[names.JOINT_QPOS]) == len(range(model.nv)[names.JOINT_QVEL]) == 12
    assert slice(0, 6) == names.BASE_QVEL
    with pytest.raises(ValueError, match="unknown leg 'LM'; the legs are LF, RF, LH, RH"):
        names.shank_body("LM")


def test_physics_state_refuses_a_batch_of_another_size() -> None:
    small = AnymalCore(EnvConfig(robot="anymal_b", margin="none"), 2)
    large = AnymalCore(EnvConfig(robot="anymal_b", margin="none"), 3)
    with pytest.raises(ValueError, match=r"physics state of shape \(2, \d+\) does not fit this batch \(3, \d+\)"):
        large.physics.set_state(small.physics.get_state())
