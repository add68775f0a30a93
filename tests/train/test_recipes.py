"""Training recipes: declared once, applied by ``train --recipe`` with the command line's options on top."""

from __future__ import annotations

import pytest

from margin_rl.envs.config import CommandConfig
from margin_rl.train.commands import train as train_module
from margin_rl.train.recipes import RECIPES, TrainingRecipe, get_recipe, with_recipe


def _spec(*argv: str) -> train_module.TrainSpec:
    spec, _, _ = train_module.spec_from_args(train_module.build_parser().parse_args(list(argv)))
    return spec


def test_robust_recipe_sets_the_environment_size_and_steps() -> None:
    spec = _spec("--recipe", "robust", "--margin-weight", "0", "--seed", "3")
    config = spec.env_config
    assert spec.recipe == "robust" and spec.num_envs == 512 and spec.total_steps == RECIPES["robust"].total_steps
    assert config.command.forward_velocity == (0.2, 1.1) and config.margin_weight == 0.0 and spec.seed == 3
    randomization = config.randomization
    assert randomization.friction == (0.3, 1.25) and randomization.added_base_mass == (-5.0, 5.0)
    assert randomization.push_interval_s == 8.0 and randomization.push_force * randomization.push_duration_s == 30.0
    assert config.reward_params.alive_bonus == 0.1 and config.reward_params.knee_clearance == 5.0
    assert spec.to_json()["recipe"] == "robust"
    assert train_module.TrainSpec.from_json(spec.to_json()) == spec  # what --resume reads back


def test_both_variants_differ_only_in_the_margin_weight() -> None:
    baseline = _spec("--recipe", "robust", "--margin-weight", "0").env_config
    margin = _spec("--recipe", "robust").env_config
    assert margin.margin_weight == RECIPES["robust"].margin_weight > 0
    assert baseline.replace(margin_weight=margin.margin_weight) == margin


def test_options_given_replace_the_recipes() -> None:
    spec = _spec(
        "--recipe", "robust", "--num-envs", "64", "--total-steps", "1000",
        "--env-option", "reward_params.knee_clearance=1", "--env-option", 'command={"forward_velocity": [0.5, 0.5]}',
    )  # fmt: skip
    assert spec.num_envs == 64 and spec.total_steps == 1000
    params = spec.env_config.reward_params
    assert params.knee_clearance == 1.0 and params.alive_bonus == 0.1  # one reward entry changed, the other kept
    assert spec.env_config.command == CommandConfig(forward_velocity=(0.5, 0.5))
    assert spec.env_config.randomization.friction == (0.3, 1.25)  # what was not given stays the recipe's


def test_fixed_command_recipe_is_the_knee_term_experiment() -> None:
    recipe = _spec("--recipe", "fixed_command", "--margin-weight", "0.2")
    by_hand = _spec(
        "--recipe", "none", "--margin-weight", "0.2", "--num-envs", "128", "--total-steps", "5000000",
        "--env-option", "reward_params.knee_clearance=5",
    )  # fmt: skip
    assert recipe.env_config == by_hand.env_config and recipe.num_envs == 128 and recipe.total_steps == 5_000_000


def test_recipes_are_not_shared_mutable_state() -> None:
    options = with_recipe(get_recipe("robust"), {"reward_params": {"knee_clearance": 0.0}})
    options["reward_params"]["alive_bonus"] = 9.0
    assert get_recipe("robust").env_options["reward_params"] == {"alive_bonus": 0.1, "knee_clearance": 5.0}


def test_bad_recipes_are_clear_errors(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match=r"unknown training recipe 'fast'.*robust"):
        get_recipe("fast")
    with pytest.raises(SystemExit):
        train_module.build_parser().parse_args(["--recipe", "fast"])
    assert "fixed_command" in capsys.readouterr().err
    with pytest.raises(ValueError, match="num_envs must be an int >= 1"):
        TrainingRecipe("x", "", {}, num_envs=0, total_steps=1, margin_weight=0.2)
    with pytest.raises(ValueError, match="margin variant's weight"):
        TrainingRecipe("x", "", {}, num_envs=1, total_steps=1, margin_weight=0.0)
    with pytest.raises(ValueError, match="unknown training recipe"):
        train_module.TrainSpec(recipe="fast")


@pytest.mark.parametrize(("backend", "field"), [("rsl", "entropy_coef"), ("sb3", "ent_coef")])
def test_robust_recipe_trains_without_an_entropy_bonus_on_both_backends(backend: str, field: str) -> None:
    spec = _spec("--recipe", "robust", "--backend", backend)
    assert getattr(spec.ppo, field) == 0.0
    assert getattr(_spec("--recipe", "none", "--backend", backend).ppo, field) == 0.01  # the backend's: legged_gym's
    given = _spec("--recipe", "robust", "--backend", backend, "--ppo-option", f"{field}=0.005")
    assert getattr(given.ppo, field) == 0.005  # an option given replaces the recipe's
    assert train_module.TrainSpec.from_json(spec.to_json()) == spec


