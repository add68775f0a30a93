"""Robot layer: MuJoCo and Pinocchio agree, IK round-trips, the robots stand, bad inputs fail clearly."""

from __future__ import annotations

import shutil
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

import margin_rl
from margin_rl.robot import (
    RobotModelError,
    UnreachableFootError,
    available_robots,
    leg_inverse_kinematics,
    load_robot,
    load_robot_from_xml,
    quat_wxyz_to_matrix,
)

ROBOTS = ("anymal_b", "anymal_c")

# Independent oracle: URDF composite totals from the ANYbotics descriptions (fact sheet §B2, §C2b).
URDF_TOTAL_MASS = {"anymal_b": 30.4214, "anymal_c": 52.13485}


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request: pytest.FixtureRequest) -> margin_rl.Robot:
    return load_robot(request.param)


def random_unit_quat(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def random_joint_pos(robot: margin_rl.Robot, rng: np.random.Generator, n: int, spread: float = 0.6) -> np.ndarray:
    q = robot.standing_joint_pos + rng.uniform(-spread, spread, size=(n, 12))
    return np.clip(q, robot.joint_lower, robot.joint_upper)


def mj_state(robot: margin_rl.Robot, base_pos: np.ndarray, quat: np.ndarray, q: np.ndarray) -> mujoco.MjData:
    data = mujoco.MjData(robot.mj_model)
    data.qpos[:3] = base_pos
    data.qpos[3:7] = quat
    data.qpos[7:] = q
    mujoco.mj_forward(robot.mj_model, data)
    return data


def test_available_robots_lists_both() -> None:
    assert set(ROBOTS) <= set(available_robots())


def test_total_mass_mujoco_pinocchio_and_urdf_agree(robot: margin_rl.Robot) -> None:
    pin_mass = sum(inertia.mass for inertia in robot.pin_model.inertias)
    assert robot.total_mass == pytest.approx(pin_mass, abs=1e-9)
    assert robot.total_mass == pytest.approx(URDF_TOTAL_MASS[robot.name], abs=1e-3)


def test_every_body_has_explicit_inertial(robot: margin_rl.Robot) -> None:
    # Pinocchio ignores geom-inferred masses: each MuJoCo body mass must show up in Pinocchio too.
    model = robot.mj_model
    for body_id in range(1, model.nbody):
        name = model.body(body_id).name
        pin_joint = robot.pin_model.frames[robot.pin_model.getFrameId(name)].parentJoint
        assert model.body_mass[body_id] > 0, name
        assert robot.pin_model.inertias[pin_joint].mass == pytest.approx(model.body_mass[body_id]), name


def test_foot_positions_agree_at_random_configurations(robot: margin_rl.Robot) -> None:
    rng = np.random.default_rng(1)
    pin_data = robot.pin_model.createData()
    for q in random_joint_pos(robot, rng, 25):
        base_pos, quat = rng.normal(size=3), random_unit_quat(rng)
        data = mj_state(robot, base_pos, quat, q)
        pin.forwardKinematics(robot.pin_model, pin_data, robot.pin_configuration(q, base_pos, quat))
        pin.updateFramePlacements(robot.pin_model, pin_data)
        R = quat_wxyz_to_matrix(quat)
        closed_form = base_pos + robot.foot_positions(q) @ R.T
        for i, foot in enumerate(robot.foot_names):
            mj_foot = data.site(foot).xpos
            pin_foot = pin_data.oMf[robot.pin_model.getFrameId(foot)].translation
            np.testing.assert_allclose(pin_foot, mj_foot, atol=1e-10)
            np.testing.assert_allclose(closed_form[i], mj_foot, atol=1e-10)


def test_closed_form_com_agrees_with_pinocchio_and_mujoco(robot: margin_rl.Robot) -> None:
    """The batched closed-form CoM (used to sample millions of states) against two independent sources."""
    rng = np.random.default_rng(6)
    q = random_joint_pos(robot, rng, 20)
    batched = robot.com_positions(q)
    assert batched.shape == (20, 3)
    for qi, com in zip(q, batched, strict=True):
        np.testing.assert_allclose(com, robot.com_position(qi), atol=1e-12)  # Pinocchio
        data = mj_state(robot, np.zeros(3), np.array([1.0, 0, 0, 0]), qi)
        np.testing.assert_allclose(com, data.subtree_com[robot.mj_model.body("base").id], atol=1e-12)  # MuJoCo


def test_foot_jacobians_agree_with_mujoco_and_finite_differences(robot: margin_rl.Robot) -> None:
    rng = np.random.default_rng(2)
    for q in random_joint_pos(robot, rng, 10):
        quat = random_unit_quat(rng)
        R = quat_wxyz_to_matrix(quat)
        J = robot.leg_jacobians(q, base_rotation=R)
        data = mj_state(robot, np.zeros(3), quat, q)
        for i, foot in enumerate(robot.foot_names):
            jacp = np.zeros((3, robot.mj_model.nv))
            mujoco.mj_jacSite(robot.mj_model, data, jacp, None, robot.mj_model.site(foot).id)
            dofs = [robot.mj_model.joint(n).dofadr[0] for n in robot.joint_names[robot.leg_slice(robot.leg_names[i])]]
            np.testing.assert_allclose(J[i], jacp[:, dofs], atol=1e-10)
        # Central differences of the closed-form kinematics, in the base frame.
        J_base = robot.leg_jacobians(q)
        eps = 1e-6
        for k in range(12):
            dq = np.zeros(12)
            dq[k] = eps
            column = (robot.foot_positions(q + dq) - robot.foot_positions(q - dq)) / (2 * eps)
            leg, j = divmod(k, 3)
            np.testing.assert_allclose(J_base[leg][:, j], column[leg], atol=1e-7)


def test_gravity_torques_agree(robot: margin_rl.Robot) -> None:
    rng = np.random.default_rng(3)
    for q in random_joint_pos(robot, rng, 20):
        quat = random_unit_quat(rng)
        data = mj_state(robot, np.zeros(3), quat, q)  # qvel = 0, so qfrc_bias is pure gravity
        mj_tau = data.qfrc_bias[6:]
        pin_tau = pin.computeGeneralizedGravity(
            robot.pin_model, robot.pin_model.createData(), robot.pin_configuration(q, None, quat)
        )[6:]
        np.testing.assert_allclose(pin_tau, mj_tau, atol=1e-9)
        bias = robot.bias_torques(q, base_rotation=quat_wxyz_to_matrix(quat))
        np.testing.assert_allclose(bias.reshape(12), mj_tau, atol=1e-9)


def test_bias_torques_with_base_acceleration_match_mujoco_inverse_dynamics(robot: margin_rl.Robot) -> None:
    """delta_i = M_bi^T nu_dot + g_i, checked against MuJoCo's recursive Newton-Euler (mj_rne)."""
    rng = np.random.default_rng(4)
    model = robot.mj_model
    for q in random_joint_pos(robot, rng, 10):
        quat = random_unit_quat(rng)
        R = quat_wxyz_to_matrix(quat)
        com_acc, ang_acc = rng.normal(scale=3.0, size=3), rng.normal(scale=2.0, size=3)
        bias = robot.bias_torques(q, base_rotation=R, com_acc=com_acc, base_ang_acc=ang_acc)
        data = mj_state(robot, np.zeros(3), quat, q)
        com = data.subtree_com[model.body("base").id]
        # MuJoCo's free joint: linear acceleration of the body origin in world axes, angular in body axes.
        data.qacc[:] = 0.0
        data.qacc[0:3] = com_acc - np.cross(ang_acc, com - data.qpos[:3])
        data.qacc[3:6] = R.T @ ang_acc
        result = np.zeros(model.nv)
        mujoco.mj_rne(model, data, 1, result)
        np.testing.assert_allclose(bias.reshape(12), result[6:], atol=1e-8)
        # The free-joint force row checks the CoM-acceleration convention: it equals m (c_ddot - g)
        # (MuJoCo's free-joint linear DoFs are world-aligned).
        np.testing.assert_allclose(
            result[0:3], robot.total_mass * (com_acc - robot.mj_model.opt.gravity), rtol=1e-9, atol=1e-8
        )


def test_ik_round_trip_over_the_workspace(robot: margin_rl.Robot) -> None:
    rng = np.random.default_rng(5)
    q = random_joint_pos(robot, rng, 5000, spread=0.8)
    feet = robot.foot_positions(q)
    sol = robot.inverse_kinematics(feet)
    # Every foot position produced from a configuration on the standing knee branch is reachable.
    knee_branch = sol.reachable
    assert knee_branch.mean() > 0.95
    ok = np.all(sol.reachable, axis=-1)
    np.testing.assert_allclose(robot.foot_positions(sol.joint_pos[ok]), feet[ok], atol=1e-6)


def _straight_knee_angle(robot: margin_rl.Robot, i: int) -> float:
    """KFE angle psi at which thigh and shank are collinear in the sagittal plane (knee branch boundary)."""
    g = robot.legs[i]
    a, b = g.kfe_offset[[0, 2]], g.foot_offset[[0, 2]]
    return float(np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b))


