"""The three base-motion planners: one interface, eq. (25)-(28)'s constraints, derivatives, calibration."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from margin_rl.planning.crawl import PLANNER_NAMES, BaseMotionPlan, HeuristicPlanner, make_planner
from margin_rl.planning.crawl.gait import triangle_halfplanes
from margin_rl.planning.crawl.planners import BaseMotionTask, nearest_point_in_triangle
from margin_rl.stability.geometry.contact import gravito_inertial_wrench

from .conftest import standing_task


def test_nearest_point_in_triangle_matches_a_brute_force_search(task_c, gait):
    a, b = triangle_halfplanes(task_c.triangle(), gait.stability_margin)
    grid = np.stack(np.meshgrid(np.linspace(-0.6, 0.6, 601), np.linspace(-0.4, 0.4, 401)), -1).reshape(-1, 2)
    inside = grid[np.all(grid @ a.T <= b, axis=1)]
    for point in ([0.0, 0.0], [0.3, -0.3], [0.2, 0.1]):
        nearest = nearest_point_in_triangle(np.array(point), a, b)
        brute = inside[np.argmin(np.linalg.norm(inside - point, axis=1))]
        assert np.linalg.norm(nearest - point) <= np.linalg.norm(brute - point) + 1e-12
        assert np.linalg.norm(nearest - brute) < 3e-3


@pytest.mark.parametrize("name", PLANNER_NAMES)
def test_every_planner_returns_the_same_kind_of_plan(name, robot_c, gait, task_c):
    plan = make_planner(name, robot_c, gait).plan(task_c)
    assert isinstance(plan, BaseMotionPlan) and plan.planner == name
    n = gait.knots
    assert plan.com_xy.shape == plan.com_vel_xy.shape == (n + 1, 2)
    np.testing.assert_allclose(plan.com_xy[0], task_c.com_start[:2])
    assert plan.success and gait.duration_bounds[0] - 1e-9 <= plan.duration <= gait.duration_bounds[1] + 1e-9
    a, b = triangle_halfplanes(task_c.triangle(), gait.stability_margin)
    assert np.all(a @ plan.com_xy[-1] <= b + 1e-7)  # statically stable in the next triple stance
    pos, vel, _ = plan.com_at(0.0)
    assert np.allclose(vel, 0.0) and np.allclose(pos[:2], plan.com_xy[0])
    pos, vel, _ = plan.com_at(plan.duration)
    assert np.allclose(vel, 0.0, atol=1e-9) and np.allclose(pos[:2], plan.com_xy[-1])


def test_fwp_plan_obeys_backward_euler_rest_and_the_acceleration_bound(fwp_planner_c, fwp_polytopes_c, task_c, gait):
    plan = fwp_planner_c.solve(task_c, *fwp_polytopes_c)
    h = plan.duration / gait.knots
    np.testing.assert_allclose(plan.com_vel_xy[1:], np.diff(plan.com_xy, axis=0) / h, atol=1e-7)
    np.testing.assert_allclose(plan.com_vel_xy[[0, -1]], 0.0, atol=1e-8)
    acc = np.diff(plan.com_vel_xy, axis=0) / h
    assert np.all(np.abs(acc) <= gait.max_acceleration + 1e-6)
    assert plan.iterations < 60


def _numpy_cost(planner, task, four, triple, x: np.ndarray) -> float:
    """The objective written again with numpy and the polytopes' own cost, for the CasADi one."""
    n = planner.gait.knots
    cx, cy, vx, vy, dt = x[:n], x[n : 2 * n], x[2 * n : 3 * n], x[3 * n : 4 * n], x[-1]
    h = dt / n
    px, py = np.r_[task.com_start[0], cx], np.r_[task.com_start[1], cy]
    qx, qy = np.r_[0.0, vx], np.r_[0.0, vy]
    ref = four.reference_com
    ext_f, ext_t = task.ext_force, task.ext_torque
    mass, g = planner.robot.total_mass, planner.robot.gravity
    running = 0.0
    for k in range(1, n + 1):
        acc = np.array([(qx[k] - qx[k - 1]) / h, (qy[k] - qy[k - 1]) / h])
        offset = np.array([px[k] - ref[0], py[k] - ref[1], 0.0])
        running += four.cost(gravito_inertial_wrench(mass, [*acc, 0.0], (0, 0, 0), ext_f, ext_t, g, offset))
    offset = np.array([px[n] - ref[0], py[n] - ref[1], 0.0])
    terminal = triple.cost(gravito_inertial_wrench(mass, (0, 0, 0), (0, 0, 0), ext_f, ext_t, g, offset))
    return running / n + terminal + planner.time_weight * dt


