"""The policies shipped with the package (train/bundled/): intact, the right size for their environment, and
still walking in the current environment (a change of the observation layout or the dynamics breaks them)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from margin_rl.train.artifacts.bundle import bundled_names, load_bundle
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import evaluate

# The ids the bundles stored: the robust recipe's margin policies (weight 0.1, trained with the v6 learned margin)
# beside the baselines of the bundles before them (their training never read a network)
SHIPPED = {
    "anymal_b": "margin_rl/AnymalB-v1",
    "anymal_c": "margin_rl/AnymalC-v1",
    "anymal_c_rough": "margin_rl/AnymalC-Rough-v1",  # the rough recipe's perceptive policies, three seeds each
    "anymal_b_field": "margin_rl/AnymalB-v1",  # the field's reward with and without the margin, five seeds each
    "anymal_c_field": "margin_rl/AnymalC-v1",
}
FLAT = {name: env_id for name, env_id in SHIPPED.items() if "Rough" not in env_id}
SLOW = {("anymal_b_field", "with margin"): 0.40}
"""The velocity error [m/s] a bundle's first policy is held to where it is known to walk slower than commanded (else
0.15): B's field-reward margin policy of seed 0 walks 0.42 m/s at 0.75 (docs/studies/field_reward.md)."""
V0_RUN = Path(__file__).resolve().parents[2] / "fixtures" / "v0_run" / "config.json"
"""The config.json of a run stored under a retired -v0 id (the first comparison's, margin seed 0): runs and bundles
of that time must still resume and evaluate."""


def test_a_run_stored_under_a_retired_id_is_read_as_the_current_one() -> None:
    from margin_rl.train.commands.train import TrainSpec
    from margin_rl.train.environments import anymal_id

    stored = json.loads(V0_RUN.read_text())
    assert stored["env_id"] == "margin_rl/AnymalB-v0" and "recipe" not in stored
    spec = TrainSpec.from_json(stored)  # what --resume and compare --runs read
    assert anymal_id(spec.env_id) == "margin_rl/AnymalB-v1"
    assert spec.env_config.margin_weight == 0.2 and spec.num_envs == 128 and spec.total_steps == 5_000_000


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_every_bundled_policys_training_command_rebuilds_its_config(name: str) -> None:
    """Re-running the command a card records for a policy trains that policy's run again: the spec it parses to
    today is the one its stored config.json loads as (environment, PPO, sizes, seed, recipe; fields added to the
    configs since default to what the run had)."""
    import shlex

    from margin_rl.train.commands.train import TrainSpec, build_parser, spec_from_args

    bundle = load_bundle(name)
    for entry in bundle.card["policies"]:
        program, *argv = shlex.split(entry["training_command"])
        assert program == "margin-rl-train", entry["training_command"]
        rebuilt, _, resume = spec_from_args(build_parser().parse_args(argv))
        stored = TrainSpec.from_json(json.loads((bundle.path / entry["config"]).read_text()))
        assert not resume and rebuilt.to_json() == stored.to_json(), entry["policy"]


@pytest.mark.parametrize(("name", "env_id"), sorted(SHIPPED.items()))
def test_bundle_is_shipped_with_both_variants_and_several_seeds(name: str, env_id: str) -> None:
    assert name in bundled_names()
    bundle = load_bundle(name)  # verifies every checksum
    variants = bundle.variants()
    assert set(variants) == {"without margin", "with margin"}
    assert variants["without margin"][0] == 0.0 and variants["with margin"][0] > 0.0
    assert all(len(policies) >= 3 for _, policies in variants.values())
    assert bundle.card["settings"]["env_id"] == env_id
    assert bundle.card["provenance"]["commit"] not in ("", "unknown")


@pytest.mark.parametrize("name", ["anymal_b", "anymal_c"])
def test_robust_bundle_card_has_every_command_and_the_history_it_replaced(name: str) -> None:
    """The shipped B and C bundles: five seeds per variant of the robust recipe, evaluated at the three commands
    in four conditions with each cell's tests, and the fixed-command bundle they replaced kept in ``history``."""
    card = load_bundle(name).card
    assert card["settings"]["recipe"] == "robust" and len(card["policies"]) == 10
    cells = {(cell["condition"], cell["forward_velocity"]) for cell in card["grid"]}
    assert {("nominal", 0.5), ("nominal", 1.0), ("mass_+20", 0.75)} <= cells and len(cells) == 11
    assert all("lin_acc_rms" in cell["statistics"] for cell in card["grid"])
    first = card["history"][-1]  # the fixed-command bundle the robust ones replaced; newer ones above it
    assert first["settings"]["total_steps"] == 5_000_000 and first["settings"].get("recipe") is None
    assert all(set(earlier["table"]) == {"without margin", "with margin"} for earlier in card["history"])


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_bundle_carries_the_learned_margin_its_policies_were_trained_with(name: str) -> None:
    """The policies' reward used these weights and the card's margin column is measured with them, so the
    bundle stays reproducible when the package's own weights are retrained."""
    from margin_rl.stability import LearnedMargin

    bundle = load_bundle(name)  # also checks every margin policy's recorded weights against the carried copy
    assert bundle.margin_weights is not None and bundle.margin_weights.is_file()
    carried = LearnedMargin.load(bundle.margin_weights)
    for entry in bundle.card["policies"]:  # baselines (weight 0) may have loaded an older network: never rewarded
        if entry["margin_weight"] > 0:
            assert entry["learned_margin"]["sha256"] == carried.card["sha256"]
        else:
            assert len(entry["learned_margin"]["sha256"]) == 64
    assert bundle.env_overrides()["margin_weights"] == str(bundle.margin_weights)
    # the rough bundle is evaluated on its card's fixed-difficulty terrain, the flat ones on their own ground
    evaluation_terrain = {"terrain", "terrain_config"} if name not in FLAT else set()
    assert set(bundle.env_overrides()) == {"margin_weights", *evaluation_terrain}