@settings(max_examples=80, deadline=None)
@given(
    dq=st.tuples(st.floats(-0.45, 0.45), st.floats(-0.8, 0.8), st.floats(-0.7, 0.7)),
    leg=st.sampled_from(["LF", "RF", "LH", "RH"]),
    name=st.sampled_from(ROBOTS),
)
def test_ik_inverts_fk_on_the_standing_knee_branch(dq: tuple[float, float, float], leg: str, name: str) -> None:
    robot = _cached(name)
    i, sl = robot.leg_names.index(leg), robot.leg_slice(leg)
    full = robot.standing_joint_pos.copy()
    q_leg = np.clip(full[sl] + np.array(dq), robot.joint_lower[sl], robot.joint_upper[sl])
    psi = _straight_knee_angle(robot, i)
    # Only configurations on the standing pose's knee branch, away from the straight-knee singularity.
    assume(np.sin(q_leg[2] - psi) * np.sin(full[sl][2] - psi) > 0.05)
    full[sl] = q_leg
    target = robot.foot_positions(full)[i]
    q = robot.leg_ik(leg, target)
    np.testing.assert_allclose(q, q_leg, atol=1e-8)
    solved = full.copy()
    solved[sl] = q
    np.testing.assert_allclose(robot.foot_positions(solved)[i], target, atol=1e-6)


