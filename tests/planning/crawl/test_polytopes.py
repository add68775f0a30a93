"""Stance polytopes and the pseudo-inverse cost of eq. (27)-(28)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from margin_rl.planning.crawl.polytopes import stance_polytope
from margin_rl.stability.fwp.factor import feasibility_factor
from margin_rl.stability.geometry.contact import gravito_inertial_wrench


def test_metric_cost_equals_the_explicit_pseudo_inverse_weights(fwp_polytopes_c, robot_c):
    """Two ways: n_v ||V^# w + N_V lambda_0 - lambda_0||^2 with an explicit pseudo-inverse (n_v x n_v), and the
    6 x 6 quadratic form the planner uses."""
    rng = np.random.default_rng(0)
    for polytope in fwp_polytopes_c:
        n_v = polytope.n_vertices
        lam0 = np.full(n_v, 1.0 / n_v)
        for _ in range(3):
            w = polytope.centroid + rng.normal(size=6) * np.array([30, 30, 100, 10, 10, 5])
            weights = polytope.weights(w)
            np.testing.assert_allclose(polytope.polytope.vertices.T @ weights, w, rtol=1e-7, atol=1e-6)
            explicit = n_v * float(np.sum((weights - lam0) ** 2))
            assert polytope.cost(w) == pytest.approx(explicit, rel=1e-6)
        assert polytope.cost(polytope.centroid) == pytest.approx(0.0, abs=1e-12)


def test_the_standing_wrench_is_inside_both_kinds_of_polytope(robot_c, task_c):
    snapshot = task_c.snapshot(task_c.com_start, swing_lifted=False)
    w = gravito_inertial_wrench(robot_c.total_mass, gravity=robot_c.gravity)
    np.testing.assert_allclose(w, [0, 0, robot_c.total_mass * robot_c.gravity, 0, 0, 0])
    for kind in ("fwp", "cwc"):
        polytope = stance_polytope(robot_c, snapshot, kind)
        assert polytope.polytope.dim == 6
        s = feasibility_factor(polytope.polytope.vertices, w, length_scale=polytope.polytope.length_scale).s
        assert 0 < s <= 1


def test_the_triple_stance_cwc_has_fewer_vertices_than_the_four_foot_one(robot_c, task_c):
    four = stance_polytope(robot_c, task_c.snapshot(task_c.com_start, False), "cwc")
    three = stance_polytope(robot_c, task_c.snapshot(task_c.com_start, True), "cwc")
    assert three.n_vertices < four.n_vertices


def test_bad_kind_and_too_few_feet_are_named(robot_c, task_c):
    snapshot = task_c.snapshot(task_c.com_start, False)
    with pytest.raises(ValueError, match="unknown polytope kind 'awp'"):
        stance_polytope(robot_c, snapshot, "awp")
    with pytest.raises(ValueError, match="at least three feet"):
        stance_polytope(robot_c, dataclasses.replace(snapshot, stance=np.array([True, True, False, False])), "fwp")
