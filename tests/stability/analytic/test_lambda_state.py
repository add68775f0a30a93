"""lambda layout (seed 000 eq. 4): one declaration, converters both ways, frames."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.stability.analytic.lambda_state import (
    LAMBDA_DIM,
    LAMBDA_FIELDS,
    LAMBDA_SLICES,
    StabilityState,
    base_rotation_from_gravity_axis,
    check_lambda,
    from_lambda,
    gravity_axis_from_roll_pitch,
    lambda_names,
    mirror_lambda,
)


def test_layout_is_eq4() -> None:
    assert LAMBDA_DIM == 47
    assert [f.name for f in LAMBDA_FIELDS] == [
        "gravity_axis",
        "com_vel",
        "com_acc",
        "base_ang_acc",
        "ext_force",
        "ext_torque",
        "feet",
        "mu",
        "contacts",
        "normals",
    ]
    names = lambda_names()
    assert len(names) == 47 and len(set(names)) == 47
    assert names[LAMBDA_SLICES["mu"]] == ("mu",)
    assert names[LAMBDA_SLICES["feet"]][3:6] == ("feet.RF.x", "feet.RF.y", "feet.RF.z")


def test_round_trip_single_and_batch() -> None:
    rng = np.random.default_rng(0)
    lam = rng.normal(size=(5, 47))
    np.testing.assert_array_equal(from_lambda(lam).to_lambda(), lam)
    np.testing.assert_array_equal(from_lambda(lam[0]).to_lambda(), lam[0])
    state = from_lambda(lam)
    assert state.feet.shape == (5, 4, 3) and state.mu.shape == (5,) and state.contacts.shape == (5, 4)
    np.testing.assert_array_equal(state.feet[:, 2], lam[:, LAMBDA_SLICES["feet"]].reshape(5, 4, 3)[:, 2])


def test_to_lambda_rejects_wrong_field_shape() -> None:
    state = from_lambda(np.zeros(47))
    bad = StabilityState(**{**state.__dict__, "feet": np.zeros((3, 3))})
    with pytest.raises(ValueError, match="feet"):
        bad.to_lambda()


def test_check_lambda_names_the_bad_field() -> None:
    lam = np.zeros((2, 47))
    lam[1, LAMBDA_SLICES["com_acc"].start + 1] = np.nan
    lam[0, LAMBDA_SLICES["normals"].stop - 1] = np.inf
    with pytest.raises(ValueError, match=r"com_acc\.y.*normals\.RH\.z|normals\.RH\.z.*com_acc\.y"):
        check_lambda(lam)
    with pytest.raises(ValueError, match="shape"):
        check_lambda(np.zeros(46))


@settings(max_examples=50, deadline=None)
@given(roll=st.floats(-1.2, 1.2), pitch=st.floats(-1.2, 1.2), yaw=st.floats(-3.1, 3.1))
def test_gravity_axis_matches_mujoco_orientation(roll: float, pitch: float, yaw: float) -> None:
    """e_g is the third row of R whatever the yaw; R_HB reproduces it with zero heading."""
    R = np.zeros(9)
    # Build R = Rz(yaw) Ry(pitch) Rx(roll) from three elementary MuJoCo quaternions (independent path).
    q = np.array([1.0, 0, 0, 0])
    for axis, angle in ((np.array([0, 0, 1.0]), yaw), (np.array([0, 1.0, 0]), pitch), (np.array([1.0, 0, 0]), roll)):
        dq = np.zeros(4)
        mujoco.mju_axisAngle2Quat(dq, axis, angle)
        out = np.zeros(4)
        mujoco.mju_mulQuat(out, q, dq)
        q = out
    mujoco.mju_quat2Mat(R, q)
    R = R.reshape(3, 3)
    e_g = gravity_axis_from_roll_pitch(roll, pitch)
    np.testing.assert_allclose(e_g, R[2], atol=1e-12)
    R_hb = base_rotation_from_gravity_axis(e_g)
    np.testing.assert_allclose(R_hb[2], R[2], atol=1e-12)
    np.testing.assert_allclose(R_hb @ R_hb.T, np.eye(3), atol=1e-12)
    # Zero heading: the base x axis, seen in H, has no y component.
    assert abs(R_hb[1, 0]) < 1e-12


def test_gravity_axis_must_be_unit() -> None:
    with pytest.raises(ValueError, match="unit vector"):
        base_rotation_from_gravity_axis(np.array([0.0, 0.0, 2.0]))
    with pytest.raises(ValueError, match="unit vector"):
        base_rotation_from_gravity_axis(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0]]))
    with pytest.raises(ValueError, match="unit vector"):
        base_rotation_from_gravity_axis(np.array([np.nan, 0.0, 1.0]))


def test_base_rotation_of_one_axis_matches_the_batch_bit_for_bit() -> None:
    """One gravity axis takes its own (scalar) code path; it must give the batch's bits exactly."""
    rng = np.random.default_rng(0)
    e = gravity_axis_from_roll_pitch(rng.uniform(-0.6, 0.6, 300), rng.uniform(-0.6, 0.6, 300))
    e *= rng.uniform(1.0 - 9e-4, 1.0 + 9e-4, size=(300, 1))  # within the unit-norm tolerance
    e = np.vstack([e, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]])
    batch = base_rotation_from_gravity_axis(e)
    for axis, R in zip(e, batch, strict=True):
        np.testing.assert_array_equal(base_rotation_from_gravity_axis(axis), R)


