"""The policies shipped with the package (train/bundled/): intact, the right size for their environment, and
still walking in the current environment (a change of the observation layout or the dynamics breaks them)."""

from __future__ import annotations

import pytest

from margin_rl.train.bundle import bundled_names, load_bundle
from margin_rl.train.evaluate import evaluate
from margin_rl.train.policies import load_policy


def test_anymal_b_v1_bundle_is_shipped_with_both_variants_and_three_seeds() -> None:
    assert "anymal_b_v1" in bundled_names()
    bundle = load_bundle("anymal_b_v1")  # verifies every checksum
    variants = bundle.variants()
    assert set(variants) == {"without margin", "with margin"}
    assert variants["without margin"][0] == 0.0 and variants["with margin"][0] > 0.0
    assert all(len(policies) >= 3 for _, policies in variants.values())
    assert bundle.card["settings"]["env_id"] == "margin_rl/AnymalB-v0"
    assert bundle.card["provenance"]["commit"] not in ("", "unknown")


def test_bundle_carries_the_learned_margin_its_policies_were_trained_with() -> None:
    """The policies' reward used these weights and the card's margin column is measured with them, so the
    bundle stays reproducible when the package's own anymal_b weights are retrained."""
    from margin_rl.stability import LearnedMargin

    bundle = load_bundle("anymal_b_v1")  # also checks every policy's recorded weights against the carried copy
    assert bundle.margin_weights is not None and bundle.margin_weights.is_file()
    carried = LearnedMargin.load(bundle.margin_weights)
    for entry in bundle.card["policies"]:
        assert entry["learned_margin"]["sha256"] == carried.card["sha256"]
    assert bundle.env_overrides() == {"margin_weights": str(bundle.margin_weights)}


@pytest.mark.parametrize("variant", ["without margin", "with margin"])
def test_bundled_policy_walks_at_the_commanded_speed(variant: str, tmp_path) -> None:
    bundle = load_bundle("anymal_b_v1")
    _, policies = bundle.variants()[variant]
    seed, path = policies[0]
    policy = load_policy(path)
    assert policy.train_config is not None and policy.train_config["env_id"] == "margin_rl/AnymalB-v0"
    report, _ = evaluate(path, episodes=2, seed=7, forward_velocity=0.75, max_steps=200, out_dir=tmp_path)
    s = report["summary"]
    assert s["fell"]["mean"] == 0.0, f"bundled {variant} policy (seed {seed}) fell within 4 s"
    assert s["velocity_error_mean"]["mean"] < 0.15, s["velocity_error_mean"]
