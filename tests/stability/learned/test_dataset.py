"""Dataset generation: sharded, atomic, resumable, worker-count independent, refuses mixing settings."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from margin_rl.robot import load_robot
from margin_rl.stability.analytic.margin import STATUSES, AnalyticSettings, analytic_margin
from margin_rl.stability.learned.dataset import DatasetError, DatasetSpec, generate, load_dataset, main, shard_path

SPEC = DatasetSpec(robot="anymal_b", n=50, shard_size=20, seed=3, settings=AnalyticSettings())


def shards(path: Path) -> list[Path]:
    return sorted(path.glob("shard_*.npz"))


def test_generate_resume_and_labels(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    counts = generate(SPEC, out, workers=1, progress=False)
    assert sum(counts.values()) == 50 and len(shards(out)) == 3
    assert not list(out.glob(".*tmp")), "temporary files left behind"
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["robot"] == "anymal_b" and manifest["sampler_version"] >= 1 and manifest["seed"] == 3
    assert manifest["package_version"] and manifest["analytic_settings"]["friction"] == "cone"
    # Labels are the analytic margins of the stored states.
    robot = load_robot("anymal_b")
    with np.load(shard_path(out, 0)) as data:
        lam, margin, status = data["lam"], data["margin"], data["status"]
    for i in range(5):
        result = analytic_margin(robot, lam[i].astype(np.float64))
        assert STATUSES[status[i]] == result.status
        if result.status == "ok":
            assert margin[i] == pytest.approx(result.margin, abs=2e-4)  # lambda stored as float32
    # A rerun skips finished shards (files untouched) and reports nothing new.
    mtimes = [p.stat().st_mtime_ns for p in shards(out)]
    again = generate(SPEC, out, workers=1, progress=False)
    assert sum(again.values()) == 0 and [p.stat().st_mtime_ns for p in shards(out)] == mtimes


def test_lost_and_truncated_shards_are_remade_identically(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    generate(SPEC, out, workers=2, progress=False)
    reference = tmp_path / "reference.npz"
    reference.write_bytes(shard_path(out, 1).read_bytes())
    shard_path(out, 1).unlink()
    shard_path(out, 2).write_bytes(b"truncated")
    counts = generate(SPEC, out, workers=1, progress=False)
    assert sum(counts.values()) == 20 + 10
    # Each shard has its own seed, so it is remade identically whatever the number of workers.
    with np.load(shard_path(out, 1)) as remade, np.load(reference) as original:
        np.testing.assert_array_equal(remade["lam"], original["lam"])
        np.testing.assert_array_equal(remade["margin"], original["margin"])


def test_other_settings_are_refused(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    generate(SPEC, out, workers=1, progress=False)
    other = DatasetSpec(robot="anymal_b", n=50, shard_size=20, seed=4, settings=AnalyticSettings())
    with pytest.raises(DatasetError, match="seed"):
        generate(other, out, workers=1, progress=False)
    smaller = DatasetSpec(robot="anymal_b", n=30, shard_size=20, seed=3, settings=AnalyticSettings())
    with pytest.raises(DatasetError, match="at least"):
        generate(smaller, out, workers=1, progress=False)
    bigger = DatasetSpec(robot="anymal_b", n=60, shard_size=20, seed=3, settings=AnalyticSettings())
    counts = generate(bigger, out, workers=1, progress=False)
    assert sum(counts.values()) == 20  # the partial last shard is remade at full length
    assert sum(load_dataset(out).counts.values()) == 60


def test_load_dataset_keeps_ok_and_counts_the_rest(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    generate(SPEC, out, workers=1, progress=False)
    ds = load_dataset(out)
    assert sum(ds.counts.values()) == 50
    assert len(ds.lam) == ds.counts["ok"] == len(ds.margin)
    assert np.all(np.isfinite(ds.margin))
    with pytest.raises(DatasetError, match="not a margin_rl dataset"):
        load_dataset(tmp_path)


def test_bad_requests(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="unknown robot"):
        generate(DatasetSpec("anymal_x", 10, 5, 0, AnalyticSettings()), tmp_path / "a", progress=False)
    with pytest.raises(DatasetError, match="positive"):
        generate(DatasetSpec("anymal_b", 0, 5, 0, AnalyticSettings()), tmp_path / "b", progress=False)


def test_cli_generate_and_summary(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cli"
    assert (
        main(
            [
                "generate",
                "--robot",
                "anymal_c",
                "--n",
                "12",
                "--shard-size",
                "6",
                "--out",
                str(out),
                "--workers",
                "1",
                "--quiet",
            ]
        )
        == 0
    )
    assert main(["summary", str(out)]) == 0
    text = capsys.readouterr().out
    assert "12 samples" in text and "anymal_c" in text


@pytest.mark.slow
def test_ray_path_with_a_local_instance(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    out_ray, out_local = tmp_path / "ray", tmp_path / "local"
    generate(SPEC, out_ray, ray_address="local", progress=False)
    generate(SPEC, out_local, workers=1, progress=False)
    for a, b in zip(shards(out_ray), shards(out_local), strict=True):
        with np.load(a) as x, np.load(b) as y:
            np.testing.assert_array_equal(x["lam"], y["lam"])
            np.testing.assert_array_equal(x["status"], y["status"])


def test_distribution_is_recorded_and_not_mixed(tmp_path: Path) -> None:
    from dataclasses import replace

    from margin_rl.stability.analytic.sampling import LOCOMOTION, sample_states

    out = tmp_path / "loco"
    spec = replace(SPEC, n=10, shard_size=10, distribution="locomotion")
    generate(spec, out, workers=1, progress=False)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["distribution"] == "locomotion" and "--distribution locomotion" in manifest["command"]
    with np.load(shard_path(out, 0)) as data:
        expected = sample_states(load_robot("anymal_b"), 10, np.random.SeedSequence(3, spawn_key=(0,)), LOCOMOTION)
        np.testing.assert_array_equal(data["lam"], expected.astype(np.float32))
    with pytest.raises(DatasetError, match="distribution"):
        generate(replace(spec, distribution="table_i"), out, workers=1, progress=False)
    with pytest.raises(DatasetError, match="distribution must be one of"):
        replace(SPEC, distribution="walking")
    # A manifest written before distributions were named is read as Table I and resumes.
    old = tmp_path / "old"
    generate(SPEC, old, workers=1, progress=False)
    manifest = json.loads((old / "manifest.json").read_text())
    del manifest["distribution"]
    (old / "manifest.json").write_text(json.dumps(manifest))
    assert sum(generate(SPEC, old, workers=1, progress=False).values()) == 0


def test_rollouts_distribution_names_its_states_file(tmp_path: Path) -> None:
    from dataclasses import replace

    from margin_rl.provenance import sha256_file
    from margin_rl.stability.analytic.sampling import sample_around_states, sample_states

    recorded = sample_states(load_robot("anymal_b"), 50, seed=9)
    states = tmp_path / "rollouts.npz"
    np.savez(states, lam=recorded.astype(np.float32))
    out = tmp_path / "ds"
    spec = replace(SPEC, n=10, shard_size=10, distribution="rollouts", states=str(states),
                   states_sha256=sha256_file(states))  # fmt: skip
    generate(spec, out, workers=1, progress=False)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["distribution"] == "rollouts" and manifest["states_sha256"] == sha256_file(states)
    with np.load(shard_path(out, 0)) as data:
        expected = sample_around_states(
            load_robot("anymal_b"), recorded.astype(np.float32), 10, np.random.SeedSequence(3, spawn_key=(0,))
        )
        np.testing.assert_array_equal(data["lam"], expected.astype(np.float32))
    np.savez(states, lam=recorded[::-1].astype(np.float32))  # other recorded states: another dataset
    with pytest.raises(DatasetError, match="states_sha256"):
        generate(replace(spec, states_sha256=sha256_file(states)), out, workers=1, progress=False)
    with pytest.raises(DatasetError, match="needs --states"):
        replace(SPEC, distribution="rollouts")
    with pytest.raises(DatasetError, match="needs --states"):
        replace(SPEC, states=str(states))


def test_shards_carry_the_extended_margin_and_load_by_target(tmp_path: Path) -> None:
    from margin_rl.stability.analytic.extended import SOURCES, extended_margin_batch

    out = tmp_path / "ds"
    generate(SPEC, out, workers=1, progress=False)
    with np.load(shard_path(out, 0)) as data:
        lam, status, extended, source = data["lam"], data["status"], data["extended"], data["source"]
        margin, load_fraction = data["margin"], data["load_fraction"]
    ok = status == STATUSES.index("ok")
    # m_x is m_a on ok states and has a value on every state with a stance (Table I has no unreachable ones here).
    np.testing.assert_array_equal(extended[ok], margin[ok])
    assert np.isfinite(extended).all() and (source[~ok] != SOURCES.index("analytic")).all()
    assert (load_fraction[ok] == 1.0).all()
    # The same labels as the module computes on the stored (float32) states.
    again = extended_margin_batch(load_robot("anymal_b"), lam[:8].astype(np.float64))
    np.testing.assert_allclose(again.margin, extended[:8], atol=2e-3)
    analytic, both = load_dataset(out), load_dataset(out, target="extended")
    assert len(analytic.lam) == analytic.counts["ok"] and len(both.lam) == 50
    assert np.isnan(both.analytic).sum() == 50 - analytic.counts["ok"]
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["format_version"] == 2 and manifest["extended_margin"]["bisection_steps"] >= 1
    with pytest.raises(DatasetError, match="target must be one of"):
        load_dataset(out, target="both")


def test_a_format_1_dataset_cannot_train_the_extended_target(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    generate(SPEC, out, workers=1, progress=False)
    for path in shards(out):  # strip the m_x columns, as a dataset labelled before them has none
        with np.load(path) as data:
            kept = {k: data[k] for k in ("lam", "margin", "status", "n_lps", "seconds")}
        np.savez(path, **kept)
    assert len(load_dataset(out).lam) > 0
    with pytest.raises(DatasetError, match="format-1 dataset"):
        load_dataset(out, target="extended")


def _same_shards(a: Path, b: Path) -> None:
    assert [p.name for p in shards(a)] == [p.name for p in shards(b)]
    for left, right in zip(shards(a), shards(b), strict=True):
        with np.load(left) as x, np.load(right) as y:
            assert sorted(x.files) == sorted(y.files)
            for key in x.files:
                np.testing.assert_array_equal(x[key], y[key], err_msg=f"{left.name}: {key}")


def test_labels_packed_without_states_unpack_to_the_same_dataset(tmp_path: Path) -> None:
    from margin_rl.stability.learned.dataset import pack_labels, unpack_labels

    out = tmp_path / "ds"
    generate(SPEC, out, workers=1, progress=False)
    # Two packs (shards 0-1, then 2), restored in either order on the command line.
    first = pack_labels(out, tmp_path / "a.npz", max_shards=2)
    second = pack_labels(out, tmp_path / "b.npz", first_shard=2)
    assert (first.shards, first.samples, second.shards, second.samples) == (2, 40, 1, 10)
    assert (tmp_path / "a.npz").stat().st_size < 0.3 * sum(p.stat().st_size for p in shards(out))
    assert main(["unpack", str(tmp_path / "b.npz"), str(tmp_path / "a.npz"), "--out", str(tmp_path / "back"),
                 "--quiet"]) == 0  # fmt: skip
    _same_shards(out, tmp_path / "back")
    manifest = json.loads((tmp_path / "back" / "manifest.json").read_text())
    assert manifest["n"] == 50 and manifest["seed"] == 3 and "generate --robot anymal_b --n 50" in manifest["command"]
    # Generating the unpacked directory's dataset here finds every shard present: it is that dataset.
    assert sum(generate(SPEC, tmp_path / "back", workers=1, progress=False).values()) == 0
    # A rerun of an unpack into a complete directory rewrites nothing.
    mtimes = [p.stat().st_mtime_ns for p in shards(tmp_path / "back")]
    restored = unpack_labels(tmp_path / "a.npz", tmp_path / "back", progress=False)
    assert restored.exact_shards == 2 and [p.stat().st_mtime_ns for p in shards(tmp_path / "back")] == mtimes


def test_a_pack_ends_at_the_first_missing_shard(tmp_path: Path) -> None:
    from margin_rl.stability.learned.dataset import pack_labels

    out = tmp_path / "ds"
    generate(SPEC, out, workers=1, progress=False)
    shard_path(out, 1).write_bytes(b"in flight")
    assert pack_labels(out, tmp_path / "p.npz").shards == 1
    with pytest.raises(DatasetError, match="shard 1 is not complete"):
        pack_labels(out, tmp_path / "q.npz", first_shard=1)
    with pytest.raises(DatasetError, match="not a margin_rl dataset"):
        pack_labels(tmp_path, tmp_path / "r.npz")


def test_unpack_refuses_states_that_were_not_the_labelled_ones(tmp_path: Path) -> None:
    from dataclasses import replace

    from margin_rl.provenance import sha256_file
    from margin_rl.stability.analytic.sampling import sample_states
    from margin_rl.stability.learned.dataset import pack_labels, unpack_labels

    out = tmp_path / "ds"
    generate(SPEC, out, workers=1, progress=False)
    pack_labels(out, tmp_path / "p.npz")
    with np.load(tmp_path / "p.npz") as data:
        tampered = {key: data[key] for key in data.files}
    tampered["row_sum"] = tampered["row_sum"] + 1e-3  # as if the labels belonged to other states
    tampered["lam_sha256"] = np.array(["0" * 64] * len(tampered["lam_sha256"]))
    np.savez(tmp_path / "t.npz", **tampered)
    with pytest.raises(DatasetError, match="shard 0: the states drawn here differ"):
        unpack_labels(tmp_path / "t.npz", tmp_path / "back", progress=False)
    assert not shards(tmp_path / "back")
    # Another machine's rounding: checksums differ but every row sum agrees -> accepted, counted as not exact.
    tampered["row_sum"] = tampered["row_sum"] - 1e-3
    np.savez(tmp_path / "r.npz", **tampered)
    rounded = unpack_labels(tmp_path / "r.npz", tmp_path / "rounded", progress=False)
    assert rounded.exact_shards == 0 and rounded.max_row_sum_deviation <= 1e-5
    _same_shards(out, tmp_path / "rounded")
    # A rollouts dataset needs the recorded states it was drawn around, and exactly those.
    states = tmp_path / "rollouts.npz"
    np.savez(states, lam=sample_states(load_robot("anymal_b"), 30, seed=9).astype(np.float32))
    spec = replace(SPEC, n=10, shard_size=10, distribution="rollouts", states=str(states),
                   states_sha256=sha256_file(states))  # fmt: skip
    generate(spec, tmp_path / "roll", workers=1, progress=False)
    pack_labels(tmp_path / "roll", tmp_path / "roll.npz")
    with pytest.raises(DatasetError, match="needs --states"):
        unpack_labels(tmp_path / "roll.npz", tmp_path / "roll_back", progress=False)
    other = tmp_path / "other.npz"
    np.savez(other, lam=sample_states(load_robot("anymal_b"), 30, seed=10).astype(np.float32))
    with pytest.raises(DatasetError, match="pass the recorded states file"):
        unpack_labels(tmp_path / "roll.npz", tmp_path / "roll_back", states=other, progress=False)
    unpack_labels(tmp_path / "roll.npz", tmp_path / "roll_back", states=states, progress=False)
    _same_shards(tmp_path / "roll", tmp_path / "roll_back")
    with pytest.raises(SystemExit):
        main(["unpack", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "x")])
