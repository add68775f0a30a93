"""compare: both variants, one seed, a tiny budget: PNG, Markdown and JSON with the table's metrics."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from margin_rl.train.artifacts.bundle import card_markdown
from margin_rl.train.commands.compare import CompareSettings, eval_folder, evaluate_variants, main
from margin_rl.train.commands.evaluate import evaluate
from margin_rl.train.metrics import SUMMARY_METRICS, TERRAIN_METRICS


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
    # no --recipe: the shipped recipe, its options recorded as JSON (config dataclasses as mappings)
    assert report["settings"]["recipe"] == "robust" and report["env_options"]["randomization"]["push_interval_s"] == 8
    assert report["variants"]["without margin"]["margin_weight"] == 0.0
    assert report["variants"]["with margin"]["margin_weight"] == 2.0
    for variant in report["variants"].values():
        assert set(variant["mean"]) == set(SUMMARY_METRICS) == set(variant["std"])  # flat: no terrain columns
        assert len(variant["runs"]) == 1 and Path(variant["runs"][0]["policy"]).is_file()
        assert all(v is not None for v in variant["mean"].values())  # finite: the baseline's margin too
    markdown = (out / "compare.md").read_text()
    assert "| without margin | 0 |" in markdown and "| with margin | 2 |" in markdown and "compare.png" in markdown
    assert (out / "compare.png").stat().st_size > 10_000
    # A second call reuses the finished runs instead of training again; with a grid of commands and conditions.
    assert main([*args, "--eval-commands", "1.0", "--eval-conditions", "friction_0.4"]) == 0
    assert len(list((out / "runs").glob("*/checkpoints/*.pt"))) == 2
    grid_report = json.loads((out / "compare.json").read_text())
    assert grid_report["variants"] == report["variants"]  # the main cell does not depend on the grid
    cells = [(cell["condition"], cell["forward_velocity"]) for cell in grid_report["grid"]]
    assert cells == [("nominal", 1.0), ("friction_0.4", 0.75), ("friction_0.4", 1.0)]
    for cell in grid_report["grid"]:
        assert set(cell["variants"]) == {"without margin", "with margin"} and "fell" in cell["statistics"]
    run = Path(grid_report["grid"][2]["variants"]["with margin"]["runs"][0]["run_dir"])
    cell_metrics = json.loads((run / "eval_grid" / "friction_0.4__v1" / "metrics.json").read_text())
    assert cell_metrics["condition"] == "friction_0.4" and cell_metrics["forward_velocity"] == 1.0
    assert cell_metrics["env_config"]["randomization"]["friction"] == [0.4, 0.4]
    # the same cell evaluated directly gives the same numbers
    direct, _ = evaluate(
        run / "final_model.pt", episodes=2, seed=1000, forward_velocity=1.0, warmup_s=0.1,
        condition="friction_0.4", out_dir=tmp_path / "direct",
    )  # fmt: skip
    assert grid_report["grid"][2]["variants"]["with margin"]["runs"][0]["metrics"]["return"] == pytest.approx(
        direct["summary"]["return"]["mean"]
    )
    # --runs evaluates the same finished runs without training; identical grid cells are reused, not re-run
    cell_file = run / "eval_grid" / "friction_0.4__v1" / "metrics.json"
    before = cell_file.stat().st_mtime_ns
    runs = sorted(str(r) for r in (out / "runs").iterdir())
    again = ["--eval-episodes", "2", "--warmup-s", "0.1", "--eval-commands", "1.0", "--eval-conditions", "friction_0.4"]
    bundle = tmp_path / "bundle_of_runs"
    assert main([*again, "--runs", *runs, "--out", str(tmp_path / "from_runs"), "--bundle", str(bundle)]) == 0
    from_runs = json.loads((tmp_path / "from_runs" / "compare.json").read_text())
    assert from_runs["grid"] == grid_report["grid"] and cell_file.stat().st_mtime_ns == before
    card = json.loads((bundle / "card.json").read_text())  # --bundle writes the given runs' policies too
    assert sorted(entry["margin_weight"] for entry in card["policies"]) == [0.0, 2.0]
    timed = "wall time of the comparison (evaluation only: the runs were trained before)"
    card_text = (bundle / "CARD.md").read_text()
    assert timed in card_text and "without margin: seeds [0]; with margin: seeds [0]" in card_text
    # each run's training command, from its config.json (runs trained by compare itself record none)
    assert all(entry["training_command"] is None and entry["init_from"] is None for entry in card["policies"])
    card["policies"][1]["training_command"] = "margin-rl-train --seed 0 --init-from base.pt"
    assert "`with_margin__s0/policy.pt`: `margin-rl-train --seed 0 --init-from base.pt`" in card_markdown(card)
    std_column = {line.split(" | ")[4] for line in card_text.splitlines() if line.startswith("| `with_margin")}
    assert std_column == {f"{card['policies'][1]['final_action_std']:.3f}"}  # the card's table shows it too
    card["policies"][1]["final_action_std"] = None  # an SB3 run, or a model saved before it was recorded
    assert "| not recorded |" in card_markdown(card)
    assert (
        from_runs["variants"]["with margin"]["runs"][0]["metrics"]
        == report["variants"]["with margin"]["runs"][0]["metrics"]
    )
    grid_markdown = (out / "compare.md").read_text()
    rows = [line for line in grid_markdown.splitlines() if line.startswith(("| nominal |", "| friction_0.4 |"))]
    assert [row.split(" | ")[:2] for row in rows] == [
        ["| nominal", "0.75"], ["| nominal", "1"], ["| friction_0.4", "0.75"], ["| friction_0.4", "1"],
    ]  # fmt: skip
    assert rows[0].count(" → ") == 4
    # On rough ground the fall causes and the step-edge landings join the table and the statistics.
    rough = tmp_path / "rough"
    assert main(["--eval-episodes", "2", "--warmup-s", "0.1", "--terrain-difficulty", "0.5", "--runs", *runs,
                 "--out", str(rough)]) == 0  # fmt: skip
    rough_report = json.loads((rough / "compare.json").read_text())
    columns = {**SUMMARY_METRICS, **TERRAIN_METRICS}
    for name, variant in rough_report["variants"].items():
        assert set(variant["mean"]) == set(columns), name
        run_metrics = variant["runs"][0]["metrics"]
        for key in TERRAIN_METRICS:  # one seed: its mean over episodes is the variant's mean
            expected = run_metrics[key]  # None where no episode gave a value (e.g. no touchdown)
            assert variant["mean"][key] == (None if expected is None else pytest.approx(expected))
    assert set(rough_report["statistics"]) == set(columns)
    assert "termination/thigh_contact" in TERRAIN_METRICS and "termination/diverged" not in TERRAIN_METRICS
    rough_markdown = (rough / "compare.md").read_text()
    assert all(rough_markdown.count(f" {label} |") == 2 for label in TERRAIN_METRICS.values())  # both tables


def test_bundle_round_trip_evaluates_like_the_runs(tmp_path: Path, toy_weights: str) -> None:
    """compare --bundle copies the TorchScript actors with a card; --bundled evaluates them to the same metrics
    as the rsl-rl checkpoints they were exported from (two independent loaders of one policy), with the
    learned-margin weights they were trained with even after the original weights file was replaced."""
    from margin_rl.stability.learned.model import save_weights
    from margin_rl.train.artifacts.bundle import CARD_FILE, load_bundle
    from tests.stability.learned.test_model import random_weights

    weights = tmp_path / "margin.npz"  # a private copy: it is replaced below
    for suffix in (".npz", ".json"):
        weights.with_suffix(suffix).write_bytes(Path(toy_weights).with_suffix(suffix).read_bytes())
    out, bundle_dir = tmp_path / "cmp", tmp_path / "bundle"
    args = [
        "--backend", "rsl", "--seeds", "1", "--num-envs", "8", "--total-steps", "192", "--eval-episodes", "2",
        "--warmup-s", "0.1", "--margin-weight", "2", "--margin-weights", str(weights), "--out", str(out),
        "--env-option", "episode_length_s=0.4", "--no-progress", "--bundle", str(bundle_dir),
    ]  # fmt: skip
    assert main(args) == 0
    trained_sha = json.loads(weights.with_suffix(".json").read_text())["sha256"]
    save_weights(random_weights(seed=1), weights, {"robot": "toy"})  # "retrained" margin weights
    bundle = load_bundle(bundle_dir)
    assert {v: (w, [s for s, _ in p]) for v, (w, p) in bundle.variants().items()} == {
        "without margin": (0.0, [0]),
        "with margin": (2.0, [0]),
    }
    card = json.loads((bundle_dir / CARD_FILE).read_text())
    assert card["provenance"]["command"].startswith("margin-rl-compare") and card["provenance"]["commit"]
    assert "| without margin |" in (bundle_dir / "CARD.md").read_text()
    assert all(e["learned_margin"]["source"] == str(weights) for e in card["policies"])  # margin weights recorded
    assert card["learned_margin_weights"]["npz_sha256"] == trained_sha  # ... and carried
    assert bundle.margin_weights is not None and bundle.margin_weights.parent.parent == bundle_dir
    report = json.loads((out / "compare.json").read_text())["variants"]
    for entry in card["policies"]:  # the action std each run ended with, as its final model recorded it
        run_dir = next(Path(r["run_dir"]) for r in report[entry["variant"]]["runs"] if r["seed"] == entry["seed"])
        saved = torch.load(run_dir / "final_model.pt", weights_only=True)["infos"]["action_std"]
        assert entry["final_action_std"] == pytest.approx(saved) and 0.5 < saved < 1.5

    evaluated = tmp_path / "evaluated"
    assert main(["--bundled", str(bundle_dir), "--out", str(evaluated)]) == 0
    trained = json.loads((out / "compare.json").read_text())["variants"]
    from_bundle = json.loads((evaluated / "compare.json").read_text())["variants"]
    for name, variant in trained.items():
        for key in SUMMARY_METRICS:
            a, b = variant["mean"][key], from_bundle[name]["mean"][key]
            assert (a is None and b is None) or abs(a - b) <= 1e-4 * (1 + abs(a)), (name, key, a, b)

    # Evaluated with the retrained weights instead, the margin column differs: the carried copy mattered.
    replaced = tmp_path / "replaced"
    assert main(["--bundled", str(bundle_dir), "--out", str(replaced), "--margin-weights", str(weights)]) == 0
    margins = json.loads((replaced / "compare.json").read_text())["variants"]["with margin"]["mean"]["margin_mean"]
    assert abs(margins - from_bundle["with margin"]["mean"]["margin_mean"]) > 1e-3

    # A changed policy or margin file is refused, naming the file.
    for path in (bundle.runs[0].policy, bundle.margin_weights):
        original = path.read_bytes()
        path.write_bytes(original + b"\0")
        with pytest.raises(ValueError, match=f"{path.name}: checksum mismatch"):
            load_bundle(bundle_dir)
        path.write_bytes(original)


def test_rewritten_bundle_keeps_the_replaced_cards_numbers(tmp_path: Path, toy_weights: str) -> None:
    """A bundle written over an existing one carries the replaced card's settings and tables (and its history)
    into ``history``, newest first; its card holds the grid with each cell's tests; an unreadable card is not
    overwritten; ``--bundled ... --eval-conditions nominal`` evaluates the commands only."""
    from margin_rl.train.artifacts.bundle import CARD_FILE, load_bundle

    out, bundle_dir = tmp_path / "cmp", tmp_path / "bundle"
    common = [
        "--backend", "rsl", "--num-envs", "8", "--total-steps", "192", "--eval-episodes", "2", "--warmup-s", "0.1",
        "--margin-weight", "2", "--margin-weights", toy_weights, "--env-option", "episode_length_s=0.4",
        "--no-progress", "--eval-commands", "1.0",
    ]  # fmt: skip
    assert main([*common, "--seeds", "1", "--out", str(out), "--bundle", str(bundle_dir)]) == 0
    first = json.loads((bundle_dir / CARD_FILE).read_text())
    assert first["history"] == []
    assert [(c["condition"], c["forward_velocity"]) for c in first["grid"]] == [("nominal", 1.0)]
    assert set(first["grid"][0]["variants"]) == {"without margin", "with margin"}
    assert set(first["statistics"]) == set(SUMMARY_METRICS)
    assert "| nominal | 1 |" in (bundle_dir / "CARD.md").read_text()  # the grid row, from the card alone

    # a second seed, written over the first bundle
    assert main([*common, "--seeds", "2", "--out", str(out), "--bundle", str(bundle_dir)]) == 0
    second = json.loads((bundle_dir / CARD_FILE).read_text())
    assert len(second["policies"]) == 4 and len(second["history"]) == 1
    earlier = second["history"][0]
    assert earlier["table"] == first["table"] and earlier["grid"] == first["grid"]
    assert earlier["seeds"] == {"without margin": [0], "with margin": [0]}
    assert earlier["provenance"]["command"] == first["provenance"]["command"]
    assert earlier["learned_margin_sha256"] == first["learned_margin_weights"]["npz_sha256"]
    text = (bundle_dir / "CARD.md").read_text()
    assert "## Earlier versions of this bundle" in text and "without margin: seeds [0]; with margin: seeds [0]" in text
    assert text.count("| nominal | 1 |") == 2  # the grid of the bundle and of its predecessor
    load_bundle(bundle_dir)  # the history does not disturb loading

    assert main([*common, "--seeds", "2", "--out", str(out), "--bundle", str(bundle_dir)]) == 0
    third = json.loads((bundle_dir / CARD_FILE).read_text())
    assert [len(entry["seeds"]["with margin"]) for entry in third["history"]] == [2, 1]  # newest first

    # a card that cannot be read is not overwritten: its numbers would be lost
    (bundle_dir / CARD_FILE).write_text("{not json")
    with pytest.raises(SystemExit):
        main([*common, "--seeds", "2", "--out", str(out), "--bundle", str(bundle_dir)])
    assert (bundle_dir / CARD_FILE).read_text() == "{not json"
    assert not list(tmp_path.glob(".bundle.*"))  # no staging folder left behind

    # a card whose grid has a second condition, evaluated on its commands only
    third["settings"]["grid_conditions"] = ["friction_0.4"]
    (bundle_dir / CARD_FILE).write_text(json.dumps(third))
    few = tmp_path / "few"
    assert main(["--bundled", str(bundle_dir), "--out", str(few), "--eval-conditions", "nominal"]) == 0
    cells = [(c["condition"], c["forward_velocity"]) for c in json.loads((few / "compare.json").read_text())["grid"]]
    assert cells == [("nominal", 1.0)]


def test_bundle_refuses_margin_weights_changed_since_training(tmp_path: Path, toy_weights: str) -> None:
    """A bundle must carry the weights its policies were trained with, not whatever the path holds now."""
    from margin_rl.stability.learned.model import save_weights
    from margin_rl.train.artifacts.bundle import copy_margin_weights
    from tests.stability.learned.test_model import random_weights

    weights = tmp_path / "margin"
    save_weights(random_weights(seed=2), weights, {"robot": "toy"})
    sha = json.loads(weights.with_suffix(".json").read_text())["sha256"]
    trained_with = {"source": str(weights.with_suffix(".npz")), "sha256": sha}
    entries = [{"learned_margin": trained_with, "margin_weight": 0.1}, {"learned_margin": None, "margin_weight": 0.1}]
    record = copy_margin_weights(entries, tmp_path)
    assert record is not None and record["npz_sha256"] == sha and (tmp_path / record["npz"]).is_file()
    assert copy_margin_weights([{"learned_margin": None, "margin_weight": 0.1}], tmp_path) is None
    # a baseline (weight 0) whose environment loaded another network: it never entered that policy's reward
    baseline = {"learned_margin": {"source": toy_weights, "sha256": "x"}, "margin_weight": 0.0}
    assert copy_margin_weights([*entries, baseline], tmp_path) == record
    assert copy_margin_weights([baseline], tmp_path) is None
    save_weights(random_weights(seed=3), weights, {"robot": "toy"})
    with pytest.raises(ValueError, match="changed since the runs were trained"):
        copy_margin_weights(entries, tmp_path)
    other = {"learned_margin": {"source": toy_weights, "sha256": "x"}, "margin_weight": 0.2}
    with pytest.raises(ValueError, match="different learned-margin weights"):
        copy_margin_weights([*entries, other], tmp_path)


def test_new_bundle_reuses_a_bundled_baseline_trained_with_another_network(tmp_path: Path, toy_weights: str) -> None:
    """compare --runs takes a bundle's policy folder as a finished run: the new bundle carries the margin network
    of its margin policies, keeps the reused baseline's own network and training facts in its entry, evaluates it
    to the same metrics as in its first bundle (the margin column aside: another network measures it), and
    refuses a reused folder whose file was changed."""
    from margin_rl.stability.learned.model import save_weights
    from margin_rl.train.artifacts.bundle import CARD_FILE, load_bundle
    from margin_rl.train.commands.compare import variants_of_runs
    from tests.stability.learned.test_model import random_weights

    newer = tmp_path / "newer"
    save_weights(random_weights(seed=4), newer, {"robot": "toy"})
    common = [
        "--backend", "rsl", "--seeds", "1", "--num-envs", "8", "--total-steps", "192", "--eval-episodes", "2",
        "--warmup-s", "0.1", "--margin-weight", "2", "--env-option", "episode_length_s=0.4", "--no-progress",
        "--eval-commands", "1.0",
    ]  # fmt: skip
    old_bundle, new_out = tmp_path / "old_bundle", tmp_path / "new"
    old_args = ["--margin-weights", toy_weights, "--out", str(tmp_path / "old"), "--bundle", str(old_bundle)]
    assert main([*common, *old_args]) == 0
    assert main([*common, "--margin-weights", str(newer.with_suffix(".npz")), "--out", str(new_out)]) == 0
    baseline, margin_run = old_bundle / "without_margin__s0", new_out / "runs" / "mw2__s0"
    bundle_dir, out = tmp_path / "release", tmp_path / "release_eval"
    assert main(["--runs", str(baseline), str(margin_run), "--eval-episodes", "2", "--warmup-s", "0.1",
                 "--eval-commands", "1.0", "--out", str(out), "--bundle", str(bundle_dir)]) == 0  # fmt: skip

    bundle = load_bundle(bundle_dir)  # the baseline's other network is not a mismatch: weight 0
    card = json.loads((bundle_dir / CARD_FILE).read_text())
    newer_sha = json.loads(newer.with_suffix(".json").read_text())["sha256"]
    assert card["learned_margin_weights"]["npz_sha256"] == newer_sha
    old_card = json.loads((old_bundle / CARD_FILE).read_text())
    old_entry = next(e for e in old_card["policies"] if e["margin_weight"] == 0)
    reused = next(e for e in card["policies"] if e["margin_weight"] == 0)
    assert reused["learned_margin"] == old_entry["learned_margin"] != card["policies"][1]["learned_margin"]
    assert reused["reused_from"] == {
        "bundle": "old_bundle",
        "commit": old_card["provenance"]["commit"],
        "policy": "without_margin__s0/policy.pt",
    }
    assert reused["env_steps"] == old_entry["env_steps"] and reused["final_action_std"] == old_entry["final_action_std"]
    assert reused["policy_sha256"] == old_entry["policy_sha256"]
    assert "reused from bundle `old_bundle`" in (bundle_dir / "CARD.md").read_text()
    before, after = old_card["table"]["without margin"]["mean"], card["table"]["without margin"]["mean"]
    for key in ("lin_acc_rms", "ang_acc_rms", "velocity_error_mean", "stance_width_mean", "fell"):
        assert after[key] == pytest.approx(before[key], rel=1e-6, abs=1e-9), key
    assert bundle.variants()["with margin"][0] == 2.0

    (baseline / "policy.pt").write_bytes((baseline / "policy.pt").read_bytes() + b"\0")
    with pytest.raises(ValueError, match=r"policy\.pt: checksum mismatch"):
        variants_of_runs([baseline, margin_run])


def test_a_bundle_evaluated_on_a_fixed_terrain_is_reevaluated_there(tmp_path: Path, toy_weights: str) -> None:
    """compare --runs ... --terrain-difficulty D --bundle: the card records the evaluation's environment options and
    compare --bundled applies them, so it reproduces the card's table (the rough bundles' evaluation in make demo)."""
    from margin_rl.train.artifacts.bundle import CARD_FILE, load_bundle

    train = [
        "--backend", "rsl", "--seeds", "1", "--num-envs", "4", "--total-steps", "96", "--eval-episodes", "1",
        "--warmup-s", "0.1", "--margin-weight", "2", "--env-option", "episode_length_s=0.4", "--no-progress",
        "--margin-weights", toy_weights, "--out", str(tmp_path / "trained"),
    ]  # fmt: skip
    assert main(train) == 0
    runs = [str(tmp_path / "trained" / "runs" / name) for name in ("mw0__s0", "mw2__s0")]
    bundle_dir = tmp_path / "rough_bundle"
    evaluate = ["--eval-episodes", "2", "--warmup-s", "0.1", "--terrain-difficulty", "0.25"]
    assert main(["--runs", *runs, *evaluate, "--out", str(tmp_path / "first"), "--bundle", str(bundle_dir)]) == 0
    card = json.loads((bundle_dir / CARD_FILE).read_text())
    assert card["eval_env_overrides"]["terrain"] == "rough"
    assert card["eval_env_overrides"]["terrain_config"]["step_height"] == pytest.approx([0.015, 0.045])
    assert "Evaluation environment options" in (bundle_dir / "CARD.md").read_text()
    assert load_bundle(bundle_dir).env_overrides()["terrain"] == "rough"
    assert main(["--bundled", str(bundle_dir), "--out", str(tmp_path / "again")]) == 0
    again = json.loads((tmp_path / "again" / "compare.json").read_text())
    assert again["eval_env_overrides"]["terrain"] == "rough"
    for variant, row in card["table"].items():
        for metric, value in row["mean"].items():
            assert again["bundle"]["card_table"][variant]["mean"][metric] == value
            measured = np.mean([r["metrics"][metric] for r in again["variants"][variant]["runs"]])
            assert measured == pytest.approx(value, rel=1e-9, abs=1e-12), (variant, metric)


def test_main_cell_reuses_evaluations_made_for_the_same_request(tmp_path: Path, rsl_run: Path) -> None:
    """A comparison asked again reuses every main-cell evaluation but each variant's first (its episode is the
    plot's), with the same numbers; another command evaluates again; another environment evaluates into its own
    folder and leaves the first one's evaluations as they were."""
    runs = [tmp_path / f"run_s{seed}" for seed in (0, 1)]  # one policy under two seeds' names
    for run in runs:
        shutil.copytree(rsl_run, run, ignore=shutil.ignore_patterns("eval", "eval_grid"))
    variants = {"with margin": (0.5, [(seed, run / "final_model.pt") for seed, run in enumerate(runs)])}
    settings = CompareSettings(margin_weight=0.5, seeds=(0, 1), eval_episodes=2, eval_seed=7, warmup_s=0.1)
    second_metrics = runs[1] / "eval" / "metrics.json"
    first = evaluate_variants(variants, settings, tmp_path / "cmp")
    stamps = [(run / "eval" / "metrics.json").stat().st_mtime_ns for run in runs]
    again = evaluate_variants(variants, settings, tmp_path / "cmp")
    assert again["variants"] == first["variants"]
    after = [(run / "eval" / "metrics.json").stat().st_mtime_ns for run in runs]
    assert after[0] != stamps[0] and after[1] == stamps[1]  # the first seed ran again for the plot, not the second

    shorter = {"episode_length_s": 0.3}  # another environment: its own folder, the first one untouched
    elsewhere = evaluate_variants(variants, settings, tmp_path / "cmp_shorter", eval_env_overrides=shorter)
    folder = Path(elsewhere["variants"]["with margin"]["runs"][1]["eval_dir"])
    assert (
        folder == runs[1] / eval_folder("eval", shorter) and folder.name.startswith("eval_") and len(folder.name) == 13
    )
    assert (folder / "metrics.json").is_file() and second_metrics.stat().st_mtime_ns == stamps[1]
    assert first["variants"]["with margin"]["runs"][1]["eval_dir"] == str(runs[1] / "eval")
    assert eval_folder("eval", None) == "eval" and eval_folder("eval_grid", shorter).startswith("eval_grid_")

    other = evaluate_variants(variants, replace(settings, forward_velocity=0.5), tmp_path / "cmp_other")
    assert second_metrics.stat().st_mtime_ns != stamps[1]  # same folder, another request: evaluated again
    second_seed = [report["variants"]["with margin"]["runs"][1]["metrics"] for report in (first, other)]
    assert second_seed[0] != second_seed[1]


