"""Shared fixtures of the crawl tests: a gait and the first base-motion task from ANYmal C's standing pose."""

from __future__ import annotations

import numpy as np
import pytest

from margin_rl.planning.crawl import BaseMotionTask, CrawlGait, WrenchPolytopePlanner


def standing_task(robot, swing: str = "LH", load_kg: float = 0.0) -> BaseMotionTask:
    """The base motion before ``swing`` lifts, from the standing keyframe (world = base frame on the ground)."""
    q = robot.standing_joint_pos
    base = np.array([0.0, 0.0, robot.standing_height])
    feet = robot.foot_positions(q) + base
    return BaseMotionTask(
        com_start=robot.com_position(q) + base, feet=feet, swing=swing, normals=np.tile([0.0, 0.0, 1.0], (4, 1)),
        mu=1.0, ext_force=np.array([0.0, 0.0, -load_kg * robot.gravity]), ext_torque=np.zeros(3),
        torque_limits=np.asarray(robot.torque_limits, dtype=float).reshape(4, 3),
        foothold=feet[["LF", "RF", "LH", "RH"].index(swing)] + np.array([0.1, 0.0, 0.0]),
    )  # fmt: skip


@pytest.fixture(scope="session")
def gait():
    return CrawlGait()


@pytest.fixture(scope="session")
def task_c(robot_c):
    return standing_task(robot_c)


@pytest.fixture(scope="session")
def fwp_planner_c(robot_c, gait):
    return WrenchPolytopePlanner(robot_c, gait, "fwp")


@pytest.fixture(scope="session")
def fwp_polytopes_c(fwp_planner_c, task_c):
    return fwp_planner_c.polytopes(task_c)
