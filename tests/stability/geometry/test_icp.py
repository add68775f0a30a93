"""Tests of the Instantaneous Capture Point (eq. 5) and the analytic stability margin (eq. 7)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull

from margin_rl.stability.geometry.icp import capture_point, stability_margin
from margin_rl.stability.geometry.region import FeasibleRegion, halfspaces_from_polygon, polygon_area


def region_from(vertices: np.ndarray) -> FeasibleRegion:
    v = np.asarray(vertices, dtype=float)
    return FeasibleRegion(
        vertices=v,
        halfspaces=halfspaces_from_polygon(v),
        status="ok",
        converged=True,
        n_lps=0,
        solve_time=0.0,
        area=polygon_area(v),
        gap=0.0,
    )


UNIT_SQUARE = region_from(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]))

finite = st.floats(-5.0, 5.0, allow_nan=False)


# ----------------------------------------------------------------------------------------------
# Capture point
# ----------------------------------------------------------------------------------------------


def test_capture_point_hand_value() -> None:
    # omega = sqrt(9.81 / 0.4) = 4.9523..., xi = c + v / omega
    xi = capture_point([0.1, -0.2], [1.0, 0.5], 0.4)
    omega = math.sqrt(9.81 / 0.4)
    np.testing.assert_allclose(xi, [0.1 + 1.0 / omega, -0.2 + 0.5 / omega], rtol=1e-14)


def test_capture_point_at_rest_is_the_com() -> None:
    np.testing.assert_array_equal(capture_point([0.3, 0.4], [0.0, 0.0], 1.0), [0.3, 0.4])


def test_capture_point_gravity_argument() -> None:
    xi = capture_point([0.0, 0.0], [1.0, 0.0], 1.0, g=4.0)
    np.testing.assert_allclose(xi, [0.5, 0.0])


def test_capture_point_batches_broadcast_heights() -> None:
    c = np.zeros((5, 2))
    v = np.tile([1.0, 0.0], (5, 1))
    h = np.linspace(0.1, 1.0, 5)
    xi = capture_point(c, v, h)
    assert xi.shape == (5, 2)
    np.testing.assert_allclose(xi[:, 0], np.sqrt(h / 9.81))


@pytest.mark.parametrize("height", [0.0, -0.5, math.nan, math.inf])
def test_capture_point_rejects_bad_height(height: float) -> None:
    with pytest.raises(ValueError, match="com_height"):
        capture_point([0.0, 0.0], [0.0, 0.0], height)


@pytest.mark.parametrize(
    ("args", "name"),
    [
        (([0.0, 0.0, 0.0], [0.0, 0.0], 1.0), "com_xy"),
        (([0.0, 0.0], [0.0], 1.0), "com_vel_xy"),
        (([0.0, math.nan], [0.0, 0.0], 1.0), "finite"),
    ],
)
def test_capture_point_rejects_bad_vectors(args: tuple, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        capture_point(*args)


def test_capture_point_rejects_bad_gravity() -> None:
    with pytest.raises(ValueError, match="g must"):
        capture_point([0.0, 0.0], [0.0, 0.0], 1.0, g=0.0)


@settings(max_examples=50, deadline=None)
@given(cx=finite, cy=finite, vx=finite, vy=finite, h=st.floats(0.05, 2.0))
def test_capture_point_lies_along_the_velocity(cx: float, cy: float, vx: float, vy: float, h: float) -> None:
    xi = capture_point([cx, cy], [vx, vy], h)
    d = xi - np.array([cx, cy])
    np.testing.assert_allclose(np.linalg.norm(d), math.hypot(vx, vy) * math.sqrt(h / 9.81), atol=1e-12)
    assert abs(d[0] * vy - d[1] * vx) <= 1e-9  # parallel
    assert d[0] * vx + d[1] * vy >= 0.0  # same direction


# ----------------------------------------------------------------------------------------------
# Stability margin
# ----------------------------------------------------------------------------------------------


def test_margin_of_unit_square() -> None:
    assert stability_margin(UNIT_SQUARE, [0.5, 0.5]) == pytest.approx(0.5)
    assert stability_margin(UNIT_SQUARE, [0.1, 0.5]) == pytest.approx(0.1)
    assert stability_margin(UNIT_SQUARE, [1.0, 0.3]) == pytest.approx(0.0)
    assert stability_margin(UNIT_SQUARE, [1.25, 0.5]) == pytest.approx(-0.25)
    # Beyond a corner eq. (7) measures the most violated edge line, not the Euclidean distance.
    assert stability_margin(UNIT_SQUARE, [1.3, 1.4]) == pytest.approx(-0.4)
    assert stability_margin(UNIT_SQUARE, [1.3, 1.4], outside="euclidean") == pytest.approx(-0.5)


def test_margin_accepts_raw_halfspaces_and_batches() -> None:
    pts = np.array([[[0.5, 0.5], [2.0, 0.5]], [[0.5, 0.9], [0.5, -1.0]]])
    m = stability_margin(UNIT_SQUARE.halfspaces, pts)
    assert m.shape == (2, 2)
    np.testing.assert_allclose(m, [[0.5, -1.0], [0.1, -1.0]])
    assert isinstance(stability_margin(UNIT_SQUARE, [0.5, 0.5]), float)


def test_margin_of_empty_region_is_minus_infinity() -> None:
    empty = region_from(np.zeros((0, 2)))
    assert stability_margin(empty, [0.0, 0.0]) == -math.inf
    assert np.all(stability_margin(empty, np.zeros((3, 2))) == -math.inf)


def test_margin_rejects_bad_shapes_and_modes() -> None:
    with pytest.raises(ValueError, match="point"):
        stability_margin(UNIT_SQUARE, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="half-spaces"):
        stability_margin(np.zeros((3, 2)), [0.0, 0.0])
    with pytest.raises(ValueError, match="outside"):
        stability_margin(UNIT_SQUARE, [0.0, 0.0], outside="other")
    with pytest.raises(ValueError, match="FeasibleRegion"):
        stability_margin(UNIT_SQUARE.halfspaces, [0.0, 0.0], outside="euclidean")


def segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + t * (b - a))))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_margin_is_distance_to_boundary_inside_and_euclidean_outside(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cloud = rng.normal(size=(12, 2))
    hull = ConvexHull(cloud)
    v = cloud[hull.vertices]  # scipy returns 2-D hull vertices counter-clockwise
    region = region_from(v)
    pts = rng.normal(scale=1.5, size=(30, 2))
    m_lines = stability_margin(region, pts)
    m_euc = stability_margin(region, pts, outside="euclidean")
    for p, ml, me in zip(pts, m_lines, m_euc, strict=True):
        # One point at a time (its own code path) agrees with the batch (to rounding: BLAS products).
        assert stability_margin(region, p) == pytest.approx(ml, abs=1e-12)
        assert stability_margin(region, p, outside="euclidean") == pytest.approx(me, abs=1e-12)
        dist = min(segment_distance(p, v[i], v[(i + 1) % len(v)]) for i in range(len(v)))
        inside = bool(np.all(hull.equations[:, :2] @ p + hull.equations[:, 2] <= 0))
        if inside:
            assert ml == pytest.approx(dist, abs=1e-12) and ml >= 0
            assert me == ml
        else:
            assert me == pytest.approx(-dist, abs=1e-12)
            assert -dist - 1e-12 <= ml <= 1e-12  # a line is never farther than the polygon