@pytest.mark.parametrize("variant", ["without margin", "with margin"])
@pytest.mark.parametrize(("name", "env_id"), sorted(FLAT.items()))
def test_bundled_policy_walks_at_the_commanded_speed(name: str, env_id: str, variant: str, tmp_path) -> None:
    bundle = load_bundle(name)
    _, policies = bundle.variants()[variant]
    seed, path = policies[0]
    policy = load_policy(path)
    assert policy.train_config is not None and policy.train_config["env_id"] == env_id
    report, _ = evaluate(path, episodes=2, seed=7, forward_velocity=0.75, max_steps=200, out_dir=tmp_path)
    s = report["summary"]
    assert s["fell"]["mean"] == 0.0, f"{name}: bundled {variant} policy (seed {seed}) fell within 4 s"
    assert s["velocity_error_mean"]["mean"] < SLOW.get((name, variant), 0.15), s["velocity_error_mean"]


@pytest.mark.parametrize("name", ["anymal_b_field", "anymal_c_field"])
def test_field_bundle_card_is_the_five_seed_comparison_on_the_fields_reward(name: str) -> None:
    """The field-reward bundles (docs/studies/field_reward.md): the field recipe's five seeds per variant at margin
    weight 0.1, evaluated at the three commands in the four conditions with each cell's tests."""
    card = load_bundle(name).card
    assert card["settings"]["recipe"] == "field" and len(card["policies"]) == 10
    assert sorted(card["settings"]["seeds"]) == [0, 1, 2, 3, 4]
    assert {entry["margin_weight"] for entry in card["policies"]} == {0.0, 0.1}
    cells = {(cell["condition"], cell["forward_velocity"]) for cell in card["grid"]}
    assert {("nominal", 0.5), ("nominal", 1.0), ("friction_0.4", 0.75), ("mass_-20", 1.0)} <= cells
    assert len(cells) == 11 and all("lin_acc_rms" in cell["statistics"] for cell in card["grid"])


def test_rough_bundle_card_is_the_three_seed_comparison_on_a_fixed_terrain() -> None:
    """The rough bundle: the rough recipe's three seeds per variant, evaluated at difficulty 0.75 (steps 4.5-13.5 cm)
    at 0.75 m/s and 0.5 m/s with each cell's tests, the terrain columns in its table."""
    card = load_bundle("anymal_c_rough").card
    assert card["settings"]["recipe"] == "rough" and len(card["policies"]) == 6
    assert sorted(card["settings"]["seeds"]) == [0, 1, 2]
    terrain = card["eval_env_overrides"]
    assert terrain["terrain"] == "rough" and terrain["terrain_config"]["step_height"] == pytest.approx([0.045, 0.135])
    assert [(cell["condition"], cell["forward_velocity"]) for cell in card["grid"]] == [("nominal", 0.5)]
    assert {"fell", "termination/tilt", "edge_landing_fraction", "lin_acc_rms"} <= set(card["statistics"])


@pytest.mark.parametrize("variant", ["without margin", "with margin"])
def test_rough_bundled_policy_walks_a_mild_terrain_with_its_height_scan(variant: str, tmp_path: Path) -> None:
    """Each variant's first rough policy, blind to nothing it was trained on (the height scan), walks 4 s of
    difficulty-0.25 tiles at 0.5 m/s without falling."""
    from margin_rl.envs.terrain import TerrainConfig, at_difficulty

    bundle = load_bundle("anymal_c_rough")
    seed, path = bundle.variants()[variant][1][0]
    policy = load_policy(path)
    assert policy.train_config is not None and policy.train_config["env_config"]["height_scan"] is True
    overrides = {**bundle.env_overrides(), "terrain_config": at_difficulty(TerrainConfig(), 0.25)}
    report, _ = evaluate(
        path, env_overrides=overrides, episodes=2, seed=7, forward_velocity=0.5, max_steps=200, out_dir=tmp_path
    )
    s = report["summary"]
    assert s["fell"]["mean"] == 0.0, f"rough {variant} policy (seed {seed}) fell within 4 s on difficulty 0.25"
    assert s["velocity_error_mean"]["mean"] < 0.2, s["velocity_error_mean"]