_ROBOT_CACHE: dict[str, margin_rl.Robot] = {}


def _cached(name: str) -> margin_rl.Robot:
    if name not in _ROBOT_CACHE:
        _ROBOT_CACHE[name] = load_robot(name)
    return _ROBOT_CACHE[name]


def test_unreachable_target_raises_and_batch_reports_status(robot: margin_rl.Robot) -> None:
    far = robot.foot_positions(robot.standing_joint_pos)[0] + np.array([0.0, 0.0, -1.0])
    with pytest.raises(UnreachableFootError, match="unreachable for leg LF"):
        robot.leg_ik("LF", far)
    feet = robot.foot_positions(robot.standing_joint_pos).copy()
    feet[2] += np.array([2.0, 0.0, 0.0])
    sol = robot.inverse_kinematics(feet)
    assert sol.reachable.tolist() == [True, True, False, True]
    assert np.isnan(sol.joint_pos[robot.leg_slice("LH")]).all()
    assert np.isfinite(sol.joint_pos[robot.leg_slice("LF")]).all()


def test_ik_respects_haa_limits_of_anymal_c() -> None:
    robot = _cached("anymal_c")
    q = robot.standing_joint_pos.copy()
    q[robot.leg_slice("LF")][0] = 0.0
    q[0] = robot.joint_upper[0] + 0.2  # LF_HAA beyond its 0.49 rad limit
    target = robot.foot_positions(q)[0]
    with pytest.raises(UnreachableFootError):
        robot.leg_ik("LF", target)


def test_ik_of_one_leg_one_state_and_a_batch_agree_bit_for_bit(robot: margin_rl.Robot) -> None:
    """leg_inverse_kinematics (one leg), inverse_kinematics of one state and of a batch run the same
    operations on differently shaped arrays: identical angles and statuses, unreachable legs included."""
    rng = np.random.default_rng(8)
    feet = robot.foot_positions(robot.standing_joint_pos) + rng.uniform(-0.3, 0.3, size=(400, 4, 3))
    for clip in (False, True):
        batch = robot.inverse_kinematics(feet, clip=clip)
        assert 0.1 < batch.reachable.mean() < 0.9  # both kinds of legs
        for k in range(0, 400, 8):
            one = robot.inverse_kinematics(feet[k], clip=clip)
            np.testing.assert_array_equal(one.joint_pos, batch.joint_pos[k])
            np.testing.assert_array_equal(one.reachable, batch.reachable[k])
    batch = robot.inverse_kinematics(feet)
    for i, g in enumerate(robot.legs):
        q, ok = leg_inverse_kinematics(g, feet[:, i])
        np.testing.assert_array_equal(q, batch.joint_pos[:, 3 * i : 3 * i + 3])
        np.testing.assert_array_equal(ok, batch.reachable[:, i])


