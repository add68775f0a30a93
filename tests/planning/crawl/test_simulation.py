"""The crawl in MuJoCo and seed 004 §VI-A's tests: s = 0 where the simulated robot reaches its limit."""

from __future__ import annotations

import numpy as np
import pytest

from margin_rl.planning.crawl import CrawlSimulation, HeuristicPlanner, HinderedJoint
from margin_rl.planning.crawl.stance_tests import displacement_test, triple_stance, vertical_disturbance_test
from margin_rl.planning.crawl.terrain import TileTerrain


def test_the_controller_holds_and_moves_the_standing_robot(robot_c, gait):
    sim = CrawlSimulation(robot_c, gait)
    target = sim.com_des + np.array([0.03, 0.02, 0.0])
    sim.com_des = target
    sim.hold(1.5)
    np.testing.assert_allclose(sim.com(), target, atol=5e-3)
    assert not np.asarray(sim.trace.at_limit).any()


def test_the_heuristic_crawl_walks_on_its_footholds(robot_c, gait):
    sim = CrawlSimulation(robot_c, gait)
    planner = HeuristicPlanner(gait)
    for step in range(4):
        sim.crawl_step(step, planner)
    assert sim.com()[0] > 0.05  # one cycle: every foot half a stride ahead, the CoM followed
    assert np.abs(sim.feet() - sim.footholds)[:, :2].max() < 0.03
    assert sim.data.qpos[2] > 0.9 * robot_c.standing_height
    assert not np.asarray(sim.trace.at_limit).any()


def test_a_hindered_joint_lowers_the_servo_and_the_controller_limit(robot_c, gait):
    sim = CrawlSimulation(robot_c, gait, hindered=HinderedJoint("LF", 2, 0.5))
    assert sim.model.actuator_forcerange[2, 1] == pytest.approx(0.5 * robot_c.torque_limits[2])
    assert sim.controller.torque_limits[0, 2] == pytest.approx(0.5 * robot_c.torque_limits[2])
    with pytest.raises(ValueError, match="fraction must be in"):
        HinderedJoint("LF", 2, 1.5)
    with pytest.raises(ValueError, match="load_kg must be >= 0"):
        CrawlSimulation(robot_c, gait, load_kg=-1.0)


@pytest.fixture(scope="module")
def held(robot_c, gait):
    return lambda: triple_stance(robot_c, gait, HeuristicPlanner(gait))[0]


def test_s_reaches_zero_where_the_pushed_robot_runs_out_of_torque(held):
    """Vertical disturbance test: the force at which the controller finds no force distribution within the
    torque limits (the simulated FWP boundary) is the force at which s = 0, to 1 %; the servos reach their
    limit earlier by their position error, by less than 15 %."""
    result = vertical_disturbance_test(held())
    assert result.s_start > 0
    assert result.distribution_limit_force == pytest.approx(result.s_zero_force, rel=0.01)
    assert 0.85 * result.s_zero_force <= result.limit_force <= result.s_zero_force
    assert result.limit_joint


def test_s_reaches_zero_where_the_watched_foot_unloads(held):
    """Displacement test: LF's measured normal force and s reach zero within 1 cm of CoM displacement."""
    result = displacement_test(held())
    assert result.s_start > 0
    assert abs(result.unload_shift - result.s_zero_shift) < 0.01


def test_a_crawl_replays_into_an_mp4(robot_c, gait, tmp_path):
    from margin_rl.planning.crawl.video import write_crawl_mp4
    from margin_rl.planning.video import VideoUnavailableError

    sim = CrawlSimulation(robot_c, gait)
    qpos = np.asarray(sim.trace.qpos)
    pytest.importorskip("imageio_ffmpeg", reason="MP4 needs imageio-ffmpeg (the 'video' extra)")
    try:
        mp4 = write_crawl_mp4(robot_c, {"settle": qpos}, tmp_path / "crawl.mp4", 0.005, fps=5, size=(160, 96))
    except VideoUnavailableError as exc:
        pytest.skip(str(exc))
    assert mp4.stat().st_size > 1000


def test_the_crawl_steps_onto_level_tiles_at_their_heights(robot_c, gait):
    """Rough ground: the footholds take the height of the tile under them, and the robot walks onto them."""
    terrain = TileTerrain(max_height=0.05, seed=0)
    sim = CrawlSimulation(robot_c, gait, terrain=terrain)
    planner = HeuristicPlanner(gait)
    for step in range(4):
        sim.crawl_step(step, planner)
    for foothold in sim.footholds:
        expected = terrain.height(foothold[0], foothold[1]) + robot_c.foot_radius
        assert foothold[2] == pytest.approx(expected)
    assert np.ptp(sim.footholds[:, 2]) > 0.01  # the feet stand at different heights
    assert np.abs(sim.feet() - sim.footholds).max() < 0.03
    assert sim.data.qpos[2] > 0.9 * robot_c.standing_height


def test_tiles_are_level_and_flat_under_the_standing_robot():
    terrain = TileTerrain(max_height=0.05, seed=3)
    assert terrain.height(0.45, 0.3) == terrain.height(-0.45, -0.3) == 0.0
    assert terrain.heights.min() >= 0.0 and terrain.heights.max() <= 0.05
    assert terrain.height(10.0, 0.0) == 0.0  # beyond the tiles: the floor
    with pytest.raises(ValueError, match="ranges must be increasing"):
        TileTerrain(x_range=(1.0, 0.0))
