"""The rough terrain: walkable everywhere (no jump above one step), flat pads at the spawn points, deterministic."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.envs.terrain import TILE_TYPES, Terrain, TerrainConfig, rough_terrain

# 3 x 3 tiles of 4 m: every tile type appears (8 types, 9 tiles), on a 241 x 241 grid that builds in milliseconds.
SMALL = {"size": 12.0, "tile": 4.0, "border": 0.0}


def _largest_neighbour_jump(heights: np.ndarray) -> float:
    """Largest height difference [m] between grid nodes one cell apart, along rows or columns."""
    return float(max(np.abs(np.diff(heights, axis=0)).max(), np.abs(np.diff(heights, axis=1)).max()))


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    low=st.floats(0.0, 0.2),
    spread=st.floats(0.0, 0.1),
    max_slope_deg=st.floats(5.0, 30.0),
)
def test_no_jump_is_higher_than_one_step(seed: int, low: float, spread: float, max_slope_deg: float) -> None:
    """Stairs and inclines rise from the border to the pad and back: a robot crossing tiles never meets a wall.

    The bound: one step (step_height's upper bound), or an incline's rise over one grid cell when that is larger.
    """
    config = TerrainConfig(**SMALL, step_height=(low, low + spread), max_slope_deg=max_slope_deg)
    terrain = rough_terrain(config, seed)
    bound = max(low + spread, np.tan(np.deg2rad(max_slope_deg)) * config.resolution)
    assert _largest_neighbour_jump(terrain.heights) <= bound + 1e-9


def test_tile_borders_are_at_the_base_level_and_stairs_are_pyramids() -> None:
    config = TerrainConfig(**SMALL)
    terrain = rough_terrain(config, seed=7)
    per_tile = round(config.tile / config.resolution)
    borders = terrain.heights[::per_tile, :], terrain.heights[:, ::per_tile]
    for border in borders:
        np.testing.assert_allclose(border, config.base_level)
    # The highest pad is a stairs_up or slope_up top, well above a single step: the pyramids are there.
    assert terrain.spawn_points[:, 2].max() > config.base_level + config.step_height[1]


def test_pads_are_flat_and_spawn_points_sit_on_them() -> None:
    config = TerrainConfig(**SMALL)
    terrain = rough_terrain(config, seed=11)
    np.testing.assert_allclose(terrain.height(terrain.spawn_points[:, :2]), terrain.spawn_points[:, 2], atol=1e-12)
    offsets = np.linspace(-config.pad / 2, config.pad / 2, 5)
    for x, y, z in terrain.spawn_points:
        around = np.array([(x + dx, y + dy) for dx in offsets for dy in offsets])
        np.testing.assert_allclose(terrain.height(around), z, atol=1e-12)
        np.testing.assert_allclose(terrain.normal(np.array([[x, y]])), [[0.0, 0.0, 1.0]], atol=1e-12)


def test_a_flat_border_holds_every_episode_walk() -> None:
    """Default settings: from any spawn pad, a whole episode at the default command stays on the heightfield."""
    from margin_rl.envs.config import EnvConfig

    env = EnvConfig(terrain="rough")
    config = env.terrain_config
    terrain = rough_terrain(config, seed=0)
    n = terrain.heights.shape[0]
    extent = (n - 1) * config.resolution
    assert extent == pytest.approx(config.size + 2 * config.border)
    walk = env.episode_length_s * max(abs(v) for v in env.command.forward_velocity)  # 15 m
    to_edge = extent / 2 - np.abs(terrain.spawn_points[:, :2]).max()
    assert to_edge >= walk
    margin = round(config.border / config.resolution)
    ring = np.ones((n, n), bool)
    ring[margin : n - margin, margin : n - margin] = False
    np.testing.assert_array_equal(terrain.heights[ring], config.base_level)


def test_same_seed_same_grid_and_every_tile_type_used() -> None:
    config = TerrainConfig(**SMALL)
    a, b = rough_terrain(config, seed=5), rough_terrain(config, seed=5)
    np.testing.assert_array_equal(a.heights, b.heights)
    assert not np.array_equal(a.heights, rough_terrain(config, seed=6).heights)
    assert len(a.spawn_points) == 9 >= len(TILE_TYPES)


def test_heights_are_the_surface_mujoco_collides_with() -> None:
    """Terrain.height against MuJoCo's own ray casts down onto the heightfield geom, at random points over the tiles
    (risers included): equal to the heightfield's float32 storage (MuJoCo splits every cell along one diagonal; a
    bilinear interpolation differs by up to 3 cm on risers). The normals are those of the same surface: on a planar
    incline the central-difference normal is the plane's."""
    import mujoco

    from margin_rl.envs.config import EnvConfig
    from margin_rl.envs.scene import build_model
    from margin_rl.robot import load_robot

    config = EnvConfig(robot="anymal_c", terrain="rough", terrain_config=TerrainConfig(**SMALL))
    terrain = rough_terrain(config.terrain_config, seed=3)
    model = build_model(load_robot("anymal_c"), terrain, config.terrain_config)
    data = mujoco.MjData(model)
    data.qpos[:3] = [0.0, 0.0, 10.0]  # the robot well above the rays' start
    mujoco.mj_forward(model, data)
    floor, hit = model.geom("floor").id, np.zeros(1, dtype=np.int32)
    half = (terrain.heights.shape[0] - 1) * terrain.resolution / 2
    points = np.random.default_rng(0).uniform(-half + 0.01, half - 0.01, size=(2000, 2))
    ray, hits = np.empty(len(points)), np.empty(len(points), dtype=int)
    for i, (x, y) in enumerate(points):
        ray[i] = 5.0 - mujoco.mj_ray(model, data, np.array([x, y, 5.0]), np.array([0.0, 0.0, -1.0]), None, 1, -1, hit)
        hits[i] = hit[0]
    assert np.all(hits == floor)
    heights = terrain.height(points)
    assert np.ptp(heights) > 0.1  # the points met the tiles, not only the base level
    np.testing.assert_allclose(heights, ray, atol=config.terrain_config.max_height * 2**-22)  # float32 storage

    slope = 0.2
    x = (np.arange(41) - 20) * 0.05
    incline = Terrain(heights=1.0 + slope * np.tile(x, (41, 1)), origin=(-1.0, -1.0), resolution=0.05,
                      spawn_points=np.zeros((1, 3)))  # fmt: skip
    inside = np.random.default_rng(1).uniform(-0.8, 0.8, size=(50, 2))
    np.testing.assert_allclose(incline.height(inside), 1.0 + slope * inside[:, 0], atol=1e-12)
    np.testing.assert_allclose(incline.normal(inside), np.tile([-slope, 0.0, 1.0] / np.hypot(slope, 1.0), (50, 1)),
                               atol=1e-12)  # fmt: skip


