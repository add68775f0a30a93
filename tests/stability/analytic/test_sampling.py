"""Table I sampler: seeded, every distribution as in the table, stance types, kinematic feasibility."""

from __future__ import annotations

import numpy as np
import pytest

from margin_rl import load_robot
from margin_rl.stability.analytic.lambda_state import from_lambda
from margin_rl.stability.analytic.sampling import TableI, nominal_feet, reachable, sample_states


@pytest.fixture(scope="module")
def robot():
    return load_robot("anymal_c")


@pytest.fixture(scope="module")
def raw(robot):
    return from_lambda(sample_states(robot, 20000, seed=3, reachable_only=False))


def test_seeded_and_deterministic(robot) -> None:
    a = sample_states(robot, 200, seed=7)
    np.testing.assert_array_equal(a, sample_states(robot, 200, seed=7))
    assert not np.array_equal(a, sample_states(robot, 200, seed=8))
    assert sample_states(robot, 0, seed=1).shape == (0, 47)


def test_stance_types_are_4_3_and_diagonal_2(raw) -> None:
    n_contacts = raw.contacts.sum(axis=1)
    assert set(np.unique(n_contacts)) == {2.0, 3.0, 4.0}
    for k in (2, 3, 4):
        assert abs(np.mean(n_contacts == k) - 1 / 3) < 0.02
    two = raw.contacts[n_contacts == 2]
    # Only diagonal pairs stand: LF+RH or RF+LH.
    assert np.all((two[:, 0] == two[:, 3]) & (two[:, 1] == two[:, 2]) & (two[:, 0] != two[:, 1]))
    three = raw.contacts[n_contacts == 3]
    lifted = np.argmax(three == 0, axis=1)
    assert np.all(np.abs(np.bincount(lifted, minlength=4) / len(lifted) - 0.25) < 0.03)


def test_distributions_follow_table_one(robot, raw) -> None:
    t = TableI()
    pitch = -np.arcsin(raw.gravity_axis[:, 0])
    roll = np.arctan2(raw.gravity_axis[:, 1], raw.gravity_axis[:, 2])
    for angle in (roll, pitch):
        assert angle.min() >= -t.roll_pitch_half_width and angle.max() <= t.roll_pitch_half_width
        assert abs(angle.std() - t.roll_pitch_half_width / np.sqrt(3)) < 0.01
    assert np.abs(raw.com_vel[:, :2]).max() <= 1.25 and abs(raw.com_vel[:, 2].std() - 0.2) < 0.01
    assert np.abs(raw.com_acc[:, :2]).max() <= 2.5 and np.abs(raw.com_acc[:, 2]).max() <= 1.25
    assert np.abs(raw.base_ang_acc[:, :2]).max() <= 1.0 and abs(raw.base_ang_acc[:, 2].std() - 0.5) < 0.02
    assert raw.mu.min() >= 0.2 and raw.mu.max() <= 0.9
    dev = raw.feet - nominal_feet(robot)
    assert np.abs(dev[..., 0]).max() <= 0.35 and np.abs(dev[..., 1:]).max() <= 0.2
    assert abs(dev[..., 0].std() - 0.35 / np.sqrt(3)) < 0.01
    np.testing.assert_allclose(np.linalg.norm(raw.normals, axis=-1), 1.0)
    tilt = np.arccos(raw.normals[..., 2])
    assert 0.3 < np.median(tilt) < 0.6  # two N(0, pi/8) tilts: median of the combined tilt ~ 0.46 rad
    assert abs(raw.ext_force.std() - 50) < 1.5 and abs(raw.ext_torque.std() - 25) < 0.8


def test_reachable_only_keeps_feasible_states(robot, raw) -> None:
    lam = sample_states(robot, 500, seed=11)
    assert reachable(robot, lam).all()
    # Raw Table I draws are mostly outside the leg workspace; the fraction is reported in the docs.
    frac = reachable(robot, raw.to_lambda()[:4000]).mean()
    assert 0.05 < frac < 0.2


def test_nominal_feet_are_relative_to_the_com(robot) -> None:
    q = robot.standing_joint_pos
    np.testing.assert_allclose(nominal_feet(robot), robot.foot_positions(q) - robot.com_position(q))
    assert np.all(nominal_feet(robot)[:, 2] < -0.4)


def test_bad_arguments(robot) -> None:
    with pytest.raises(ValueError, match="n must be"):
        sample_states(robot, -1, seed=0)
    with pytest.raises(ValueError, match="max_lifted_feet"):
        TableI(max_lifted_feet=3)


def _inside(values: np.ndarray, low: float, high: float) -> float:
    return float(np.mean((values >= low) & (values <= high)))


