"""benchmarks/studies/learning_curves.py: TensorBoard scalars read back on the environment-step axis, binned and
grouped by variant, against values written by hand."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from torch.utils.tensorboard import SummaryWriter

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

from benchmarks.studies import learning_curves as lc


def fake_run(root: Path, name: str, weight: float, values: dict[int, float], resumed: dict[int, float]) -> Path:
    """A run folder as rsl-rl training leaves it: config.json (512 envs x 24 steps per iteration) and tb/ with the
    tag logged per iteration, then a resumed session's event file that repeats some iterations."""
    run = root / name
    (run / "tb").mkdir(parents=True)
    config = {"backend": "rsl", "num_envs": 512, "backend_config": {"num_steps_per_env": 24},
              "env_config": {"margin_weight": weight}}  # fmt: skip
    (run / "config.json").write_text(json.dumps(config))
    for session in (values, resumed):
        writer = SummaryWriter(str(run / "tb"))
        for iteration, value in session.items():
            writer.add_scalar("Curriculum/terrain_level_mean", value, iteration)
        writer.close()
    return run


def test_curves_are_binned_on_environment_steps_and_grouped_by_weight(tmp_path: Path) -> None:
    batch = 512 * 24  # 12,288 environment steps per iteration
    a = fake_run(tmp_path, "a", 0.0, {0: 1.0, 1: 2.0, 2: 3.0, 3: 4.0}, {3: 10.0})  # iteration 3 resumed: 10 wins
    b = fake_run(tmp_path, "b", 0.1, {0: 0.0, 1: 0.0, 2: 2.0, 3: 2.0}, {})
    curve = lc.read_curve(a, "Curriculum/terrain_level_mean")
    np.testing.assert_array_equal(curve.steps, [batch, 2 * batch, 3 * batch, 4 * batch])
    np.testing.assert_allclose(curve.values, [1.0, 2.0, 3.0, 10.0])
    summary = lc.summarise([curve, lc.read_curve(b, "Curriculum/terrain_level_mean")], bin_steps=2 * batch)
    assert set(summary) == {"without margin", "with margin (0.1)"}
    np.testing.assert_allclose(summary["without margin"]["mean"], [1.5, 6.5, np.nan])  # bins of 2 iterations
    np.testing.assert_allclose(summary["with margin (0.1)"]["mean"], [0.0, 2.0, np.nan])
    np.testing.assert_allclose(summary["without margin"]["steps"], [batch, 3 * batch, 5 * batch])


def test_a_missing_run_or_tag_is_named(tmp_path: Path) -> None:
    run = fake_run(tmp_path, "a", 0.0, {0: 1.0}, {})
    with pytest.raises(ValueError, match=r"no scalar 'Episode_Termination/fell'.*Curriculum/terrain_level_mean"):
        lc.read_curve(run, "Episode_Termination/fell")
    with pytest.raises(ValueError, match="not a training run"):
        lc.read_curve(tmp_path / "nowhere", "Curriculum/terrain_level_mean")
    with pytest.raises(SystemExit):
        lc.main([str(run), "--bin-steps", "0", "--out", str(tmp_path / "x")])


def test_main_writes_the_figure_and_the_record(tmp_path: Path) -> None:
    runs = [fake_run(tmp_path, n, w, {0: 1.0, 1: 2.0}, {}) for n, w in (("a", 0.0), ("b", 0.1))]
    assert lc.main([*map(str, runs), "--tags", "Curriculum/terrain_level_mean", "--out", str(tmp_path / "lc")]) == 0
    record = json.loads((tmp_path / "lc.json").read_text())
    assert set(record["tags"]["Curriculum/terrain_level_mean"]) == {"without margin", "with margin (0.1)"}
    assert (tmp_path / "lc.png").stat().st_size > 0


def test_the_printed_last_value_names_the_bin_it_comes_from(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The binning's trailing bin may be empty (NaN); the line quotes the last filled bin's value and centre."""
    batch = 512 * 24
    run = fake_run(tmp_path, "a", 0.0, {0: 1.0, 1: 2.0, 2: 3.0, 3: 4.0}, {})
    args = [str(run), "--tags", "Curriculum/terrain_level_mean", "--bin-steps", str(2 * batch)]
    assert lc.main([*args, "--out", str(tmp_path / "lc")]) == 0
    record = json.loads((tmp_path / "lc.json").read_text())["tags"]["Curriculum/terrain_level_mean"]["without margin"]
    assert np.isnan(record["mean"][-1])  # the empty trailing bin, centred at 5 batches
    expected = f"without margin: 3.5 in its last filled bin (centred at {3 * batch / 1e6:.2f}M steps)"
    assert expected in capsys.readouterr().out
