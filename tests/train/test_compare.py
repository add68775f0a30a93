"""compare: both variants, one seed, a tiny budget: PNG, Markdown and JSON with the table's metrics."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from margin_rl.train.compare import main
from margin_rl.train.metrics import SUMMARY_METRICS


def test_compare_writes_png_markdown_and_json(tmp_path: Path, toy_weights: str) -> None:
    out = tmp_path / "cmp"
    args = [
        "--backend", "rsl", "--seeds", "1", "--num-envs", "8", "--total-steps", "192", "--eval-episodes", "2",
        "--warmup-s", "0.1", "--margin-weight", "2", "--margin-weights", toy_weights, "--out", str(out),
        "--env-option", "episode_length_s=0.4", "--no-progress",
    ]  # fmt: skip
    assert main(args) == 0
    report = json.loads((out / "compare.json").read_text())
    assert set(report["variants"]) == {"without margin", "with margin"}
    assert report["variants"]["without margin"]["margin_weight"] == 0.0
    assert report["variants"]["with margin"]["margin_weight"] == 2.0
    for variant in report["variants"].values():
        assert set(SUMMARY_METRICS) <= set(variant["mean"]) and set(SUMMARY_METRICS) <= set(variant["std"])
        assert len(variant["runs"]) == 1 and Path(variant["runs"][0]["policy"]).is_file()
        assert all(v is not None for v in variant["mean"].values())  # finite: the baseline's margin too
    markdown = (out / "compare.md").read_text()
    assert "| without margin | 0 |" in markdown and "| with margin | 2 |" in markdown and "compare.png" in markdown
    assert (out / "compare.png").stat().st_size > 10_000
    # A second call reuses the finished runs instead of training again.
    assert main(args) == 0
    assert len(list((out / "runs").glob("*/checkpoints/*.pt"))) == 2


def test_bundle_round_trip_evaluates_like_the_runs(tmp_path: Path, toy_weights: str) -> None:
    """compare --bundle copies the TorchScript actors with a card; --bundled evaluates them to the same metrics
    as the rsl-rl checkpoints they were exported from (two independent loaders of one policy)."""
    from margin_rl.train.bundle import CARD_FILE, load_bundle

    out, bundle_dir = tmp_path / "cmp", tmp_path / "bundle"
    args = [
        "--backend", "rsl", "--seeds", "1", "--num-envs", "8", "--total-steps", "192", "--eval-episodes", "2",
        "--warmup-s", "0.1", "--margin-weight", "2", "--margin-weights", toy_weights, "--out", str(out),
        "--env-option", "episode_length_s=0.4", "--no-progress", "--bundle", str(bundle_dir),
    ]  # fmt: skip
    assert main(args) == 0
    bundle = load_bundle(bundle_dir)
    assert {v: (w, [s for s, _ in p]) for v, (w, p) in bundle.variants().items()} == {
        "without margin": (0.0, [0]),
        "with margin": (2.0, [0]),
    }
    card = json.loads((bundle_dir / CARD_FILE).read_text())
    assert card["provenance"]["command"].startswith("margin-rl-compare") and card["provenance"]["commit"]
    assert "| without margin |" in (bundle_dir / "CARD.md").read_text()
    assert all(e["learned_margin"]["source"] == toy_weights for e in card["policies"])  # margin weights recorded

    evaluated = tmp_path / "evaluated"
    assert main(["--bundled", str(bundle_dir), "--out", str(evaluated)]) == 0
    trained = json.loads((out / "compare.json").read_text())["variants"]
    from_bundle = json.loads((evaluated / "compare.json").read_text())["variants"]
    for name, variant in trained.items():
        for key in SUMMARY_METRICS:
            a, b = variant["mean"][key], from_bundle[name]["mean"][key]
            assert (a is None and b is None) or abs(a - b) <= 1e-4 * (1 + abs(a)), (name, key, a, b)

    # A changed policy file is refused, naming the file.
    policy = bundle.runs[0].policy
    policy.write_bytes(policy.read_bytes() + b"\0")
    with pytest.raises(ValueError, match="checksum mismatch"):
        load_bundle(bundle_dir)


def test_unknown_bundle_is_a_clear_error(tmp_path: Path) -> None:
    from margin_rl.train.bundle import load_bundle

    with pytest.raises(ValueError, match="no policy bundle 'nope'"):
        load_bundle("nope")