def test_mirror_flips_polar_y_axial_xz_and_swaps_left_right_legs() -> None:
    """A hand-built state and its mirror image, field by field."""
    feet = np.arange(12.0).reshape(4, 3) + 1
    normals = np.arange(12.0).reshape(4, 3) + 20
    state = StabilityState(
        gravity_axis=np.array([0.1, 0.2, 0.97]),
        com_vel=np.array([1.0, 2.0, 3.0]),
        com_acc=np.array([4.0, 5.0, 6.0]),
        base_ang_acc=np.array([7.0, 8.0, 9.0]),
        ext_force=np.array([10.0, 11.0, 12.0]),
        ext_torque=np.array([13.0, 14.0, 15.0]),
        feet=feet,
        mu=np.array(0.6),
        contacts=np.array([1.0, 0.0, 0.0, 1.0]),
        normals=normals,
    )
    lam = state.to_lambda()
    before = lam.copy()
    m = from_lambda(mirror_lambda(lam))
    np.testing.assert_array_equal(lam, before)  # input untouched
    np.testing.assert_array_equal(m.gravity_axis, [0.1, -0.2, 0.97])
    np.testing.assert_array_equal(m.com_vel, [1.0, -2.0, 3.0])
    np.testing.assert_array_equal(m.com_acc, [4.0, -5.0, 6.0])
    np.testing.assert_array_equal(m.ext_force, [10.0, -11.0, 12.0])
    np.testing.assert_array_equal(m.base_ang_acc, [-7.0, 8.0, -9.0])  # axial: x and z flip
    np.testing.assert_array_equal(m.ext_torque, [-13.0, 14.0, -15.0])
    swap = [1, 0, 3, 2]  # LF <-> RF, LH <-> RH
    np.testing.assert_array_equal(m.feet, feet[swap] * [1, -1, 1])
    np.testing.assert_array_equal(m.normals, normals[swap] * [1, -1, 1])
    np.testing.assert_array_equal(m.contacts, [0.0, 1.0, 1.0, 0.0])
    assert float(m.mu) == 0.6


def test_mirror_of_a_torque_is_the_torque_of_the_mirrored_force() -> None:
    """Axial parity checked against physics: tau = r x f transforms like the mirror says."""
    rng = np.random.default_rng(3)
    r, f = rng.normal(size=3), rng.normal(size=3)
    flip = np.diag([1.0, -1.0, 1.0])
    torque = np.cross(r, f)
    lam = StabilityState(
        gravity_axis=np.array([0.0, 0.0, 1.0]), com_vel=np.zeros(3), com_acc=np.zeros(3), base_ang_acc=np.zeros(3),
        ext_force=f, ext_torque=torque, feet=np.zeros((4, 3)), mu=np.array(0.5), contacts=np.ones(4),
        normals=np.tile([0.0, 0.0, 1.0], (4, 1)),
    ).to_lambda()  # fmt: skip
    mirrored = from_lambda(mirror_lambda(lam))
    np.testing.assert_allclose(mirrored.ext_torque, np.cross(flip @ r, flip @ f), atol=1e-12)
    np.testing.assert_allclose(mirrored.ext_force, flip @ f)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5))
def test_mirror_is_an_involution_on_batches(seed: int, n: int) -> None:
    lam = np.random.default_rng(seed).normal(size=(n, LAMBDA_DIM))
    np.testing.assert_array_equal(mirror_lambda(mirror_lambda(lam)), lam)
    np.testing.assert_array_equal(mirror_lambda(lam[0]), mirror_lambda(lam)[0])


def test_mirror_refuses_a_wrong_shape() -> None:
    with pytest.raises(ValueError, match="last dimension 47"):
        mirror_lambda(np.zeros(46))
