"""The contact problem (one state is a batch of one) and the batched labelling path against the per-state path."""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from margin_rl.robot import load_robot
from margin_rl.stability.analytic.contact_problem import ContactProblem, contact_problem
from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES, base_rotation_from_gravity_axis, from_lambda
from margin_rl.stability.analytic.margin import (
    STATUSES,
    AnalyticSettings,
    _stance_programs,
    analytic_margin,
    analytic_margin_batch,
)
from margin_rl.stability.analytic.sampling import sample_states, standing_state
from margin_rl.stability.geometry.contact import CentroidalLoad, validate_contact_arrays
from margin_rl.stability.geometry.region_batch import ProgramStructure
from margin_rl.stability.geometry.region_program import build_program
from margin_rl.stability.learned.dataset import DatasetError, DatasetSpec, generate, load_dataset

PER_STATE = AnalyticSettings(labelling="per_state")
BATCHED = AnalyticSettings(labelling="batched")


@pytest.mark.parametrize("robot_name", ["anymal_b", "anymal_c"])
def test_batched_labels_agree_with_the_per_state_path(robot_name: str) -> None:
    """Same statuses, margins within the focus bracket (0.5 mm), on random Table I states.

    Both paths solve the same programs in the same order of directions; they differ in rounding (the
    batch's vectorised assembly and IK, the re-used solver's equilibration), which the focused
    projection can turn into a different refinement inside its bracket. Measured: max |dm| 0.12-0.3 mm.
    """
    lams = sample_states(load_robot(robot_name), 300, seed=17)
    old = analytic_margin_batch(robot_name, lams, PER_STATE, workers=1)
    new = analytic_margin_batch(robot_name, lams, BATCHED, workers=1)
    np.testing.assert_array_equal(new.status, old.status)
    ok = old.status == STATUSES.index("ok")
    assert ok.sum() > 100
    assert np.isnan(new.margin[~ok]).all()
    assert np.abs(new.margin[ok] - old.margin[ok]).max() < 0.5e-3
    assert np.median(np.abs(new.margin[ok] - old.margin[ok])) < 1e-5


def test_batched_labels_do_not_depend_on_how_the_states_are_cut() -> None:
    """Every state is solved through the same solver update, so a label is the same in any batch."""
    lams = sample_states(load_robot("anymal_c"), 40, seed=3)
    whole = analytic_margin_batch("anymal_c", lams, BATCHED, workers=1)
    pieces = analytic_margin_batch("anymal_c", lams, BATCHED, workers=1, chunk_size=7)
    np.testing.assert_array_equal(pieces.status, whole.status)
    np.testing.assert_array_equal(pieces.margin, whole.margin)
    np.testing.assert_array_equal(pieces.n_lps, whole.n_lps)


@pytest.mark.parametrize("robot_name", ["anymal_b", "anymal_c"])
def test_one_state_is_a_batch_of_one(robot_name: str) -> None:
    """A state's problem does not depend on its batch: ``problem[i]`` of a batch equals the batch of one, to
    rounding (each state stops its CoM fixed point on its own; BLAS rounds the small matrix products of 1 and of
    N rows differently in the last bit on a few states in a thousand)."""
    robot = load_robot(robot_name)
    lams = sample_states(robot, 40, seed=8)
    whole = contact_problem(robot, lams)
    assert len(whole) == 40 and whole.solvable.sum() >= 30
    for i in range(len(lams)):
        alone, part = contact_problem(robot, lams[i : i + 1])[0], whole[i]
        for f in fields(ContactProblem):
            mine, theirs = getattr(alone, f.name), getattr(part, f.name)
            if isinstance(mine, np.ndarray) and mine.dtype.kind == "f":
                np.testing.assert_allclose(mine, theirs, rtol=1e-12, atol=1e-12, err_msg=f.name)
            else:
                np.testing.assert_array_equal(mine, theirs, err_msg=f.name)


def test_contact_problem_matches_the_robots_own_com_relative_ik() -> None:
    """Cross-check against an independent path: the robot's batched CoM fixed point
    (``Robot.inverse_kinematics_com_relative``), Pinocchio's Jacobians at its joint angles and the
    gravito-inertial wrench of :class:`CentroidalLoad`."""
    robot = load_robot("anymal_b")
    lams = sample_states(robot, 30, seed=8)
    problems = contact_problem(robot, lams)
    for i, lam in enumerate(lams):
        problem = problems[i]
        if problem.status != "ok":
            continue
        st = from_lambda(lam)
        R = base_rotation_from_gravity_axis(st.gravity_axis)
        ik, _ = robot.inverse_kinematics_com_relative(st.feet @ R, 10, 3e-5)
        # The same CoM fixed-point iterate (another iterate differs by ~1e-5 rad), up to rounding.
        np.testing.assert_allclose(problem.joint_pos, ik.joint_pos, atol=1e-12)
        jacobians, dynamics = robot.jacobians_and_dynamics(
            ik.joint_pos, base_rotation=R, com_acc=st.com_acc, base_ang_acc=st.base_ang_acc
        )
        np.testing.assert_allclose(problem.jacobians, jacobians, atol=1e-12)
        np.testing.assert_allclose(problem.leg_bias, dynamics.bias_torques, atol=1e-9)
        load = CentroidalLoad(robot.total_mass, st.com_acc, dynamics.ang_momentum_rate, st.ext_force, st.ext_torque)
        np.testing.assert_allclose(problem.wrench, load.wrench(), atol=1e-9)
        np.testing.assert_allclose(problem.wrench, problem.load().wrench(), atol=1e-12)
        z = problem.com_height
        np.testing.assert_allclose(problem.capture_point, st.com_vel[:2] * np.sqrt(z / robot.gravity), atol=1e-15)