def test_unknown_bundle_is_a_clear_error(tmp_path: Path) -> None:
    from margin_rl.train.artifacts.bundle import load_bundle

    with pytest.raises(ValueError, match="no policy bundle 'nope'"):
        load_bundle("nope")


def test_runs_that_cannot_be_compared_are_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from margin_rl.train.commands.compare import variants_of_runs

    with pytest.raises(ValueError, match="not a finished training run"):
        variants_of_runs([tmp_path])
    for weight, seed in ((0.0, 0), (0.2, 0), (0.5, 1)):  # two nonzero weights: which is "with margin"?
        run = tmp_path / f"mw{weight}_s{seed}"
        run.mkdir()
        config = {
            "env_id": "margin_rl/AnymalB-v1",
            "seed": seed,
            "backend": "rsl",
            "env_config": {"margin_weight": weight},
        }
        (run / "config.json").write_text(json.dumps(config))
        (run / "progress.json").write_text(json.dumps({"finished": True}))
    with pytest.raises(ValueError, match=r"weight 0 and one other weight; got .* weights \[0.0, 0.2, 0.5\]"):
        variants_of_runs(sorted(tmp_path.glob("mw*")))
    env_id, variants = variants_of_runs(sorted(tmp_path.glob("mw0.[02]*")))
    assert env_id == "margin_rl/AnymalB-v1" and variants["with margin"][0] == 0.2
    with pytest.raises(SystemExit):
        main(["--runs", str(tmp_path)])
    assert "not a finished training run" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # a bundle is not written from a bundle
        main(["--bundled", "anymal_b", "--bundle", str(tmp_path / "copy")])
    assert "--bundled evaluates a bundle: give one" in capsys.readouterr().err and not (tmp_path / "copy").exists()
