"""Tests of the resumable sharded data set generator."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from margin_rl.atomic import atomic_savez
from margin_rl.slip.dataset import DatasetConfig, generate_dataset, load_dataset, main
from margin_rl.slip.dynamics import SlipParams
from margin_rl.slip.margin import FailureMargin


def test_generation_is_resumable_and_deterministic(tmp_path: Path) -> None:
    cfg = DatasetConfig(n=2500, shard_size=1000, seed=3)
    first = generate_dataset(tmp_path / "a", cfg)
    assert first.generated == (0, 1, 2) and first.margin_recomputed
    data = load_dataset(tmp_path / "a")
    assert len(data) == 2500 and data.margin is not None

    again = generate_dataset(tmp_path / "a", cfg)
    assert again.generated == () and again.skipped == (0, 1, 2) and not again.margin_recomputed

    # A truncated shard (an interrupted non-atomic writer) is detected and regenerated.
    shard = tmp_path / "a" / "shard_00001.npz"
    shard.write_bytes(shard.read_bytes()[:100])
    repaired = generate_dataset(tmp_path / "a", cfg)
    assert repaired.generated == (1,)
    np.testing.assert_array_equal(load_dataset(tmp_path / "a").z, data.z)

    # Shards do not depend on the number of workers.
    generate_dataset(tmp_path / "b", cfg, workers=2)
    other = load_dataset(tmp_path / "b")
    np.testing.assert_array_equal(other.z, data.z)
    np.testing.assert_array_equal(other.status, data.status)
    np.testing.assert_array_equal(other.margin, data.margin)


def test_margins_match_failure_margin(tmp_path: Path) -> None:
    generate_dataset(tmp_path, DatasetConfig(n=1500, shard_size=700, seed=1))
    data = load_dataset(tmp_path)
    fm = FailureMargin.from_samples(data.z, data.valid)
    np.testing.assert_allclose(data.margin, fm.oriented_distance(data.z, data.valid))
    assert np.all((data.margin > 0) == data.valid)


def test_growing_n_reuses_shards(tmp_path: Path) -> None:
    generate_dataset(tmp_path, DatasetConfig(n=1000, shard_size=500, seed=2), margins=False)
    grown = generate_dataset(tmp_path, DatasetConfig(n=1800, shard_size=500, seed=2))
    assert grown.skipped == (0, 1) and grown.generated == (2, 3)
    assert len(load_dataset(tmp_path)) == 1800


def test_mismatched_configuration_is_refused(tmp_path: Path) -> None:
    generate_dataset(tmp_path, DatasetConfig(n=300, shard_size=300, seed=0), margins=False)
    with pytest.raises(ValueError, match="different configuration"):
        generate_dataset(tmp_path, DatasetConfig(n=300, shard_size=300, seed=1))
    with pytest.raises(ValueError, match="different configuration"):
        generate_dataset(tmp_path, DatasetConfig(n=300, shard_size=300, seed=0, params=SlipParams(friction=0.6)))


def test_atomic_savez_leaves_no_temporary_files(tmp_path: Path) -> None:
    atomic_savez(tmp_path / "x.npz", a=np.arange(3))
    assert [p.name for p in tmp_path.iterdir()] == ["x.npz"]
    with np.load(tmp_path / "x.npz", allow_pickle=False) as d:
        np.testing.assert_array_equal(d["a"], [0, 1, 2])


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="n must"):
        DatasetConfig(n=0)
    with pytest.raises(ValueError, match="shard_size"):
        DatasetConfig(n=10, shard_size=0)


def test_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--out", str(tmp_path), "--n", "400", "--shard-size", "250", "--seed", "4"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n"] == 400 and report["n_shards"] == 2
    assert sum(report["status_counts"].values()) == 400
