"""Receding horizon, independent checks, figure, MP4 and CLI on short runs."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from margin_rl.planning import WALK, PlannerConfig, check_course, get_scenario, lateral_com_offset, run_course
from margin_rl.planning.__main__ import main
from margin_rl.stability import LearnedMargin


@pytest.fixture(scope="module")
def short_course(model_c, margin_c):
    return run_course(model_c, get_scenario("flat"), WALK, PlannerConfig(), margin_c, max_plans=3)


def test_receding_horizon_is_warm_started_and_continuous(short_course):
    plans = short_course.plans
    assert len(plans) == 3 and all(p.success for p in plans)
    for a, b in itertools.pairwise(plans):
        # Each horizon starts where the previous plan is one period later.
        np.testing.assert_allclose(b.base[0], np.concatenate(a.base_at(b.t0)[:4]), atol=1e-9)
    assert plans[-1].base[0, 0] > plans[0].base[0, 0] + 0.1  # progress along the course
    # Three plans of a 6 m course end far from its goal: the distance is the last plan's start to the goal.
    goal = np.array(get_scenario("flat").goal_xy)
    assert short_course.distance_to_goal == pytest.approx(np.linalg.norm(plans[-1].base[0, :2] - goal))
    assert short_course.distance_to_goal > 4.0 and not short_course.reached_goal


def test_analytic_margin_along_the_plan(short_course, robot_c, margin_c):
    check = check_course(short_course, robot_c, margin_c)
    summary = check.summary()
    assert summary["share_reachable"] == 1.0
    assert summary["share_analytic_ok"] >= 0.95
    assert check.at_node.sum() == len(check.times) // 4  # nodes every 0.2 s among samples every 0.05 s
    # The checks' lambda (numpy route) and the network agree to a few cm along the plan.
    assert summary["learned_minus_analytic_rmse"] < 0.05


def test_lateral_com_offset_by_hand(short_course, robot_c):
    check = check_course(short_course, robot_c, None, dt=0.5)
    feet = check.lambdas[:, 18:30].reshape(-1, 4, 3)
    expected = -feet[:, :, 1].mean()
    assert lateral_com_offset(check) == pytest.approx(expected)
    assert abs(lateral_com_offset(check)) < 0.05  # level ground: no systematic shift


def test_figure_and_video(short_course, robot_c, margin_c, tmp_path):
    from margin_rl.planning.figures import course_figure
    from margin_rl.planning.video import VideoUnavailableError, joint_configuration, write_mp4

    check = check_course(short_course, robot_c, margin_c, dt=0.25)
    png = course_figure(short_course, check, tmp_path / "c.png")
    assert png.stat().st_size > 10_000
    qpos, reachable = joint_configuration(robot_c, short_course, 0.5)
    assert reachable and qpos.shape == (19,)
    # The base placed by the CoM fixed point puts the robot's CoM on the planned one.
    com_base = robot_c.com_position(qpos[7:])
    from margin_rl.planning.checks import rotation_kinematics

    c, rpy = short_course.plan_at(0.5).base_at(0.5)[:2]
    R = rotation_kinematics(rpy, np.zeros(3), np.zeros(3))[0]
    np.testing.assert_allclose(qpos[0:3] + R @ com_base, c, atol=1e-3)
    pytest.importorskip("imageio_ffmpeg", reason="MP4 needs imageio-ffmpeg (the 'video' extra)")
    try:
        mp4 = write_mp4(robot_c, short_course, tmp_path / "c.mp4", fps=5, size=(160, 96))
    except VideoUnavailableError as exc:
        pytest.skip(str(exc))
    assert mp4.stat().st_size > 1000


def test_cli_refuses_unknown_scenarios(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--scenario", "stairs"])
    assert exc.value.code == 2
    assert "side_step" in capsys.readouterr().err


def test_cli_plans_with_other_weights_and_records_them(tmp_path, capsys):
    """``--weights`` replaces the default network (here by the robot's Table I network) and the summary records
    which weights constrained the plans; unknown weights are refused with the bundled names."""
    main(["--scenario", "flat", "--max-plans", "1", "--no-video", "--no-contrast", "--weights", "anymal_c_table_i",
          "--out", str(tmp_path)])  # fmt: skip
    summary = json.loads((tmp_path / "anymal_c_flat_walk.json").read_text())
    expected = LearnedMargin.load("anymal_c_table_i").card["sha256"]
    assert summary["weights"] == {"name": "anymal_c_table_i", "sha256": expected}
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(["--scenario", "flat", "--max-plans", "1", "--weights", "anymal_x", "--out", str(tmp_path)])
    assert exc.value.code == 2
    assert "--weights" in (err := capsys.readouterr().err) and "anymal_c_table_i" in err