def test_com_relative_ik_of_one_state_matches_a_batch_of_one(robot: margin_rl.Robot) -> None:
    """One state (Pinocchio CoM) and a batch of one (closed-form CoM) take the same fixed-point steps,
    and the converged configuration puts the reachable feet where they were asked, relative to its CoM."""
    rng = np.random.default_rng(9)
    q0 = robot.standing_joint_pos
    rel = robot.foot_positions(q0) - robot.com_position(q0) + rng.uniform(-0.12, 0.12, size=(60, 4, 3))
    for p in rel:
        one, com = robot.inverse_kinematics_com_relative(p)
        batch, com_batch = robot.inverse_kinematics_com_relative(p[None])
        np.testing.assert_allclose(com, com_batch[0], rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(one.joint_pos, batch.joint_pos[0], rtol=0.0, atol=1e-12)
        np.testing.assert_array_equal(one.reachable, batch.reachable[0])
        if one.reachable.all():
            q = one.joint_pos
            err = robot.foot_positions(q) - robot.com_position(q) - p
            assert np.abs(err).max() < 3e-5 + 1e-9
    with pytest.raises(ValueError, match="shape"):
        robot.inverse_kinematics_com_relative(np.zeros((3, 3)))


def test_jacobians_and_dynamics_equal_the_separate_methods(robot: margin_rl.Robot) -> None:
    rng = np.random.default_rng(10)
    for q in random_joint_pos(robot, rng, 5):
        R = quat_wxyz_to_matrix(random_unit_quat(rng))
        com_acc, ang_acc = rng.normal(size=3), rng.normal(size=3)
        jac, dyn = robot.jacobians_and_dynamics(q, R, com_acc, ang_acc)
        np.testing.assert_array_equal(jac, robot.leg_jacobians(q, base_rotation=R))
        ref = robot.rigid_body_dynamics(q, base_rotation=R, com_acc=com_acc, base_ang_acc=ang_acc)
        np.testing.assert_array_equal(dyn.bias_torques, ref.bias_torques)
        np.testing.assert_array_equal(dyn.ang_momentum_rate, ref.ang_momentum_rate)
        np.testing.assert_array_equal(dyn.com, ref.com)


def test_leg_ik_rejects_bad_arguments(robot: margin_rl.Robot) -> None:
    with pytest.raises(ValueError, match="unknown leg"):
        robot.leg_ik("XX", np.zeros(3))
    with pytest.raises(ValueError, match="shape"):
        robot.leg_ik("LF", np.zeros(2))
    with pytest.raises(ValueError, match="shape"):
        robot.inverse_kinematics(np.zeros((3, 3)))


def test_standing_keyframe_puts_feet_on_the_ground(robot: margin_rl.Robot) -> None:
    model = mujoco.MjModel.from_xml_path(str(robot.scene_path))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("standing").id)
    mujoco.mj_forward(model, data)
    lowest = [data.site(f).xpos[2] - robot.foot_radius for f in robot.foot_names]
    np.testing.assert_allclose(lowest, 0.0, atol=2e-5)


def test_stands_five_seconds_under_pd(robot: margin_rl.Robot) -> None:
    model = mujoco.MjModel.from_xml_path(str(robot.scene_path))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("standing").id)
    height0 = data.qpos[2]
    floor = model.geom("floor").id
    n_steps = round(5.0 / model.opt.timestep)
    for _ in range(n_steps):
        mujoco.mj_step(model, data)
        for contact in data.contact[: data.ncon]:
            pair = {contact.geom1, contact.geom2}
            if floor in pair:
                other = (pair - {floor}).pop()
                assert model.geom(other).name.endswith("_foot"), f"{model.geom(other).name} touched the floor"
    assert abs(data.qpos[2] - height0) < 0.02
    up = quat_wxyz_to_matrix(data.qpos[3:7])[:, 2]
    assert up[2] > 0.999
    assert np.all(np.abs(data.qvel) < 1e-2)


