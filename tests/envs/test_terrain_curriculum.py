"""The terrain curriculum: rows of rising difficulty, spawning on an environment's level, the level rule at episode
ends (promotion, demotion, the top level reassigned), its bad inputs, its log tag, and the fixed-difficulty terrains
that evaluations use."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.envs.config import CommandConfig, EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.terrain import (
    DEMOTION_COMMAND_FRACTION,
    PROMOTION_TILE_FRACTION,
    TerrainConfig,
    at_difficulty,
    next_levels,
    rough_terrain,
)
from margin_rl.robot import mjcf_names as names
from margin_rl.train.metrics import step_tags
from tests.envs.test_terrain import _largest_neighbour_jump

# 4 levels x 2 tiles of 4 m, no border: a 321 x 161 grid that builds in milliseconds.
CURRICULUM = TerrainConfig(size=8.0, tile=4.0, border=0.0, curriculum_levels=4, initial_max_level=1)
PER_TILE = round(CURRICULUM.tile / CURRICULUM.resolution)


def _row(heights: np.ndarray, level: int) -> np.ndarray:
    return heights[level * PER_TILE : (level + 1) * PER_TILE + 1]


def test_rows_rise_in_difficulty_from_flat_to_the_full_scale() -> None:
    """Row 0 is flat; row l's steps are at most l / (L - 1) of the full step height; the top row reaches more than
    half of it; spawn points are the pads of each row, row-major."""
    terrain = rough_terrain(CURRICULUM, seed=2)
    assert terrain.heights.shape == (4 * PER_TILE + 1, 2 * PER_TILE + 1) and terrain.levels == 4
    high = CURRICULUM.step_height[1]
    assert np.ptp(_row(terrain.heights, 0)) == 0.0
    for level in range(1, 4):
        assert _largest_neighbour_jump(_row(terrain.heights, level)) <= high * level / 3 + 1e-9
    assert _largest_neighbour_jump(_row(terrain.heights, 3)) > high / 2
    spawn = terrain.spawn_points.reshape(4, 2, 3)
    centres_y = terrain.origin[1] + (np.arange(4) + 0.5) * CURRICULUM.tile
    np.testing.assert_allclose(spawn[:, :, 1], np.repeat(centres_y[:, None], 2, axis=1))
    np.testing.assert_allclose(spawn[..., 2], terrain.height(spawn[..., :2].reshape(-1, 2)).reshape(4, 2))


def test_a_non_curriculum_terrain_is_the_one_it_always_was() -> None:
    """curriculum_levels = 0 keeps the square of random tiles (seeded draws unchanged by the curriculum's code)."""
    square = TerrainConfig(size=12.0, tile=4.0, border=0.0)
    terrain = rough_terrain(square, seed=5)
    assert terrain.heights.shape == (241, 241) and terrain.levels == 0 and len(terrain.spawn_points) == 9


def test_heights_on_a_curriculum_are_the_surface_mujoco_collides_with() -> None:
    """On the rectangular curriculum grid too, Terrain.height equals MuJoCo's ray casts onto the heightfield."""
    import mujoco

    from margin_rl.envs.scene import build_model
    from margin_rl.robot import load_robot

    terrain = rough_terrain(CURRICULUM, seed=3)
    model = build_model(load_robot("anymal_c"), terrain, CURRICULUM)
    data = mujoco.MjData(model)
    data.qpos[:3] = [0.0, 0.0, 10.0]
    mujoco.mj_forward(model, data)
    rows, columns = terrain.heights.shape
    half_x, half_y = (columns - 1) * terrain.resolution / 2, (rows - 1) * terrain.resolution / 2
    rng = np.random.default_rng(0)
    points = np.column_stack(
        [rng.uniform(-half_x + 0.01, half_x - 0.01, 800), rng.uniform(-half_y + 0.01, half_y - 0.01, 800)]
    )
    hit = np.zeros(1, dtype=np.int32)
    ray = np.array(
        [5.0 - mujoco.mj_ray(model, data, np.array([x, y, 5.0]), np.array([0.0, 0.0, -1.0]), None, 1, -1, hit)
         for x, y in points]
    )  # fmt: skip
    np.testing.assert_allclose(terrain.height(points), ray, atol=CURRICULUM.max_height * 2**-22)


def test_difficulty_scales_the_steps_and_the_incline() -> None:
    full = TerrainConfig()
    assert at_difficulty(full, 1.0) == full
    half = at_difficulty(full, 0.5)
    assert half.step_height == (0.03, 0.09) and half.max_slope_deg == 7.5
    flat = rough_terrain(dataclasses.replace(at_difficulty(full, 0.0), size=8.0, border=0.0), seed=1)
    assert np.ptp(flat.heights) == 0.0
    for bad in (-0.1, 1.5, float("nan"), "hard"):
        with pytest.raises(ValueError, match="difficulty must be a number in"):
            at_difficulty(full, bad)  # type: ignore[arg-type]


def test_the_level_rule_by_hand() -> None:
    """Tile 4 m: promoted beyond 2 m; else demoted below half the commanded distance; the top reassigned."""
    levels = np.array([0, 1, 1, 2, 3, 0])
    walked = np.array([2.5, 2.5, 1.0, 0.5, 3.0, 0.1])
    commanded = np.array([15.0, 15.0, 1.5, 15.0, 15.0, 15.0])
    random_level = np.array([9, 9, 9, 9, 1, 9])
    moved = next_levels(levels, walked, commanded, tile=4.0, top=3, random_level=random_level)
    np.testing.assert_array_equal(moved, [1, 2, 1, 1, 1, 0])
    assert PROMOTION_TILE_FRACTION == 0.5 and DEMOTION_COMMAND_FRACTION == 0.5  # the rule the docs state


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_levels_stay_in_range_and_move_by_one_on_both_array_kinds(data: st.DataObject) -> None:
    n, top = data.draw(st.integers(1, 20)), data.draw(st.integers(1, 9))
    ints, dist = st.integers(0, top), st.floats(0.0, 30.0)
    levels = np.array(data.draw(st.lists(ints, min_size=n, max_size=n)))
    walked = np.array(data.draw(st.lists(dist, min_size=n, max_size=n)))
    commanded = np.array(data.draw(st.lists(dist, min_size=n, max_size=n)))
    random_level = np.array(data.draw(st.lists(ints, min_size=n, max_size=n)))
    moved = next_levels(levels, walked, commanded, 4.0, top, random_level)
    assert np.all((moved >= 0) & (moved <= top))
    reassigned = (levels == top) & (walked > 2.0)
    assert np.all(np.abs(moved - levels)[~reassigned] <= 1)
    np.testing.assert_array_equal(moved[reassigned], random_level[reassigned])
    on_torch = next_levels(*(torch.as_tensor(a) for a in (levels, walked, commanded)), 4.0, top,
                           torch.as_tensor(random_level))  # fmt: skip
    np.testing.assert_array_equal(on_torch.numpy(), moved)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"curriculum_levels": 1}, "curriculum_levels must be 0"),
        ({"curriculum_levels": -2}, "curriculum_levels must be 0"),
        ({"curriculum_levels": 2.0}, "curriculum_levels must be 0"),
        ({"curriculum_levels": True}, "curriculum_levels must be 0"),
        ({"initial_max_level": 4}, "initial_max_level must be a whole level"),
        ({"initial_max_level": -1}, "initial_max_level must be a whole level"),
        ({"curriculum_levels": 200, "resolution": 0.05}, "heightfield, more than"),
    ],
)
def test_bad_curriculum_settings_name_the_field(change: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        EnvConfig(terrain="rough", terrain_config=dataclasses.replace(CURRICULUM, **change))


def _core(num_envs: int = 6) -> AnymalCore:
    config = EnvConfig(
        robot="anymal_c",
        terrain="rough",
        terrain_config=CURRICULUM,
        margin="none",
        command=CommandConfig(forward_velocity=(0.5, 0.5), lateral_velocity=(0.0, 0.0), yaw_rate=(0.0, 0.0)),
    )
    core = AnymalCore(config, num_envs=num_envs, seed=4)
    core.reset(seed=4)
    return core


def _row_of(core: AnymalCore) -> np.ndarray:
    """The curriculum row under each environment's base."""
    y = core.physics.qpos[:, names.BASE_POSITION_QPOS][:, 1]
    return np.floor((y - core.terrain.origin[1]) / CURRICULUM.tile).astype(int)


def test_environments_spawn_on_their_level_and_move_at_episode_ends() -> None:
    core = _core()
    assert set(core.terrain_level.tolist()) <= {0, 1}  # initial levels 0..initial_max_level
    np.testing.assert_array_equal(_row_of(core), core.terrain_level)
    core.terrain_level[:] = [0, 1, 2, 2, 3, 3]
    core.reset()  # no episode has run: nobody moves
    np.testing.assert_array_equal(core.terrain_level, [0, 1, 2, 2, 3, 3])
    np.testing.assert_array_equal(_row_of(core), core.terrain_level)
    for _ in range(50):  # 1 s at a commanded 0.5 m/s: 0.5 m commanded
        core.step(np.zeros((6, 12)))
    # Environments 0, 2, 4 carried 3 m forwards (promoted; 4 from the top: a random level); 1, 3, 5 stay (0.5 m
    # commanded, walked less than half: demoted).
    qpos = core.physics.qpos
    qpos[[0, 2, 4], 0] += 3.0
    core.reset()
    assert core.terrain_level[0] == 1 and core.terrain_level[2] == 3
    assert core.terrain_level[1] == 0 and core.terrain_level[3] == 1 and core.terrain_level[5] == 2
    assert 0 <= core.terrain_level[4] <= 3
    np.testing.assert_array_equal(_row_of(core), core.terrain_level)


def test_the_level_is_in_info_in_the_log_and_survives_pickling() -> None:
    core = _core(3)
    core.terrain_level[:] = [0, 2, 3]
    out = core.step(np.zeros((3, 12)))
    np.testing.assert_array_equal(out.info["terrain_level"], [0.0, 2.0, 3.0])
    assert step_tags(out.info)["Curriculum/terrain_level_mean"] == pytest.approx(5 / 3)
    copy = pickle.loads(pickle.dumps(core))
    np.testing.assert_array_equal(copy.terrain_level, core.terrain_level)
    np.testing.assert_array_equal(copy._spawn_xy, core._spawn_xy)
    flat = AnymalCore(EnvConfig(robot="anymal_c", margin="none"), num_envs=2, seed=0)
    flat.reset(seed=0)
    info = flat.step(np.zeros((2, 12))).info
    assert "terrain_level" not in info and "Curriculum/terrain_level_mean" not in step_tags(info)


def test_restart_on_levels_puts_walked_environments_back_on_their_rows() -> None:
    """A resumed training's curriculum: environments that have walked part of an episode start afresh on the rows
    they are given (none promoted or demoted for the cut episode), from any array kind."""
    core = _core()
    for _ in range(20):
        core.step(np.zeros((6, 12)))
    core.restart_on_levels(torch.tensor([3, 2, 1, 0, 3, 2]))
    np.testing.assert_array_equal(core.terrain_level, [3, 2, 1, 0, 3, 2])
    np.testing.assert_array_equal(_row_of(core), core.terrain_level)
    assert not core.episode_step.any()


@pytest.mark.parametrize(
    ("levels", "message"),
    [
        ([0, 1, 2], r"expected 6 integers .*--num-envs"),
        ([0.0, 1.0, 2.0, 0.0, 1.0, 2.0], r"expected 6 integers .*float64"),
        ([0, 1, 2, 3, 4, 0], r"rows must lie in 0\.\.3 .*got 0\.\.4"),
        ([-1, 1, 2, 3, 0, 0], r"rows must lie in 0\.\.3 .*got -1\.\.3"),
    ],
)
def test_restart_on_levels_names_what_is_wrong(levels: list, message: str) -> None:
    core = _core()
    before = core.terrain_level.copy()
    with pytest.raises(ValueError, match=message):
        core.restart_on_levels(levels)
    np.testing.assert_array_equal(core.terrain_level, before)  # nothing changed
    flat = AnymalCore(EnvConfig(robot="anymal_c", margin="none"), num_envs=2, seed=0)
    with pytest.raises(ValueError, match=r"needs a terrain curriculum .*curriculum_levels >= 2"):
        flat.restart_on_levels([0, 0])
