"""The state a step reads (envs.state_read) against MuJoCo's own data of the same simulation, and the episode state
kept at fixed addresses (views of two packed arrays) through pickling."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from margin_rl.envs.config import EnvConfig, RandomizationConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.episode_state import EPISODE_SPANS, EPISODE_STATE, episode_columns, episode_views
from margin_rl.envs.state_read import _field_split
from margin_rl.robot import mjcf_names as names

CONFIG = EnvConfig(robot="anymal_c", randomization=RandomizationConfig(push_interval_s=0.1, friction=(0.4, 1.0)))


def _walked_core(steps: int = 15) -> AnymalCore:
    core = AnymalCore(CONFIG, 4, seed=2)
    core.reset(seed=2)
    rng = np.random.default_rng(0)
    for _ in range(steps):
        core.step(rng.uniform(-1, 1, (4, 12)))
    return core


def test_the_state_read_is_mujocos_data_of_each_environment() -> None:
    core = _walked_core()
    state = core._read()
    model = core.model
    base = model.body(names.BASE_BODY).id
    for env in range(core.num_envs):
        data = core.render_data(env)  # MjData of the environment, forward kinematics done
        np.testing.assert_allclose(state.base_pos[env], data.qpos[:3], atol=1e-12)
        np.testing.assert_allclose(state.base_rot[env], data.xmat[base].reshape(3, 3), atol=1e-9)
        np.testing.assert_allclose(state.ang_vel_world[env], data.xmat[base].reshape(3, 3) @ data.qvel[3:6], atol=1e-9)
        np.testing.assert_allclose(state.joint_pos[env], data.qpos[7:], atol=1e-12)
        np.testing.assert_allclose(state.joint_vel[env], data.qvel[6:], atol=1e-12)
        np.testing.assert_allclose(state.com[env], data.subtree_com[base], atol=1e-9)
        feet = [data.site_xpos[model.site(f).id] for f in core.robot.foot_names]
        np.testing.assert_allclose(state.feet[env], feet, atol=1e-9)
        knees = [data.xpos[model.body(names.shank_body(leg)).id] for leg in core.robot.leg_names]
        np.testing.assert_allclose(state.knees[env], knees, atol=1e-9)
        found = [
            data.sensordata[model.sensor(names.foot_contact_sensor(leg)).adr[0]] > 0 for leg in core.robot.leg_names
        ]
        np.testing.assert_array_equal(state.contacts[env], found)


def test_a_read_of_some_environments_is_their_rows_and_finite_replaces_only_the_non_finite() -> None:
    core = _walked_core()
    every, some = core._read(), core._read(np.array([2, 0]))
    for field in ("base_pos", "base_rot", "com_vel", "feet", "contacts", "base_contact"):
        np.testing.assert_array_equal(getattr(some, field), getattr(every, field)[[2, 0]])
    core.physics.qvel[1, 4] = np.nan  # a diverged environment
    core.physics.qpos[1, 3] = np.inf  # its orientation too
    raw, finite = core._read(), core._read(finite=True)
    assert np.isnan(raw.ang_vel_body[1]).any() and np.isnan(raw.base_rot[1]).any()
    for field in ("base_pos", "base_rot", "ang_vel_body", "ang_vel_world", "joint_vel", "feet", "com_vel"):
        value = getattr(finite, field)
        assert np.isfinite(value).all(), field
        np.testing.assert_array_equal(value[[0, 2, 3]], getattr(raw, field)[[0, 2, 3]])
    # each non-finite entry 0, computed from the raw values as for any state
    np.testing.assert_array_equal(finite.base_rot[1], np.where(np.isfinite(raw.base_rot[1]), raw.base_rot[1], 0.0))


def test_the_episode_state_stays_views_of_its_packed_arrays_through_pickling() -> None:
    core = _walked_core(5)
    clone = pickle.loads(pickle.dumps(core))
    for copy_ in (core, clone):
        for name in (*EPISODE_STATE, "episode_step", "_push_steps_left"):
            packed = copy_._episode_floats if name in EPISODE_STATE else copy_._episode_counters
            assert np.shares_memory(getattr(copy_, name), packed), name
        np.testing.assert_array_equal(copy_.command, core.command)
    clone.command[...] = 0.25  # a write through the public name reaches the packed row a reset writes
    start = sum(width for name, width in EPISODE_STATE.items() if list(EPISODE_STATE).index(name) < 1)
    assert list(EPISODE_STATE)[1] == "command" and (clone._episode_floats[:, start : start + 3] == 0.25).all()
    np.testing.assert_array_equal(clone.mu, core.mu)
    actions = np.random.default_rng(1).uniform(-1, 1, (10, 4, 12))
    clone.command[...] = core.command
    for action in actions:
        np.testing.assert_array_equal(core.step(action).observation, clone.step(action).observation)


def test_the_read_splits_its_block_into_the_fields_and_the_columns_between() -> None:
    names_, widths = _field_split({"b": slice(5, 7), "a": slice(0, 3)}, 9)
    assert names_ == ("a", None, "b", None) and widths == (3, 2, 2, 2)
    with pytest.raises(ValueError, match="'b' \\(columns 2:4\\) overlaps another"):
        _field_split({"a": slice(0, 3), "b": slice(2, 4)}, 9)


def test_a_resets_episode_columns_are_its_values_in_place_and_zeros_elsewhere() -> None:
    start = {"command": np.full((2, 3), 0.5), "mu": np.full((2, 1), 0.8), "_prev_joint_vel": np.ones((2, 12))}
    floats = np.concatenate(episode_columns(start, 2, np, None), axis=1)
    assert floats.shape == (2, sum(EPISODE_STATE.values()))
    views = episode_views(floats, np.zeros((2, 2), dtype=np.int64))
    for name in EPISODE_STATE:
        expected = start[name][:, 0] if name == "mu" else start.get(name, 0.0)
        np.testing.assert_array_equal(views[name], expected, err_msg=name)


def test_each_span_of_the_episode_state_is_its_quantities_side_by_side_in_one_view() -> None:
    floats = np.arange(4 * sum(EPISODE_STATE.values()), dtype=np.float64).reshape(4, -1)
    views = episode_views(floats, np.zeros((4, 2), dtype=np.int64))
    order = list(EPISODE_STATE)
    for span, (first, last) in EPISODE_SPANS.items():
        quantities = order[order.index(first) : order.index(last) + 1]
        side_by_side = np.concatenate([views[name].reshape(4, -1) for name in quantities], axis=1)
        np.testing.assert_array_equal(views[span], side_by_side, err_msg=span)
        assert np.shares_memory(views[span], floats), span