def test_locomotion_distribution_covers_the_measured_rollout_percentiles(robot) -> None:
    """LOCOMOTION's ranges contain the 0.5-99.5 percentiles measured on walking-policy rollouts (both robots)."""
    import json
    from pathlib import Path

    from margin_rl.stability.analytic.lambda_state import lambda_names
    from margin_rl.stability.analytic.sampling import LOCOMOTION

    names = lambda_names()
    t = LOCOMOTION
    half = {
        "com_acc.x": t.com_acc_xy_half_width, "com_acc.y": t.com_acc_xy_half_width, "com_acc.z": t.com_acc_z_half_width,
        "base_ang_acc.x": t.ang_acc_xy_half_width, "base_ang_acc.y": t.ang_acc_xy_half_width,
        "base_ang_acc.z": 2.5 * t.ang_acc_z_std, "com_vel.x": t.com_vel_xy_half_width,
        "com_vel.y": t.com_vel_xy_half_width, "com_vel.z": 3 * t.com_vel_z_std,
        "gravity_axis.x": np.sin(t.roll_pitch_half_width), "gravity_axis.y": np.sin(t.roll_pitch_half_width),
    }  # fmt: skip
    docs = Path(__file__).resolve().parents[3] / "docs" / "learned_margin"
    for name in ("anymal_b", "anymal_c"):
        measured = json.loads((docs / f"locomotion_distribution_{name}.json").read_text())["percentiles"]
        for component, h in half.items():
            assert -h <= measured["p0.5"][component] and measured["p99.5"][component] <= h, (name, component)
        assert t.mu_low <= measured["p0.5"]["mu"] and measured["p99.5"]["mu"] <= t.mu_high
        nominal = nominal_feet(load_robot(name))
        for leg, key in enumerate(("LF", "RF", "LH", "RH")):
            for k, axis in enumerate("xyz"):
                h = t.foot_x_half_width if axis == "x" else t.foot_yz_half_width
                lo, hi = measured["p0.5"][f"feet.{key}.{axis}"], measured["p99.5"][f"feet.{key}.{axis}"]
                assert nominal[leg, k] - h <= lo and hi <= nominal[leg, k] + h, (name, key, axis)
    assert set(names) >= set(half)


def test_locomotion_distribution_draws_every_support_and_wide_accelerations(robot) -> None:
    from margin_rl.stability.analytic.sampling import LOCOMOTION

    raw = from_lambda(sample_states(robot, 12000, seed=5, table=LOCOMOTION, reachable_only=False))
    patterns = {tuple(c) for c in raw.contacts.astype(int).tolist()}
    assert len(patterns) == 15 and (0, 0, 0, 0) not in patterns  # every non-empty set of feet, never none
    assert _inside(np.abs(raw.base_ang_acc[:, 0]), 200, 240) > 0.1  # uniform over +-240 rad/s^2
    assert np.abs(raw.com_acc[:, 2]).max() <= LOCOMOTION.com_acc_z_half_width
    assert raw.mu.max() > 1.0
    kept = sample_states(robot, 60, seed=5, table=LOCOMOTION)  # about 0.6 % of raw draws are reachable
    assert reachable(robot, kept).all()
    # Table I itself is unchanged by the new option: the same seed gives the same draws as before it existed.
    np.testing.assert_array_equal(
        sample_states(robot, 50, seed=7, reachable_only=False),
        sample_states(robot, 50, seed=7, table=TableI(contact_patterns="table_i"), reachable_only=False),
    )
    with pytest.raises(ValueError, match="contact_patterns"):
        TableI(contact_patterns="all")


def test_sample_around_states_follows_the_recorded_states(robot) -> None:
    from margin_rl.stability.analytic.sampling import RolloutJitter, sample_around_states

    recorded = sample_states(robot, 300, seed=11)
    exact = sample_around_states(robot, recorded, 200, seed=1, jitter=RolloutJitter(0.0, 0.0), reachable_only=False)
    rows = {tuple(np.round(r, 9)) for r in recorded}
    assert all(tuple(np.round(r, 9)) in rows for r in exact)  # no jitter: recorded states only
    drawn = sample_around_states(robot, recorded, 400, seed=2)
    np.testing.assert_array_equal(drawn, sample_around_states(robot, recorded, 400, seed=2))
    assert reachable(robot, drawn).all()
    st = from_lambda(drawn)
    np.testing.assert_allclose(np.linalg.norm(st.gravity_axis, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(st.normals, axis=-1), 1.0, atol=1e-12)
    assert st.mu.min() >= RolloutJitter().min_mu
    # The perturbation is about noise_fraction of each entry's spread over the recorded states.
    raw = sample_around_states(robot, recorded, 4000, seed=3, jitter=RolloutJitter(0.1, 0.0), reachable_only=False)
    spread = from_lambda(raw).com_acc.std(axis=0) / from_lambda(recorded).com_acc.std(axis=0)
    assert np.all((spread > 0.9) & (spread < 1.15))
    flipped = sample_around_states(robot, recorded, 4000, seed=4, jitter=RolloutJitter(0.0, 0.5), reachable_only=False)
    assert 0.3 < np.mean(from_lambda(flipped).contacts != 1.0) < 0.7  # Table I states: mostly feet down


def test_sample_around_states_refuses_bad_input(robot) -> None:
    from margin_rl.stability.analytic.sampling import RolloutJitter, sample_around_states

    good = sample_states(robot, 5, seed=1)
    with pytest.raises(ValueError, match="shape"):
        sample_around_states(robot, good[:, :40], 3, seed=0)
    with pytest.raises(ValueError, match="M >= 2"):
        sample_around_states(robot, good[:1], 3, seed=0)
    bad = good.copy()
    bad[0, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        sample_around_states(robot, bad, 3, seed=0)
    with pytest.raises(ValueError, match="non-negative"):
        sample_around_states(robot, good, -1, seed=0)
    for kwargs in ({"noise_fraction": -0.1}, {"contact_flip": 1.5}, {"min_mu": 0.0}):
        with pytest.raises(ValueError, match="RolloutJitter"):
            RolloutJitter(**kwargs)
