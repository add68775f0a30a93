"""Shared fixtures of the planning tests: robots, learned margins and a small problem, loaded once."""

from __future__ import annotations

import numpy as np
import pytest

from margin_rl.planning import WALK, PlannerConfig, TrajectoryProblem, flat_map, planning_robot, planning_weights
from margin_rl.robot import load_robot
from margin_rl.stability import LearnedMargin


@pytest.fixture(scope="session")
def robot_c():
    return load_robot("anymal_c")


@pytest.fixture(scope="session")
def model_c(robot_c):
    return planning_robot(robot_c)


@pytest.fixture(scope="session")
def margin_c():
    return LearnedMargin.load(planning_weights("anymal_c"))


@pytest.fixture(scope="session")
def bumpy_map():
    """A smooth non-planar map (so normals and slopes vary under every foothold)."""
    base = flat_map((-1.0, 2.0), (-1.0, 1.0), 0.05)
    ny, nx = base.shape
    x = base.origin[0] + 0.05 * np.arange(nx)
    y = base.origin[1] + 0.05 * np.arange(ny)
    X, Y = np.meshgrid(x, y)
    heights = 0.05 * np.sin(2.0 * X) * np.cos(3.0 * Y) + 0.03 * X
    return type(base)(heights, base.origin, 0.05, "bumpy")


@pytest.fixture(scope="session")
def walk_problem(model_c, bumpy_map, margin_c):
    """The walk problem of seed 000 §V-B on the bumpy map, starting mid-cycle (t0 = 0.6 s)."""
    return TrajectoryProblem(model_c, bumpy_map, WALK, 0.6, PlannerConfig(), margin_c)


def random_decision(problem, seed: int = 0) -> np.ndarray:
    """A decision vector near a plausible walking state, with generic (non-zero) angles and rates."""
    rng = np.random.default_rng(seed)
    n = problem.schedule.n_nodes
    base = np.zeros((n, 12))
    base[:, 0] = np.linspace(0.0, 0.45, n) + 0.01 * rng.normal(size=n)
    base[:, 1] = 0.02 * rng.normal(size=n)
    base[:, 2] = problem.model.nominal_com_height + 0.01 * rng.normal(size=n)
    base[:, 3:6] = 0.05 * rng.normal(size=(n, 3))
    base[:, 6:12] = 0.1 * rng.normal(size=(n, 6))
    feet = []
    for slot in problem.schedule.slots:
        xy = problem.model.nominal_feet_com[slot.leg, :2] + np.array([0.15 * (slot.touchdown - 0.6), 0.0])
        xy = xy + 0.02 * rng.normal(size=2)
        feet.append([xy[0], xy[1], float(problem.height_map.height(xy))])
    return np.concatenate([base.ravel(), np.array(feet).ravel()])


def initial_footholds(problem) -> np.ndarray:
    xy = problem.model.nominal_feet_com[:, :2]
    return np.column_stack([xy, problem.height_map.height(xy)])
