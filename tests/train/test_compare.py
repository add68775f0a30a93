"""compare: both variants, one seed, a tiny budget: PNG, Markdown and JSON with the table's metrics."""

from __future__ import annotations

import json
from pathlib import Path

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
