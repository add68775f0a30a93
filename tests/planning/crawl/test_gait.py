"""The crawl's geometry: footholds, support triangles, the workspace box, the gait's validation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.planning.crawl.gait import (
    SWING_ORDER,
    CrawlGait,
    inradius,
    next_foothold,
    support_triangle,
    swing_leg,
    triangle_halfplanes,
    workspace_bounds,
)

FEET_XY = np.array([[0.45, 0.3], [0.45, -0.3], [-0.45, 0.3], [-0.45, -0.3]])


def test_swing_order_cycles_hind_then_front_of_each_side():
    assert [swing_leg(k) for k in range(8)] == list(SWING_ORDER) * 2
    with pytest.raises(ValueError, match="step must be >= 0"):
        swing_leg(-1)


def test_footholds_step_half_a_stride_first_then_whole_strides():
    start = np.array([0.45, 0.3, 0.03])
    first = next_foothold(start, 0.2, True, 0.03)
    np.testing.assert_allclose(first, [0.55, 0.3, 0.03])
    np.testing.assert_allclose(next_foothold(first, 0.2, False, 0.03), [0.75, 0.3, 0.03])


def test_support_triangle_drops_the_swing_foot_and_is_counter_clockwise():
    tri = support_triangle(FEET_XY, "RH")
    assert {tuple(p) for p in tri} == {(0.45, 0.3), (0.45, -0.3), (-0.45, 0.3)}
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    assert e1[0] * e2[1] - e1[1] * e2[0] > 0
    with pytest.raises(ValueError, match="unknown leg"):
        support_triangle(FEET_XY, "XX")


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
    st.floats(0.0, 1.0),
    st.floats(0.0, 1.0),
)
def test_shrunk_triangle_points_keep_the_margin_from_every_edge(coords, u, v):
    """Property: a point satisfying the half-planes of margin d is at least d from each edge line, and the
    incircle's centre satisfies margin = inradius with equality."""
    tri = np.asarray(coords).reshape(3, 2)
    area2 = abs((tri[1, 0] - tri[0, 0]) * (tri[2, 1] - tri[0, 1]) - (tri[1, 1] - tri[0, 1]) * (tri[2, 0] - tri[0, 0]))
    if area2 < 1e-2:
        return
    tri = support_triangle(np.vstack([tri, [9.0, 9.0]]), "RH")
    r = inradius(tri)
    margin = 0.5 * r
    a, b = triangle_halfplanes(tri, margin)
    if u + v > 1:
        u, v = 1 - u, 1 - v
    point = tri[0] + u * (tri[1] - tri[0]) + v * (tri[2] - tri[0])
    if np.all(a @ point <= b):
        for k in range(3):
            p, q = tri[k], tri[(k + 1) % 3]
            edge = q - p
            dist = abs(edge[0] * (point - p)[1] - edge[1] * (point - p)[0]) / np.linalg.norm(edge)
            assert dist >= margin - 1e-9
    sides = np.array([np.linalg.norm(tri[(k + 1) % 3] - tri[k]) for k in range(3)])
    incentre = (sides[1] * tri[0] + sides[2] * tri[1] + sides[0] * tri[2]) / sides.sum()
    a_r, b_r = triangle_halfplanes(tri, r)
    np.testing.assert_allclose(a_r @ incentre, b_r, atol=1e-9)


def test_workspace_bounds_center_on_the_standing_pose_and_collapse_when_crossed():
    lower, upper = workspace_bounds(FEET_XY, FEET_XY, (0.15, 0.05))
    np.testing.assert_allclose(lower, [-0.15, -0.05])
    np.testing.assert_allclose(upper, [0.15, 0.05])
    spread = FEET_XY.copy()
    spread[0, 0] += 0.4  # one foot far ahead: no CoM x keeps all within 0.15
    lower, upper = workspace_bounds(spread, FEET_XY, (0.15, 0.05))
    assert lower[0] == upper[0] == pytest.approx(0.2)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("stride", -0.1, "stride must be a positive"),
        ("knots", 1, "knots must be an integer >= 2"),
        ("duration_bounds", (2.0, 3.0), "duration_bounds must satisfy"),
        ("workspace_box", (0.1, -0.1), "workspace_box must be two positive"),
        ("max_acceleration", float("nan"), "max_acceleration must be a positive"),
    ],
)
def test_gait_rejects_bad_values_by_name(field, value, message):
    with pytest.raises(ValueError, match=message):
        CrawlGait(**{field: value})