def test_objective_and_its_gradient_match_an_independent_implementation(fwp_planner_c, fwp_polytopes_c, task_c):
    four, triple = fwp_polytopes_c
    p = fwp_planner_c.parameters(task_c, four, triple)
    program = fwp_planner_c._program
    rng = np.random.default_rng(1)
    n = fwp_planner_c.gait.knots
    x = np.concatenate([rng.normal(0.05, 0.03, 2 * n), rng.normal(0.0, 0.1, 2 * n), [1.3]])
    value = float(program.cost(x, p))
    assert value == pytest.approx(_numpy_cost(fwp_planner_c, task_c, four, triple, x), rel=1e-9)
    xs = ca.MX.sym("x", x.size)
    grad = ca.Function("grad", [xs], [ca.gradient(program.cost(xs, p), xs)])
    analytic = np.asarray(grad(x)).ravel()
    eps = 1e-6
    fd = np.array([
        (_numpy_cost(fwp_planner_c, task_c, four, triple, x + eps * e)
         - _numpy_cost(fwp_planner_c, task_c, four, triple, x - eps * e)) / (2 * eps)
        for e in np.eye(x.size)
    ])  # fmt: skip
    np.testing.assert_allclose(analytic, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_calibration_keeps_the_nominal_pace_and_a_load_slows_the_fwp_plan(robot_c, gait):
    planner = make_planner("fwp", robot_c, gait)
    rho = planner.calibrate(standing_task(robot_c))
    assert rho > 0
    unloaded = planner.plan(standing_task(robot_c))
    assert unloaded.duration == pytest.approx(gait.base_motion_duration, abs=0.15)
    loaded = planner.plan(standing_task(robot_c, load_kg=20.0))
    assert loaded.duration > unloaded.duration


def test_fwp_end_pose_is_more_feasible_than_the_heuristic_one(robot_c, gait, task_c, fwp_planner_c):
    """What the FWP planner optimises (the triple stance's s at its end pose) beats the heuristic's pose."""
    from margin_rl.planning.crawl.evaluation import fwp_factor

    heuristic = HeuristicPlanner(gait).plan(task_c)
    fwp = fwp_planner_c.plan(task_c)
    s_h = fwp_factor(robot_c, task_c.snapshot(heuristic.end_com, swing_lifted=True))
    s_f = fwp_factor(robot_c, task_c.snapshot(fwp.end_com, swing_lifted=True))
    assert s_f > s_h > 0


def test_bad_tasks_and_names_are_rejected_with_the_field(robot_c, gait, task_c):
    with pytest.raises(ValueError, match=r"BaseMotionTask\.feet must be a finite array of shape"):
        dataclasses.replace(task_c, feet=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="unknown leg"):
        dataclasses.replace(task_c, swing="XX")
    with pytest.raises(ValueError, match=r"BaseMotionTask\.mu must be positive"):
        dataclasses.replace(task_c, mu=0.0)
    with pytest.raises(ValueError, match="unknown crawl planner 'mpc'"):
        make_planner("mpc", robot_c, gait)
    with pytest.raises(ValueError, match="time_weight must be >= 0"):
        make_planner("fwp", robot_c, gait).__class__(robot_c, gait, time_weight=-1.0)
    assert isinstance(task_c, BaseMotionTask)