def test_compare_trains_its_runs_with_the_recipes_ppo_options() -> None:
    from margin_rl.train.commands import compare

    settings = compare.CompareSettings(env_id="margin_rl/AnymalB-v1", backend="rsl", recipe="robust")
    assert compare._run_spec(settings, 0.0, 0, {}).ppo.entropy_coef == 0.0
    plain = compare.CompareSettings(env_id="margin_rl/AnymalB-v1", backend="rsl")
    assert compare._run_spec(plain, 0.0, 0, {}).ppo.entropy_coef == 0.01


def test_recipe_ppo_options_are_keyed_by_backend() -> None:
    with pytest.raises(ValueError, match=r"keyed by backend \['rsl', 'sb3'\], got \['entropy_coef'\]"):
        TrainingRecipe("x", "", {}, num_envs=1, total_steps=1, margin_weight=0.2, ppo_options={"entropy_coef": 0.0})
    with pytest.raises(ValueError, match="unknown backend 'jax'"):
        get_recipe("robust").ppo_overrides("jax")
    assert get_recipe("fixed_command").ppo_overrides("rsl") == {}


def test_rough_recipe_is_the_robust_one_on_the_curriculum_with_perception() -> None:
    from margin_rl.envs.terrain import CURRICULUM_TERRAIN

    rough, robust = _spec("--recipe", "rough"), _spec("--recipe", "robust")
    config = rough.env_config
    assert config.terrain == "rough" and config.terrain_config == CURRICULUM_TERRAIN
    assert config.terrain_config.curriculum_levels == 9
    assert config.height_scan and config.privileged_observations and rough.total_steps == 25_000_000
    # the two terms the first pilots showed to be needed (docs/studies/rough_ground.md), on top of the robust ones
    assert config.reward_params == robust.env_config.reward_params.replace(termination_penalty=10.0, yaw_tracking=0.5)
    assert config.reward_weights["termination"] == -10.0 and config.reward_weights["yaw_tracking"] == 0.5
    flat = {"terrain": "flat", "terrain_config": robust.env_config.terrain_config}
    flat_fields = config.replace(
        **flat, height_scan=False, privileged_observations=False, reward_params=robust.env_config.reward_params
    )
    assert flat_fields == robust.env_config  # everything else as the robust recipe, the margin weight included
    assert rough.ppo == robust.ppo
    assert train_module.TrainSpec.from_json(rough.to_json()) == rough  # the curriculum survives config.json


def test_field_recipe_is_the_robust_one_with_the_fields_reward() -> None:
    from margin_rl.envs.config import REWARD_PRESETS

    field, robust = _spec("--recipe", "field"), _spec("--recipe", "robust")
    config = field.env_config
    assert config.reward_preset == "field" and field.total_steps == robust.total_steps == 10_000_000
    assert field.ppo == robust.ppo and field.num_envs == robust.num_envs
    # no alive bonus; the knee term at the robust recipe's size against the tracking kernel's peak (0.02 vs 0.25)
    assert config.reward_params.alive_bonus == 0.0
    assert config.reward_params.knee_clearance == pytest.approx(robust.env_config.reward_params.knee_clearance * 0.08)
    same = config.replace(reward_preset="paper", reward_params=robust.env_config.reward_params)
    assert same == robust.env_config  # commands, randomisation, pushes, the margin weight: the robust recipe's
    # the field's per-second weights times the 0.02 s policy step (legged_gym / Isaac Lab ANYmal C flat)
    per_second = {
        "tracking_lin_vel_xy": 1.0,
        "tracking_ang_vel_z": 0.5,
        "vertical_velocity": -2.0,
        "roll_pitch_rate": -0.05,
        "orientation": -5.0,
        "torques": -2.5e-5,
        "joint_acceleration": -2.5e-7,
        "action_rate": -0.01,
        "feet_air_time": 0.5,
        "collisions": -1.0,
    }
    preset = REWARD_PRESETS["field"]
    assert set(preset) == {*per_second, "margin"}
    assert config.decimation * 0.005 == pytest.approx(0.02)  # the MJCF's 5 ms timestep, 4 per policy step
    for name, weight in per_second.items():
        assert preset[name] == pytest.approx(weight * 0.02, rel=1e-12), name
    # the margin weighs against the tracking peak as in the paper's reward: w m / 0.25 there, 0.08 w m / 0.02 here
    assert preset["margin"] / 0.02 == pytest.approx(REWARD_PRESETS["paper"]["margin"] / 0.25)
    assert config.reward_weights["margin"] == pytest.approx(0.1 * 0.08)
    assert train_module.TrainSpec.from_json(field.to_json()) == field


def test_a_fixed_terrain_difficulty_sets_the_rough_tiles_at_that_scale() -> None:
    config = _spec("--terrain-difficulty", "0.5").env_config
    assert config.terrain == "rough" and config.terrain_config.curriculum_levels == 0
    assert config.terrain_config.step_height == (0.03, 0.09) and config.terrain_config.max_slope_deg == 7.5
    with pytest.raises(ValueError, match="difficulty must be a number in"):
        _spec("--terrain-difficulty", "1.5")
    with pytest.raises(ValueError, match="--terrain-difficulty sets terrain_config"):
        _spec("--terrain-difficulty", "0.5", "--env-option", 'terrain_config={"step_height": [0.0, 0.1]}')