def test_contact_problem_statuses_and_messages() -> None:
    robot = load_robot("anymal_c")
    lam = standing_state(robot)
    airborne = lam.copy()
    airborne[LAMBDA_SLICES["contacts"]] = 0.0
    far = lam.copy()
    far[LAMBDA_SLICES["feet"].start] += 2.0  # the first foot 2 m away: no leg reaches it
    problems = contact_problem(robot, np.stack([lam, airborne, far]))
    assert [problems[i].status for i in range(3)] == ["ok", "no_contact", "unreachable"]
    assert problems[1].message == "no foot in contact"
    assert problems[2].message == f"unreachable feet: {robot.leg_names[0]}"
    assert problems[0].message == "" and problems.solvable.tolist() == [True, False, False]
    with pytest.raises(ValueError, match="lam\\[None\\]"):
        contact_problem(robot, lam)
    with pytest.raises(TypeError, match="single state"):
        problems[0][0]


@pytest.mark.parametrize("friction", [0, 6])
def test_program_values_are_those_of_the_single_state_assembly(friction: int) -> None:
    """On the fixed structure, A's values and b equal region_program.build_program's of each state (whose A
    leaves out the entries that happen to be zero)."""
    robot = load_robot("anymal_c")
    lams = sample_states(robot, 40, seed=4)
    batch = contact_problem(robot, lams)
    n_stance = batch.stance.sum(axis=1)
    checked = 0
    for n in (2, 3, 4):
        states = np.flatnonzero(batch.solvable & (n_stance == n))
        if states.size == 0:
            continue
        structure = ProgramStructure.of(n, 3, friction)
        values, b = _stance_programs(batch, states, structure, 0.01, 10.0)
        for j, i in enumerate(states):
            pts, nrm, jac, lo, hi, bias, _ = validate_contact_arrays(
                batch.contact_points[i], batch.normals[i], batch.stance[i], batch.jacobians[i], batch.torque_limits,
                batch.leg_bias[i],
            )  # fmt: skip
            w = batch.wrench[i]
            ref = build_program(pts, nrm, batch.mu[i], jac, lo, hi, bias, w[:3], w[3:], friction, 0.01, 10.0)
            np.testing.assert_array_equal(structure.matrix(values[j]).toarray(), ref.A.toarray())
            np.testing.assert_array_equal(b[j], ref.b)
            assert [repr(c) for c in structure.cones()] == [repr(c) for c in ref.cones]
            checked += 1
    assert checked > 10


def test_focused_projection_refines_a_focus_inside_a_cap() -> None:
    """A focus between the inner and outer polygon, equally far from a cap's two boundaries, used to be
    left with a 10 mm bracket (converged False); the cap holding it is now refined."""
    robot = load_robot("anymal_b")
    lam = sample_states(robot, 600, seed=3)[144]
    result = analytic_margin(robot, lam)
    assert result.status == "ok" and result.region is not None
    lo, hi = result.region.margin_bounds or (np.nan, np.nan)
    assert result.region.converged and hi - lo <= AnalyticSettings().focus_tol


def test_settings_record_the_labelling_path() -> None:
    assert AnalyticSettings().labelling == "batched"
    assert AnalyticSettings().as_dict()["labelling"] == "batched"
    recorded_before = {k: v for k, v in PER_STATE.as_dict().items() if k != "labelling"}
    assert AnalyticSettings.from_dict(recorded_before).labelling == "per_state"  # what made those labels
    with pytest.raises(ValueError, match="labelling must be one of"):
        AnalyticSettings(labelling="fast")


def test_dataset_manifest_names_the_path_and_old_manifests_resume_per_state(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    spec = DatasetSpec("anymal_c", n=6, shard_size=3, seed=1, settings=BATCHED)
    generate(spec, out, workers=1, progress=False)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["analytic_settings"]["labelling"] == "batched"
    assert "--labelling batched" in manifest["command"]
    assert len(load_dataset(out).margin) > 0

    # A manifest written before the path was recorded: per-state labels.
    old = tmp_path / "old"
    generate(DatasetSpec("anymal_c", n=3, shard_size=3, seed=1, settings=PER_STATE), old, workers=1, progress=False)
    manifest = json.loads((old / "manifest.json").read_text())
    del manifest["analytic_settings"]["labelling"]
    (old / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="pass --labelling per_state"):
        generate(DatasetSpec("anymal_c", n=6, shard_size=3, seed=1, settings=BATCHED), old, progress=False)
    generate(DatasetSpec("anymal_c", n=6, shard_size=3, seed=1, settings=PER_STATE), old, workers=1, progress=False)
    assert json.loads((old / "manifest.json").read_text())["analytic_settings"]["labelling"] == "per_state"