def _ramp_terrain(rise_per_cell: np.ndarray) -> Terrain:
    """A terrain varying along x only: heights[:, c] = rise_per_cell[:c].sum(), 5 cm cells, origin (0, 0)."""
    profile = np.concatenate([[0.0], np.cumsum(rise_per_cell)])
    heights = np.tile(profile, (5, 1))
    return Terrain(heights=heights, origin=(0.0, 0.0), resolution=0.05, spawn_points=np.zeros((1, 3)))


@settings(max_examples=30, deadline=None)
@given(slope=st.floats(0.0, 0.5), radius=st.floats(0.005, 0.04), x=st.floats(0.05, 0.3), y=st.floats(0.05, 0.15))
def test_height_spread_on_an_incline_is_the_rise_across_the_disc(
    slope: float, radius: float, x: float, y: float
) -> None:
    """On a plane rising along x by ``slope``, the highest and lowest points of a disc's rim lie on the x axis
    through its centre (two of the 8 rim points): spread = 2 r slope, by hand."""
    terrain = _ramp_terrain(np.full(8, 0.05 * slope))
    spread = terrain.height_spread(np.array([[x, y]]), radius)
    np.testing.assert_allclose(spread, [2 * radius * slope], rtol=0, atol=1e-12)


def test_height_spread_sees_a_step_only_under_the_sole() -> None:
    """A 6 cm step as the heightfield makes it (a one-cell riser from x = 0.20 to 0.25 m): a 3 cm sole centred on
    the riser spans it (spread 6 cm); one centred 5 cm from it touches nothing of it (0); flat ground is 0."""
    rise = np.zeros(10)
    rise[4] = 0.06
    terrain = _ramp_terrain(rise)
    spread = terrain.height_spread(np.array([[0.225, 0.1], [0.10, 0.1], [0.35, 0.1]]), 0.03)
    np.testing.assert_allclose(spread, [0.06, 0.0, 0.0], atol=1e-12)
    flat = Terrain(heights=None, origin=(0.0, 0.0), resolution=1.0, spawn_points=np.zeros((1, 3)))
    assert flat.height_spread(np.zeros((3, 4, 2)), 0.03).shape == (3, 4)


def test_height_spread_is_the_same_on_torch() -> None:
    import torch

    terrain = rough_terrain(TerrainConfig(size=8.0, border=1.0), seed=3)
    xy = np.random.default_rng(0).uniform(-4.0, 4.0, (64, 4, 2))
    on_torch = terrain.height_spread(torch.from_numpy(xy), 0.03)
    assert isinstance(on_torch, torch.Tensor)
    np.testing.assert_allclose(on_torch.numpy(), terrain.height_spread(xy, 0.03), rtol=0, atol=1e-12)


def test_a_steps_one_terrain_lookup_equals_each_query_made_alone() -> None:
    """The core looks up every ground height of a step at once (base, knees, the feet's normal stencils and soles,
    the height scan): each part equals the query made alone, bit for bit."""
    from margin_rl.envs.config import EnvConfig, RewardParams
    from margin_rl.envs.core import AnymalCore

    config = EnvConfig(
        robot="anymal_c", terrain="rough", height_scan=True, reward_params=RewardParams(knee_clearance=0.1)
    )
    core = AnymalCore(config, 3, seed=4)
    core.reset(seed=4)
    for action in np.random.default_rng(0).uniform(-1, 1, (8, 3, 12)):
        core.step(action)
    state = core._read()
    ground, terrain = core._ground.heights(state, core.config), core.terrain
    feet_xy = state.feet[..., :2]
    assert set(ground) == {"base", "knees", "normals", "soles", "scan"}
    np.testing.assert_array_equal(ground["base"], terrain.height(state.base_pos[:, :2]))
    np.testing.assert_array_equal(ground["knees"], terrain.height(state.knees[..., :2]))
    np.testing.assert_array_equal(terrain.normal_from_heights(ground["normals"]), terrain.normal(feet_xy))
    spread = np.max(ground["soles"], axis=-1) - np.min(ground["soles"], axis=-1)
    np.testing.assert_array_equal(spread, terrain.height_spread(feet_xy, core.robot.foot_radius))
    np.testing.assert_array_equal(ground["scan"], terrain.height(core._ground.scan_points(state)))
