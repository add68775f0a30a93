"""The quasi-static controller's force distribution, against hand-solvable cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from margin_rl.planning.crawl.controller import QuasiStaticController, _skew, rotation_vector


@pytest.fixture(scope="module")
def controller(robot_c):
    return QuasiStaticController(robot_c, np.asarray(robot_c.torque_limits).reshape(4, 3), mu=1.0)


def _standing(robot):
    q = robot.standing_joint_pos
    feet = robot.foot_positions(q) - np.array([0.0, 0.0, robot.foot_radius])
    rel = feet - robot.com_position(q)
    jac, dyn = robot.jacobians_and_dynamics(q)
    return rel, jac, dyn.bias_torques


def test_symmetric_stance_shares_the_weight_and_respects_every_limit(controller, robot_c):
    rel, jac, bias = _standing(robot_c)
    rel = rel - rel.mean(axis=0) * np.array([1, 1, 0])  # make the stance exactly symmetric about the CoM
    weight = np.array([0, 0, robot_c.total_mass * robot_c.gravity, 0, 0, 0])
    forces, ok = controller.distribute(weight, rel, np.ones(4, dtype=bool), jac, bias)
    assert ok
    moment = sum(_skew(r) @ f for r, f in zip(rel, forces, strict=True))
    np.testing.assert_allclose(forces.sum(axis=0), weight[:3], atol=1e-4)
    np.testing.assert_allclose(moment, 0.0, atol=1e-4)
    np.testing.assert_allclose(forces[:, 2], weight[2] / 4, rtol=0.05)  # symmetric legs, nearly equal loads
    tangential = np.abs(forces[:, :2])
    assert np.all(tangential <= controller.gains.friction_margin * forces[:, 2:3] / np.sqrt(2) + 1e-6)
    torques = bias - np.einsum("lij,li->lj", jac, forces)
    assert np.all(np.abs(torques) <= controller.torque_limits + 1e-6)


def test_three_feet_carry_the_weight_in_proportion_to_the_lever_arms(controller, robot_c):
    """Statics of a triple stance: with the CoM on the line between two feet, the third carries nothing."""
    rel, jac, bias = _standing(robot_c)
    stance = np.array([True, True, True, False])
    com_on_diagonal = 0.5 * (rel[1] + rel[2]) * np.array([1, 1, 0])  # midpoint of RF-LH
    weight = np.array([0, 0, robot_c.total_mass * robot_c.gravity, 0, 0, 0])
    forces, ok = controller.distribute(weight, rel - com_on_diagonal, stance, jac, bias)
    assert ok
    assert forces[0, 2] == pytest.approx(0.0, abs=2.0)
    assert forces[1, 2] == pytest.approx(forces[2, 2], rel=0.02)


def test_a_wrench_beyond_the_torque_limits_is_flagged(controller, robot_c):
    rel, jac, bias = _standing(robot_c)
    heavy = np.array([0, 0, 20 * robot_c.total_mass * robot_c.gravity, 0, 0, 0])
    forces, ok = controller.distribute(heavy, rel, np.ones(4, dtype=bool), jac, bias)
    assert not ok
    np.testing.assert_allclose(forces.sum(axis=0), heavy[:3], rtol=1e-5, atol=1e-6)


def test_normal_caps_bound_a_foot_being_loaded(controller, robot_c):
    rel, jac, bias = _standing(robot_c)
    weight = np.array([0, 0, robot_c.total_mass * robot_c.gravity, 0, 0, 0])
    caps = np.array([np.inf, np.inf, np.inf, 20.0])
    forces, _ = controller.distribute(weight, rel, np.ones(4, dtype=bool), jac, bias, caps)
    assert forces[3, 2] <= 20.0 + 1e-6


def test_rotation_vector_is_axis_times_angle():
    vec = np.array([0.1, -0.2, 0.05])
    np.testing.assert_allclose(rotation_vector(Rotation.from_rotvec(vec).as_matrix()), vec, atol=1e-9)
    with pytest.raises(ValueError, match="torque_limits must be positive"):
        QuasiStaticController(None, np.zeros((4, 3)), 1.0)  # type: ignore[arg-type]
