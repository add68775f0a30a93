"""Push recovery: protocol checks, push directions, survival counts, the report, plot and command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.envs.config import EnvConfig, RandomizationConfig
from margin_rl.train.artifacts.policies import LoadedPolicy
from margin_rl.train.commands.evaluate import evaluation_config
from margin_rl.train.commands.push_recovery import (
    PolicyPushes,
    PushProtocol,
    main,
    push_forces,
    push_recovery_report,
    push_schedule,
    run_pushes,
    survival_table,
    variant_survival,
)
from margin_rl.train.environments import AnymalTarget


def standing_policy() -> LoadedPolicy:
    """Zero actions: the servos hold the standing pose."""
    return LoadedPolicy("toy", Path("standing"), None, 12, lambda obs: np.zeros((len(obs), 12), np.float32))


def standing_target(toy_weights: str, forward_velocity: float = 0.0) -> AnymalTarget:
    config = EnvConfig(
        robot="anymal_b",
        margin_weights=toy_weights,
        randomization=RandomizationConfig(reset_joint_noise=0.0, reset_velocity_noise=0.0),
    )
    return AnymalTarget("margin_rl/AnymalB-v1", evaluation_config(config, forward_velocity))


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"impulses": ()}, "impulses"),
        ({"impulses": (-1.0,)}, "impulses"),
        ({"impulses": (np.nan,)}, "impulses"),
        ({"directions": ("vertical",)}, "directions"),
        ({"forward_velocities": ()}, "forward_velocities"),
        ({"episodes": 0}, "episodes"),
        ({"duration_s": 0.0}, "duration_s"),
        ({"push_window_s": (3.0, 2.0)}, "push_window_s"),
        ({"recovery_s": 0.05, "duration_s": 0.1}, "recovery_s"),
    ],
)
def test_protocol_rejects_bad_settings(changes: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        PushProtocol(**changes)


@settings(max_examples=50, deadline=None)
@given(
    impulse=st.floats(0.0, 500.0),
    sign=st.sampled_from([-1.0, 1.0]),
    duration=st.floats(0.01, 1.0),
    direction=st.sampled_from(["longitudinal", "lateral"]),
)
def test_push_force_times_duration_is_the_signed_impulse_along_its_axis(
    impulse: float, sign: float, duration: float, direction: str
) -> None:
    force = push_forces(direction, np.array([impulse]), np.array([sign]), duration)[0]
    axis = 0 if direction == "longitudinal" else 1
    assert force[axis] * duration == pytest.approx(sign * impulse, rel=1e-12, abs=1e-12)
    assert force[1 - axis] == 0.0 and force[2] == 0.0


def test_schedule_is_inside_the_window_and_depends_on_the_seed_only() -> None:
    protocol = PushProtocol(push_window_s=(1.0, 2.0))
    start, signs = push_schedule(protocol, 500, 0.02, np.random.default_rng(3))
    again, signs_again = push_schedule(protocol, 500, 0.02, np.random.default_rng(3))
    np.testing.assert_array_equal(start, again)
    np.testing.assert_array_equal(signs, signs_again)
    assert start.min() >= 50 and start.max() <= 100
    assert set(np.unique(signs)) == {-1.0, 1.0}


def test_a_standing_robot_survives_no_push_and_falls_to_a_huge_one(toy_weights: str) -> None:
    protocol = PushProtocol(
        impulses=(0.0, 400.0), episodes=3, push_window_s=(0.2, 0.4), recovery_s=1.0, forward_velocities=(0.0,)
    )
    for direction in ("longitudinal", "lateral"):
        curve = run_pushes(standing_policy(), standing_target(toy_weights), protocol, direction)
        assert curve.pushed == (3, 3) and curve.fell_before_push == (0, 0)
        assert curve.survived == (3, 0), direction  # 400 N s: about 13 m/s across a 30 kg robot
        assert curve.survival == (1.0, 0.0)


def _pushes(seed: int, survived: tuple[int, ...], pushed: tuple[int, ...]) -> PolicyPushes:
    from margin_rl.train.commands.push_recovery import SurvivalCurve

    curve = SurvivalCurve("lateral", 0.75, (0.0, 10.0), pushed, survived, (0, 0))
    return PolicyPushes(f"p{seed}", seed, (curve,))


def test_variant_survival_is_the_mean_and_std_over_policies() -> None:
    results = [_pushes(0, (4, 2), (4, 4)), _pushes(1, (4, 0), (4, 2)), _pushes(2, (3, 1), (4, 0))]
    s = variant_survival(results, "lateral", 0.75)
    # impulse 0: 1, 1, 0.75; impulse 10: 0.5, 0, (none pushed: left out)
    assert s["mean"][0] == pytest.approx(np.mean([1, 1, 0.75]))
    assert s["std"][0] == pytest.approx(np.std([1, 1, 0.75]))
    assert s["mean"][1] == pytest.approx(0.25) and s["std"][1] == pytest.approx(0.25)
    assert s["n_policies"] == 3
    protocol = PushProtocol(impulses=(0.0, 10.0), directions=("lateral",), forward_velocities=(0.75,))
    report = push_recovery_report({"with margin": results}, protocol)
    table = survival_table(report)
    assert table[2].startswith("| lateral, 0.75 m/s | with margin | 0.92 ± 0.12 | 0.25 ± 0.25 |")


def test_command_line_on_a_tiny_run(rsl_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    policy = str(rsl_run / "final_model.pt")
    out = tmp_path / "push"
    argv = [
        "--variant", "without margin", policy, "--variant", "with margin", policy, policy,
        "--impulses", "0", "30", "--episodes", "2", "--forward-velocities", "0.75", "--recovery-s", "0.3",
        "--out", str(out),
    ]  # fmt: skip
    assert main(argv) == 0
    report = json.loads((out / "push_recovery.json").read_text())
    assert set(report["variants"]) == {"without margin", "with margin"}
    assert len(report["variants"]["with margin"]["policies"]) == 2
    # the same policy, the same seed: the same counts in both variants
    a = report["variants"]["without margin"]["policies"][0]["curves"]
    b = report["variants"]["with margin"]["policies"][1]["curves"]
    assert a == b
    assert (out / "push_recovery.png").stat().st_size > 0
    assert "lateral, 0.75 m/s | with margin" in capsys.readouterr().out


def test_command_line_names_a_missing_policy(tmp_path: Path) -> None:
    with pytest.raises(SystemExit):
        main(["--variant", "with margin", str(tmp_path / "nope.pt"), "--out", str(tmp_path)])


def test_command_line_on_a_shipped_bundle(tmp_path: Path) -> None:
    """A bundle's policies are pushed in their training environments with the bundle's own margin weights."""
    argv = [
        "--bundled", "anymal_b", "--impulses", "0", "--episodes", "1", "--directions", "lateral",
        "--forward-velocities", "0.75", "--recovery-s", "0.5", "--out", str(tmp_path),
    ]  # fmt: skip
    assert main(argv) == 0
    report = json.loads((tmp_path / "push_recovery.json").read_text())
    assert report["env_overrides"]["margin_weights"].endswith(".npz")
    for variant in report["variants"].values():
        assert len(variant["policies"]) == 5
        assert variant["survival"]["lateral@0.75"]["mean"] == [1.0]  # no push: the bundled policies walk on
        assert all(policy["training_forward_velocity"] == [0.2, 1.1] for policy in variant["policies"])


def test_command_label_follows_the_policies_training_commands() -> None:
    from margin_rl.train.commands.push_recovery import command_label

    def report(*ranges):
        return {"variants": {"v": {"policies": [{"training_forward_velocity": r} for r in ranges]}}}

    fixed, robust = [0.75, 0.75], [0.2, 1.1]
    assert command_label(report(fixed, fixed), 0.75) == "trained"
    assert command_label(report(fixed, fixed), 1.0) == "untrained"
    assert command_label(report(robust, robust), 0.5) == "in the training range"
    assert command_label(report(robust, robust), 1.2) == "untrained"
    assert command_label(report(fixed, robust), 0.5) == ""  # mixed: no single answer
    assert command_label(report(fixed, None), 0.75) == ""  # a policy that does not record it