def test_standing_keyframe_ctrl_is_the_static_equilibrium(robot: margin_rl.Robot) -> None:
    from margin_rl.robot import standing_equilibrium_ctrl

    key_ctrl = robot.mj_model.key_ctrl[robot.mj_model.key("standing").id]
    np.testing.assert_allclose(key_ctrl, standing_equilibrium_ctrl(robot), atol=1e-4)


def test_pd_gains_and_limits_come_from_the_mjcf(robot: margin_rl.Robot) -> None:
    model = robot.mj_model
    for i, name in enumerate(robot.joint_names):
        assert robot.torque_limits[i] == model.actuator(name).forcerange[1]
        assert robot.kp[i] == model.actuator(name).gainprm[0]
    assert robot.torque_limits[0] == {"anymal_b": 40.0, "anymal_c": 80.0}[robot.name]
    assert robot.foot_radius == {"anymal_b": 0.031, "anymal_c": 0.03}[robot.name]


def test_unknown_robot_lists_available_robots() -> None:
    with pytest.raises(RobotModelError, match="available robots: anymal_b, anymal_c"):
        load_robot("anymal_x")


def test_missing_model_file_is_named(tmp_path: Path) -> None:
    missing = tmp_path / "nope.xml"
    with pytest.raises(RobotModelError, match=r"nope\.xml"):
        load_robot_from_xml(missing)


def test_malformed_model_file_is_named(tmp_path: Path) -> None:
    bad = tmp_path / "broken_robot.xml"
    bad.write_text("<mujoco><worldbody><body></mujoco>")
    with pytest.raises(RobotModelError, match=r"broken_robot\.xml"):
        load_robot_from_xml(bad)


def test_model_without_conventions_is_rejected_with_reason(tmp_path: Path) -> None:
    src = load_robot("anymal_b").xml_path
    text = src.read_text().replace('name="LF_FOOT"', 'name="LF_TOE"')
    broken = tmp_path / "renamed_site.xml"
    broken.write_text(text)
    with pytest.raises(RobotModelError, match="missing site LF_FOOT"):
        load_robot_from_xml(broken)


def test_report_runs(capsys: pytest.CaptureFixture[str]) -> None:
    from margin_rl.robot import main

    assert main(["anymal_b"]) == 0
    out = capsys.readouterr().out
    assert "anymal_b: 30.421 kg" in out
    assert "LF_HAA" in out


def test_robot_files_are_package_data() -> None:
    for name in ROBOTS:
        path = load_robot(name).xml_path
        assert path.is_file()
        assert shutil.os.path.basename(path.parent) == "anymal"


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0, allow_subnormal=False), min_size=4, max_size=4))
@example([0.0, 0.5, 0.75, 0.2609569815070091])  # where a 1-D norm's dot product and an axis reduction differ
def test_the_rotation_matrix_of_a_quaternion_is_mujocos_and_the_textbook_entries(quat: list[float]) -> None:
    """Against MuJoCo's mju_quat2Mat (to rounding) and, bit for bit, the textbook entries written out one by one
    (the numbers every earlier result was computed with)."""
    q = np.array(quat)
    assume(np.linalg.norm(q) > 1e-3)
    R = quat_wxyz_to_matrix(q)
    expected = np.zeros(9)
    mujoco.mju_quat2Mat(expected, q / np.linalg.norm(q))
    np.testing.assert_allclose(R, expected.reshape(3, 3), atol=1e-12)
    # normalised as the code before the torch form did (norm over an axis: a reduction; np.linalg.norm(q) of a 1-D
    # array is a dot product, which can differ in the last bit)
    w, x, y, z = q / np.linalg.norm(q, axis=-1, keepdims=True)
    textbook = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    assert R.tobytes() == textbook.tobytes()
    batch = quat_wxyz_to_matrix(np.stack([q, -q]))  # q and -q: one rotation
    assert batch.shape == (2, 3, 3) and batch.flags["C_CONTIGUOUS"]
    np.testing.assert_array_equal(batch[0], batch[1])
