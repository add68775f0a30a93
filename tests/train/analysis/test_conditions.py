"""Evaluation conditions: a policy trained with randomisation is measured without it, in named worlds."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.envs.config import EnvConfig, RandomizationConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.robot import load_robot
from margin_rl.train.analysis.conditions import (
    CONDITIONS,
    base_mass,
    check_condition,
    condition_config,
    nominal_randomization,
)

TRAINING = EnvConfig(
    robot="anymal_b",
    randomization=RandomizationConfig(
        friction=(0.3, 1.25),
        added_base_mass=(-5.0, 5.0),
        push_interval_s=8.0,
        observation_noise=1.0,
        reset_joint_noise=0.05,
    ),
)


def test_nominal_turns_the_training_randomisation_off_and_keeps_the_reset_noise() -> None:
    nominal = condition_config(TRAINING, "nominal").randomization
    assert nominal.friction is None and nominal.added_base_mass is None and nominal.push_interval_s is None
    assert nominal.observation_noise == 0.0 and nominal.reset_joint_noise == 0.05
    assert condition_config(EnvConfig(), "nominal") == EnvConfig()  # nothing to remove: the same environment
    assert condition_config(TRAINING, "training") == TRAINING


@pytest.mark.parametrize("name", sorted(CONDITIONS))
def test_every_condition_but_training_measures_the_margin_on_the_terrain_normals(name: str) -> None:
    """A policy trained on upright normals (the ablation) is measured on the seed's margin, like every other."""
    upright = TRAINING.replace(terrain="rough", margin_normals="vertical")
    expected = "vertical" if name == "training" else "terrain"
    assert condition_config(upright, name).margin_normals == expected


@pytest.mark.parametrize("mu", [0.4, 1.0])
def test_friction_conditions_set_the_floor_in_every_environment(mu: float) -> None:
    config = condition_config(TRAINING, f"friction_{mu}")
    assert config.randomization.friction == (mu, mu) and config.randomization.push_interval_s is None
    core = AnymalCore(config, num_envs=3, seed=0)
    core.reset()
    assert (core.mu == mu).all()


@pytest.mark.parametrize(("name", "factor"), [("mass_-20", 0.8), ("mass_+20", 1.2)])
def test_mass_conditions_scale_the_base_body_of_the_mjcf(name: str, factor: float) -> None:
    robot = load_robot("anymal_b")
    mass = float(robot.mj_model.body("base").mass[0])
    assert base_mass("anymal_b") == pytest.approx(mass) and 16.0 < mass < 20.0  # read from the MJCF by name
    config = condition_config(TRAINING, name)
    core = AnymalCore(config, num_envs=2, seed=0)  # the per-environment mass, as MuJoCo simulates it
    masses = core.physics.per_env_field("body_mass")[:, robot.mj_model.body("base").id]
    assert masses == pytest.approx(factor * mass)
    assert config.randomization.friction is None and config.randomization.push_interval_s is None


def test_unknown_condition_names_the_conditions() -> None:
    with pytest.raises(ValueError, match=r"unknown evaluation condition 'icy'.*friction_0\.4"):
        check_condition("icy")
    with pytest.raises(ValueError, match="unknown evaluation condition"):
        condition_config(TRAINING, "icy")
    assert set(CONDITIONS) >= {"nominal", "friction_0.4", "friction_1.0", "mass_-20", "mass_+20", "training"}


_pairs = st.tuples(st.floats(0.0, 2.0), st.floats(0.0, 2.0)).map(sorted).map(tuple)


@settings(max_examples=60, deadline=None)
@given(
    friction=st.none() | _pairs,
    mass=st.none() | st.tuples(st.floats(-5.0, 0.0), st.floats(0.0, 5.0)),
    interval=st.none() | st.floats(0.5, 20.0),
    noise=st.floats(0.0, 2.0),
    joint_noise=st.floats(0.0, 0.5),
    velocity_noise=st.floats(0.0, 0.5),
)
def test_nominal_removes_every_randomisation_and_keeps_the_initial_states(
    friction, mass, interval, noise, joint_noise, velocity_noise
) -> None:
    training = RandomizationConfig(
        friction=friction,
        added_base_mass=mass,
        push_interval_s=interval,
        observation_noise=noise,
        reset_joint_noise=joint_noise,
        reset_velocity_noise=velocity_noise,
    )
    nominal = nominal_randomization(training)
    assert (nominal.friction, nominal.added_base_mass, nominal.push_interval_s, nominal.observation_noise) == (
        None, None, None, 0.0,
    )  # fmt: skip
    assert (nominal.reset_joint_noise, nominal.reset_velocity_noise) == (joint_noise, velocity_noise)
    assert nominal_randomization(nominal) == nominal  # idempotent
    for name in CONDITIONS:
        if name != "training":  # no condition but "training" lets a training push through
            assert condition_config(EnvConfig(randomization=training), name).randomization.push_interval_s is None
