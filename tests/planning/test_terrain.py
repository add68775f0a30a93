"""Height maps: numpy vs CasADi, gradients vs finite differences, a plane solved by hand, bad input."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.planning import HeightMap, flat_map, get_scenario
from margin_rl.planning.scenarios import SIDE_STEP_HEIGHT


def test_plane_is_reproduced_exactly():
    # A B-spline reproduces linear functions, so h = 0.2 x - 0.1 y + 0.3 has gradient (0.2, -0.1) everywhere.
    base = flat_map((0.0, 2.0), (0.0, 1.0), 0.1)
    ny, nx = base.shape
    X, Y = np.meshgrid(0.1 * np.arange(nx), 0.1 * np.arange(ny))
    plane = HeightMap(0.2 * X - 0.1 * Y + 0.3, (0.0, 0.0), 0.1)
    pts = np.array([[0.5, 0.5], [1.23, 0.77], [0.31, 0.12]])
    np.testing.assert_allclose(plane.height(pts), 0.2 * pts[:, 0] - 0.1 * pts[:, 1] + 0.3, atol=1e-12)
    np.testing.assert_allclose(plane.gradient(pts), np.tile([0.2, -0.1], (3, 1)), atol=1e-12)
    n = np.array([-0.2, 0.1, 1.0]) / np.sqrt(1.05)
    np.testing.assert_allclose(plane.normal(pts), np.tile(n, (3, 1)), atol=1e-12)


def test_casadi_matches_numpy_and_gradients_match_finite_differences(bumpy_map):
    rng = np.random.default_rng(1)
    x_min, x_max, y_min, y_max = bumpy_map.extent
    pts = np.column_stack([rng.uniform(x_min, x_max, 20), rng.uniform(y_min, y_max, 20)])
    xy = ca.MX.sym("xy", 2)
    h = bumpy_map.casadi_function(xy)
    f = ca.Function("f", [xy], [h, ca.jacobian(h, xy)])
    eps = 1e-6
    for p in pts:
        value, grad = f(p)
        assert float(value) == pytest.approx(float(bumpy_map.height(p)), abs=1e-12)
        np.testing.assert_allclose(np.array(grad).ravel(), bumpy_map.gradient(p), atol=1e-10)
        fd = [(bumpy_map.height(p + e) - bumpy_map.height(p - e)) / (2 * eps) for e in np.eye(2) * eps]
        np.testing.assert_allclose(bumpy_map.gradient(p), fd, atol=1e-6)


def test_step_is_smoothed_without_overshoot():
    hm = get_scenario("side_step").height_map
    ys = np.linspace(-0.5, 0.5, 401)
    h = hm.height(np.column_stack([np.full_like(ys, 3.0), ys]))
    assert h.min() >= -1e-12 and h.max() <= SIDE_STEP_HEIGHT + 1e-12
    assert np.all(np.diff(h) >= -1e-12)  # monotone across the edge
    assert h[0] == pytest.approx(0.0) and h[-1] == pytest.approx(SIDE_STEP_HEIGHT)


def test_env_rough_terrain_loads_with_the_envs_grid_convention():
    from margin_rl.envs.terrain import TerrainConfig, flat_terrain, rough_terrain

    terrain = rough_terrain(TerrainConfig(size=4.0, tile=2.0), seed=3)
    hm = HeightMap.from_env_terrain(terrain)
    # On grid nodes of a planar patch the spline equals the grid; check the convention through the spawn pads.
    pads = np.asarray(terrain.spawn_points)
    np.testing.assert_allclose(hm.height(pads[:, :2]), terrain.height(pads[:, :2]), atol=1e-9)
    with pytest.raises(ValueError, match="flat"):
        HeightMap.from_env_terrain(flat_terrain())


@settings(max_examples=25, deadline=None)
@given(
    shape=st.tuples(st.integers(0, 4), st.integers(0, 4)),
    resolution=st.floats(-1.0, 1.0),
)
def test_bad_maps_are_refused_with_a_clear_message(shape, resolution):
    heights = np.zeros(shape)
    if min(shape) >= 2 and resolution > 0:
        HeightMap(heights, (0.0, 0.0), resolution)  # valid: must not raise
        return
    with pytest.raises(ValueError, match=r"grid|resolution"):
        HeightMap(heights, (0.0, 0.0), resolution)


def test_nan_heights_and_bad_query_shapes_are_refused():
    with pytest.raises(ValueError, match="NaN"):
        HeightMap(np.full((3, 3), np.nan), (0.0, 0.0), 0.1)
    with pytest.raises(ValueError, match=r"\(\.\.\., 2\)"):
        flat_map((0, 1), (0, 1)).height(np.zeros((4, 3)))


def test_unknown_scenario_lists_the_known_ones():
    with pytest.raises(ValueError, match="side_step"):
        get_scenario("sidestep")
