"""statistics: Welch's p against the textbook formula, the bootstrap interval on known groups, symmetry under
swapping the variants (hypothesis), clear errors, the n < 2 and no-variance cases, and the reports' tables."""

from __future__ import annotations

import importlib.util
import json
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy import stats

from margin_rl.train.analysis.significance import Difference, compare_seeds, compare_variants, difference_table
from margin_rl.train.commands.compare import write_markdown
from margin_rl.train.metrics import SUMMARY_METRICS, TERRAIN_METRICS, summary_table

ROOT = Path(__file__).resolve().parents[3]
seed_groups = st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=2, max_size=8)


def welch_by_hand(a: list[float], b: list[float]) -> tuple[float, float, float]:
    """t, Welch–Satterthwaite df and two-sided p, from the formulas (not scipy's test)."""
    va = sum((x - sum(a) / len(a)) ** 2 for x in a) / (len(a) - 1) / len(a)  # s_a² / n_a
    vb = sum((x - sum(b) / len(b)) ** 2 for x in b) / (len(b) - 1) / len(b)
    t = (sum(b) / len(b) - sum(a) / len(a)) / math.sqrt(va + vb)
    df = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1))
    return t, df, 2 * stats.t.sf(abs(t), df)


def test_welch_p_value_matches_the_formula() -> None:
    a, b = [1.0, 2.0, 4.0, 3.5], [5.0, 6.5, 5.5]
    t, df, p = welch_by_hand(a, b)
    assert 3 < df < 5 and t > 0  # unequal variances: fewer degrees of freedom than the pooled n_a + n_b − 2 = 5
    result = compare_seeds("velocity_error_mean", a, b)
    assert result.p_value == pytest.approx(p, rel=1e-12)
    assert result.difference == pytest.approx(17 / 3 - 2.625)
    assert result.relative == pytest.approx((17 / 3 - 2.625) / 2.625)
    assert (result.n_a, result.n_b, result.note) == (4, 3, None)
    assert p < 0.05 and result.significant is True


def test_bootstrap_interval_covers_the_true_difference_of_separated_groups() -> None:
    rng = np.random.default_rng(7)
    a, b = rng.normal(0.0, 1.0, 8), rng.normal(5.0, 1.0, 8)  # true difference 5
    result = compare_seeds("lin_acc_rms", a, b)
    assert result.ci_low < 5 < result.ci_high and result.ci_low > 0
    assert result.ci_low < result.difference < result.ci_high
    assert result.significant is True and result.p_value < 1e-6
    assert compare_seeds("lin_acc_rms", a, b) == result  # a fixed generator seed: reproducible
    other_seed = compare_seeds("lin_acc_rms", a, b, seed=1)
    assert other_seed.ci_low != result.ci_low and other_seed.ci_low == pytest.approx(result.ci_low, abs=0.2)


def test_identical_groups_give_a_symmetric_interval_around_zero() -> None:
    values = [0.3, 0.1, 0.7, 0.4]
    result = compare_seeds("margin_mean", values, values)
    assert result.difference == 0 and result.ci_low == -result.ci_high < 0
    assert result.p_value == pytest.approx(1.0) and result.significant is False


def test_the_interval_level_follows_alpha() -> None:
    a, b = [1.0, 2.0, 3.0, 4.0, 2.5], [2.0, 3.5, 4.0, 5.0, 3.0]
    wide, narrow = compare_seeds("fell", a, b, alpha=0.01), compare_seeds("fell", a, b, alpha=0.2)
    assert wide.ci_low < narrow.ci_low < narrow.ci_high < wide.ci_high
    assert wide.p_value == narrow.p_value and wide.alpha == 0.01


@pytest.mark.filterwarnings("ignore:Precision loss occurred:RuntimeWarning")  # scipy on nearly equal values
@settings(max_examples=60, deadline=None)
@given(a=seed_groups, b=seed_groups)
@example(a=[1.0, 1.0, 0.0, 1.0, 4.0], b=[4.0, 1.0, 1.0, 0.0, 1.0])  # the same values in another order
def test_swapping_the_variants_negates_the_difference_and_the_interval(a: list[float], b: list[float]) -> None:
    forward, backward = compare_seeds("m", a, b, resamples=500), compare_seeds("m", b, a, resamples=500)
    assert backward.difference == -forward.difference
    assert (backward.n_a, backward.n_b) == (forward.n_b, forward.n_a)
    scale = 1e-9 * (1 + max(map(abs, a + b)))
    assert backward.ci_low == pytest.approx(-forward.ci_high, abs=scale)
    assert backward.ci_high == pytest.approx(-forward.ci_low, abs=scale)
    assert forward.ci_low <= forward.ci_high
    if forward.p_value is None:
        assert backward.p_value is None and forward.note == backward.note and forward.significant is None
    else:
        assert 0 <= forward.p_value <= 1 and backward.p_value == pytest.approx(forward.p_value, rel=1e-9, abs=1e-300)


@pytest.mark.parametrize(
    "values",
    [["1.0", "2.0"], [[1.0, 2.0], [3.0, 4.0]], np.ones((2, 2)), 3.0, "12", None, [1.0, object()]],
)
def test_values_that_are_not_a_1d_sequence_of_numbers_name_the_metric(values: object) -> None:
    with pytest.raises(ValueError, match="stance_width_mean: b must be a 1-D sequence of numbers"):
        compare_seeds("stance_width_mean", [1.0, 2.0], values)


@pytest.mark.parametrize(("options", "message"), [({"alpha": 0}, "alpha"), ({"alpha": 1.5}, "alpha"),
                                                  ({"resamples": 99}, "resamples")])  # fmt: skip
def test_bad_settings_are_refused(options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        compare_seeds("fell", [1.0, 2.0], [3.0, 4.0], **options)


def test_missing_seeds_are_dropped_and_fewer_than_two_leave_no_test() -> None:
    result = compare_seeds("lin_acc_rms", [1.0, None, math.nan, 3.0], [2.0, math.inf], names=("without", "with"))
    assert (result.n_a, result.n_b) == (2, 1) and result.mean_a == 2.0 and result.difference == 0.0
    assert result.p_value is None and result.significant is None and result.ci_low is None
    assert result.note == "fewer than 2 seeds with a value in with: 1"
    empty = compare_seeds("lin_acc_rms", [], [None])
    assert empty.mean_a is None and empty.difference is None and empty.relative is None and "in a: 0" in empty.note


def test_no_variance_in_either_variant_has_no_p_value() -> None:
    result = compare_seeds("fell", [0.0, 0.0, 0.0], [0.0, 0.0])  # no falls at all: a common case
    assert result.p_value is None and result.significant is None and "no variance" in result.note
    assert result.relative is None and (result.ci_low, result.ci_high) == (0.0, 0.0)
    one_sided = compare_seeds("fell", [0.0, 0.0, 0.0], [0.1, 0.0, 0.2])  # variance in one variant: Welch applies
    assert one_sided.p_value is not None and one_sided.note is None


def test_significant_is_derived_and_serialised() -> None:
    difference = Difference("m", 1.0, 2.0, 1.0, 1.0, 0.5, 1.5, 0.01, 3, 3)
    assert difference.significant is True and asdict(difference)["significant"] is True
    assert Difference("m", 1.0, 2.0, 1.0, 1.0, 0.5, 1.5, 0.01, 3, 3, alpha=0.001).significant is False


def _report() -> dict:
    """A compare report of two variants over three seeds, as evaluate_variants builds it."""
    rng = np.random.default_rng(3)
    variants = {}
    for name, weight, shift in (("without margin", 0.0, 0.0), ("with margin", 2.0, 5.0)):
        runs = [{"seed": s, "metrics": {k: float(rng.normal(shift, 1.0)) for k in SUMMARY_METRICS}} for s in range(3)]
        runs[0]["metrics"]["fell"] = 0.0 if name == "with margin" else math.nan
        means = {k: float(np.nanmean([r["metrics"][k] for r in runs])) for k in SUMMARY_METRICS}
        stds = {k: float(np.nanstd([r["metrics"][k] for r in runs])) for k in SUMMARY_METRICS}
        variants[name] = {"margin_weight": weight, "runs": runs, "mean": means, "std": stds}
    return variants


def test_compare_variants_covers_every_table_metric() -> None:
    variants = _report()
    differences = compare_variants(variants)
    assert list(differences) == list(SUMMARY_METRICS)
    assert differences["margin_mean"].significant is True and differences["fell"].n_a == 2
    with pytest.raises(ValueError, match="no variant 'baseline'"):
        compare_variants(variants, baseline="baseline")


def test_compare_variants_covers_the_terrain_columns_where_the_report_has_them() -> None:
    variants = _report()
    for variant in variants.values():  # a rough-ground report: every run also has the terrain metrics
        for run in variant["runs"]:
            run["metrics"].update({key: 0.1 * run["seed"] for key in TERRAIN_METRICS})
        variant["mean"].update({key: 0.1 for key in TERRAIN_METRICS})
        variant["std"].update({key: 0.08 for key in TERRAIN_METRICS})
    differences = compare_variants(variants)
    assert list(differences) == [*SUMMARY_METRICS, *TERRAIN_METRICS]  # table order
    assert differences["edge_landing_fraction"].difference == pytest.approx(0.0)
    assert summary_table(variants)[0].endswith(" | ".join(TERRAIN_METRICS.values()) + " |")


def test_write_markdown_adds_the_statistics_table_after_the_unchanged_one(tmp_path: Path) -> None:
    settings_ = {
        "env_id": "margin_rl/AnymalB-v1",
        "backend": "rsl",
        "seeds": [0, 1, 2],
        "total_steps": 1000,
        "num_envs": 8,
        "eval_episodes": 2,
        "eval_seed": 1000,
        "forward_velocity": 0.5,
        "warmup_s": 1.0,
    }
    report = {"settings": settings_, "variants": _report(), "plot": "compare.png"}
    plain = write_markdown(report, tmp_path / "plain.md").read_text()
    assert "p (Welch)" not in plain  # no statistics in the report: only the mean ± std table
    report["statistics"] = {k: asdict(d) for k, d in compare_variants(report["variants"]).items()}
    text = write_markdown(report, tmp_path / "compare.md").read_text()
    assert "\n".join(summary_table(report["variants"])) in text
    header = (
        "| metric | difference (with − without) | relative | 95 % CI (Welch) | p (Welch) | significant (p < 0.05) "
        "| 95 % CI (bootstrap) |"
    )
    assert text.index(header) > text.index("| variant | margin weight |")
    rows = [line for line in text.splitlines() if line.startswith(tuple(f"| {v} |" for v in SUMMARY_METRICS.values()))]
    assert len(rows) == len(SUMMARY_METRICS)
    assert any("| yes |" in line for line in rows)  # stability margin: shifted by 5 standard deviations
    stance = report["statistics"]["stance_width_mean"]
    assert f"[{stance['ci_low']:+.3g}, {stance['ci_high']:+.3g}]" in text
    assert f"[{stance['welch_low']:+.3g}, {stance['welch_high']:+.3g}]" in text


def test_difference_table_says_why_a_row_has_no_test() -> None:
    row = asdict(compare_seeds("fell", [0.0, 0.0], [0.0, 0.0]))
    (line,) = difference_table([(("falls",), row)])[2:]
    note = "no variance over seeds in either variant: Welch's t is undefined"
    assert line == f"| falls | +0 | n/a | n/a | n/a | n/a ({note}) | [+0, +0] |"


def _study(name: str):
    """A script of benchmarks/studies, loaded as a module."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / "studies" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_summarise_runs_compares_each_weight_with_weight_zero() -> None:
    """The committed ANYmal B sweep (three seeds per weight): accelerations significantly lower at 0.2 and 0.5,
    falls not significantly different, as its commit states."""
    module = _study("summarise_runs")
    runs = json.loads((ROOT / "docs" / "comparison" / "v2_sweep_anymal_b.json").read_text())["runs"]
    versus = module.versus_baseline(runs)
    assert list(versus) == ["0.2", "0.5"] and set(versus["0.2"]) == set(module.METRICS)
    for weight in versus.values():
        assert weight["lin_acc_rms"]["significant"] and weight["lin_acc_rms"]["difference"] < 0
        assert weight["ang_acc_rms"]["significant"] and weight["fell"]["significant"] is False
        assert (weight["fell"]["n_a"], weight["fell"]["n_b"]) == (3, 3)
    assert module.versus_baseline([r for r in runs if r["margin_weight"] != 0]) == {}


def test_summarise_runs_keeps_the_causes_of_falls_and_the_evaluation_terrain(tmp_path: Path) -> None:
    """A run's record keeps every fall's cause, the rough measures and where it was evaluated, beside the tabulated
    metrics; a metric neither tabulated nor recorded stays out."""
    module = _study("summarise_runs")
    run = tmp_path / "c_mw0_s0"
    (run / "eval").mkdir(parents=True)
    config = {
        "env_id": "margin_rl/AnymalC-Rough-v1",
        "seed": 0,
        "recipe": "rough",
        "env_config": {
            "robot": "anymal_c",
            "margin_weight": 0.0,
            "margin_normals": "vertical",
            "reward_params": {"termination_penalty": 10, "yaw_tracking": 0.5},
        },
    }
    summary = {
        "fell": {"mean": 0.25, "std": 0.4},
        "termination/tilt": {"mean": 0.125, "std": 0.3},
        "edge_landing_fraction": {"mean": 0.1, "std": 0.05},
        "lin_acc_peak_x": {"mean": 9.0, "std": 1.0},
    }
    metrics = {"episodes": 64, "seed": 5000, "env_id": config["env_id"], "forward_velocity": 0.75,
               "condition": "nominal", "summary": summary,
               "env_config": {"terrain": "rough", "terrain_config": {"step_height": [0.03, 0.09]}}}  # fmt: skip
    (run / "config.json").write_text(json.dumps(config))
    (run / "eval" / "metrics.json").write_text(json.dumps(metrics))
    record = module.run_summary(run, "eval")
    assert set(record["metrics"]) == {"fell", "termination/tilt", "edge_landing_fraction"}
    assert record["termination_penalty"] == 10 and record["recipe"] == "rough"
    assert record["yaw_tracking"] == 0.5 and record["margin_normals"] == "vertical"
    assert record["evaluation"]["terrain_config"] == {"step_height": [0.03, 0.09]}
    assert record["evaluation"]["forward_velocity"] == 0.75


@settings(max_examples=60, deadline=None)
@given(
    a=st.lists(st.floats(-100, 100), min_size=2, max_size=8),
    b=st.lists(st.floats(-100, 100), min_size=2, max_size=8),
)
def test_welch_interval_excludes_zero_exactly_when_the_test_is_significant(a: list[float], b: list[float]) -> None:
    result = compare_seeds("m", a, b)
    if result.p_value is None:
        assert result.welch_low is None and result.welch_high is None
        return
    assert result.welch_low <= result.difference <= result.welch_high
    excludes_zero = result.welch_low > 0 or result.welch_high < 0
    if abs(result.p_value - result.alpha) > 1e-6:  # away from the boundary, where rounding decides
        assert excludes_zero == result.significant


def test_welch_interval_matches_scipys_own() -> None:
    """Cross-check with scipy's interval of the same test (scipy's difference is a − b: negated and swapped)."""
    a, b = [0.52, 0.61, 0.47, 0.58, 0.55], [0.71, 0.69, 0.80, 0.66, 0.74]
    result = compare_seeds("stance", a, b)
    scipy_ci = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
    assert result.welch_low == pytest.approx(-scipy_ci.high, rel=1e-12)
    assert result.welch_high == pytest.approx(-scipy_ci.low, rel=1e-12)


def _grid_report(variants: dict[float, dict[int, dict[str, float]]], commands=(0.5, 1.0)) -> dict:
    """A compare report whose runs have the same metrics in the main cell and every grid cell (nominal only)."""

    def cell_variants() -> dict:
        return {
            f"weight {weight:g}": {
                "margin_weight": weight,
                "runs": [{"seed": seed, "metrics": dict(metrics)} for seed, metrics in runs.items()],
            }
            for weight, runs in variants.items()
        }

    settings = {"env_id": "x", "eval_episodes": 64, "eval_seed": 5000, "forward_velocity": 0.75, "warmup_s": 1.0}
    grid = [{"condition": "nominal", "forward_velocity": c, "variants": cell_variants()} for c in commands]
    return {"settings": settings, "variants": cell_variants(), "grid": grid}


def _metrics(fell: float, lin_acc: float) -> dict[str, float]:
    return {"fell": fell, "velocity_error_mean": 0.04, "lin_acc_rms": lin_acc, "ang_acc_rms": 100.0,
            "stance_width_mean": 0.5, "margin_mean": -0.2}  # fmt: skip


def test_sweep_grid_reads_the_committed_pilot_like_its_benchmark() -> None:
    """The committed two-seed ANYmal B pilot: weight 0.2 is not eligible, its worst cell friction 0.4 at 1.0 m/s
    (58 of 128 episodes against 8: +39.1 points), and the main cell's linear acceleration change is the report's."""
    module = _study("sweep_grid")
    path = ROOT / "docs" / "comparison" / "robust_pilot" / "compare_anymal_b.json"
    report = json.loads(path.read_text())
    result = module.sweep(*module.collect_runs([(str(path), report)]))
    verdict = result["rule"]["per_weight"]["0.2"]
    assert verdict["worst_cell"] == "friction_0.4__v1" and not verdict["eligible"]
    assert verdict["worst_excess_falls"] == pytest.approx((11 + 47 - 5 - 3) / 128)
    assert verdict["lin_acc_relative_main"] == pytest.approx(report["statistics"]["lin_acc_rms"]["relative"])
    assert result["rule"]["chosen"] is None and len(result["cells"]) == 12
    assert result["cells"][:3] == ["nominal__v0.5", "nominal__v0.75", "nominal__v1"]
    assert "| friction_0.4 1 m/s | 5 / 3 | 11 / 47 |" in module.markdown(result)


def test_sweep_grid_rule_prefers_the_largest_weight_that_reaches_the_acceleration_target() -> None:
    """Weights 0.1 (−20 % acceleration) and 0.5 (−10 %) within the falls tolerance, 0.2 one point and a half over it:
    0.1 is chosen; without 0.1, the largest eligible weight (0.5) although it misses the acceleration target."""
    module = _study("sweep_grid")
    runs = {
        0.0: {0: _metrics(0.0, 5.9), 1: _metrics(0.02, 6.1)},
        0.1: {0: _metrics(0.01, 4.7), 1: _metrics(0.03, 4.9)},
        0.2: {0: _metrics(0.0, 3.9), 1: _metrics(0.07, 4.1)},
        0.5: {0: _metrics(0.01, 5.3), 1: _metrics(0.03, 5.5)},
    }
    result = module.sweep(*module.collect_runs([("r", _grid_report(runs))]))
    rule = result["rule"]
    assert [w for w, v in rule["per_weight"].items() if v["eligible"]] == ["0.1", "0.5"]
    assert rule["per_weight"]["0.2"]["worst_excess_falls"] == pytest.approx(0.025)
    assert rule["chosen"] == "0.1" and rule["chosen_reaches_acceleration_target"]
    without = module.sweep(*module.collect_runs([("r", _grid_report({w: runs[w] for w in (0.0, 0.2, 0.5)}))]))
    assert without["rule"]["chosen"] == "0.5" and not without["rule"]["chosen_reaches_acceleration_target"]


def test_sweep_grid_refuses_reports_that_disagree_on_a_run() -> None:
    module = _study("sweep_grid")
    first = _grid_report({0.0: {0: _metrics(0.0, 6.0)}, 0.1: {0: _metrics(0.0, 5.0)}})
    second = _grid_report({0.0: {0: _metrics(0.0, 6.5)}, 0.5: {0: _metrics(0.0, 5.0)}})
    with pytest.raises(ValueError, match=r"margin weight 0, seed 0, .* b\.json and a\.json report different metrics"):
        module.collect_runs([("a.json", first), ("b.json", second)])
    other_protocol = json.loads(json.dumps(second))
    other_protocol["settings"]["eval_seed"] = 1
    with pytest.raises(ValueError, match="one evaluation protocol"):
        module.collect_runs([("a.json", first), ("c.json", other_protocol)])
    with pytest.raises(ValueError, match="needs runs of margin weight 0"):
        module.sweep(*module.collect_runs([("d.json", _grid_report({0.1: {0: _metrics(0.0, 5.0)}}))]))


def test_stance_scaling_moves_only_the_feet_sideways() -> None:
    """bench_margin_stance_width: the stance width of lambda (envs.stability_input.stance_width, computed
    independently) scales by s, the feet's mean lateral position and every other entry stay as they were."""
    from margin_rl.envs.stability_input import stance_width
    from margin_rl.robot import load_robot
    from margin_rl.stability import LAMBDA_SLICES, sample_states

    module = _study("bench_margin_stance_width")
    lam = sample_states(load_robot("anymal_b"), 16, seed=3)
    feet = LAMBDA_SLICES["feet"]
    for scale in (0.8, 1.0, 1.25):
        scaled = module.with_stance_scaled(lam, scale)
        before, after = lam[:, feet].reshape(-1, 4, 3), scaled[:, feet].reshape(-1, 4, 3)
        np.testing.assert_allclose(stance_width(after), scale * stance_width(before), rtol=1e-12)
        np.testing.assert_allclose(after[:, :, 1].mean(axis=1), before[:, :, 1].mean(axis=1), atol=1e-15)
        np.testing.assert_array_equal(
            np.delete(scaled, np.r_[feet][1::3], axis=1), np.delete(lam, np.r_[feet][1::3], axis=1)
        )


def test_headline_table_reads_a_card_like_the_compare_report_it_was_written_from() -> None:
    """The committed two-seed ANYmal B pilot report, and the bundle card that report would give (its tables and
    grid, as ``write_bundle`` stores them): the same flat-ground rows, falls counted over every seed's episodes."""
    from margin_rl.train.artifacts.bundle import _measured_differences, _variant_table

    module = _study("headline_table")
    report = json.loads((ROOT / "docs" / "comparison" / "robust_pilot" / "compare_anymal_b.json").read_text())
    card = {
        "settings": report["settings"],
        "table": _variant_table(report["variants"]),
        **_measured_differences(report),
        "policies": [
            {"variant": name, "seed": run["seed"]} for name, v in report["variants"].items() for run in v["runs"]
        ],
    }
    from_report = module.flat_rows("B", module.as_report(report))
    assert module.flat_rows("B", module.as_report(card)) == from_report
    assert [row.split(" | ")[1] for row in from_report] == ["0.5", "0.75", "1"]
    episodes = report["settings"]["eval_episodes"]
    runs = report["variants"]["with margin"]["runs"]
    falls = round(sum(run["metrics"]["fell"] for run in runs) * episodes)
    assert f"→ {falls} / {episodes * len(runs)} |" in from_report[1]


def test_headline_push_rows_test_each_impulse_over_seeds() -> None:
    from scipy import stats

    module = _study("headline_table")

    def policy(survival: list[float]) -> dict:
        curve = {"direction": "lateral", "forward_velocity": 0.75, "impulses": [30.0, 45.0], "survival": survival}
        return {"curves": [curve]}

    without, with_margin = [[1.0, 0.5], [0.9, 0.4], [1.0, 0.6]], [[0.5, 0.1], [0.7, 0.0], [0.6, 0.2]]
    push = {
        "protocol": {"directions": ["lateral"], "impulses": [30.0, 45.0], "forward_velocities": [0.75]},
        "variants": {
            "without margin": {"policies": [policy(s) for s in without]},
            "with margin": {"policies": [policy(s) for s in with_margin]},
        },
    }
    (row,) = module.push_rows("B", push, 0.75, [30.0, 45.0])
    cells = row.split(" | ")[2:]
    for index, cell in enumerate(cells):
        a, b = [s[index] for s in without], [s[index] for s in with_margin]
        p_value = stats.ttest_ind(b, a, equal_var=False).pvalue
        assert cell.startswith(f"{np.mean(a):.2f} → {np.mean(b):.2f} (") and f"{p_value:.2g}" in cell


def test_headline_robot_table_is_the_flat_rows_pushes_and_mismatch_by_command() -> None:
    """--per-robot: a column per command; the falls and flat-ground cells are the flat rows' own (one layout of the
    same numbers), the push rows the per-impulse tests, the mismatch row the off-nominal cells counted per command."""
    module = _study("headline_table")

    def cells(row: str) -> list[str]:
        return [cell.strip() for cell in row.strip().strip("|").split("|")]

    report = module.as_report(json.loads((ROOT / "train" / "bundled" / "anymal_c" / "card.json").read_text()))
    push = json.loads((ROOT / "docs" / "comparison" / "release" / "push_anymal_c.json").read_text())
    header, _, falls, *rows = module.robot_table(report, push, [("lateral", 45.0), ("longitudinal", 75.0)])
    assert cells(header)[1:] == ["0.5 m/s", "0.75 m/s", "1 m/s"]
    flat = [cells(row) for row in module.flat_rows("C", report)]  # robot, command, seeds, falls, three metrics
    assert cells(falls)[1:] == [row[3] for row in flat]
    for metric_row, column in zip(rows[:3], (4, 5, 6), strict=True):  # velocity error, linear and angular acceleration
        assert cells(metric_row)[1:] == [row[column] for row in flat]
    assert cells(rows[4])[2] == cells(module.push_rows("C", push, 0.75, [45.0])[1])[2]  # lateral 45 N s, 0.75 m/s
    conditions = sorted({c["condition"] for c in report["grid"]} - {"nominal"})
    mismatch = cells(rows[-1])
    assert mismatch[0] == f"model mismatch ({', '.join(conditions)})"
    assert all(cell.startswith("falls within +1 pt in ") and "/ 3)" in cell for cell in mismatch[1:])
    assert cells(header)[0] == f"without → with margin, {report['seeds']['with margin']} seeds each"
    three_against_five = {**report, "seeds": {"without margin": 3, "with margin": 5}}  # the field study's control
    assert cells(module.robot_table(three_against_five, push, [])[0])[0] == "without → with margin, 3 → 5 seeds"


def test_headline_mismatch_span_runs_from_the_weakest_change_to_the_strongest() -> None:
    module = _study("headline_table")

    def cell(condition: str, relative: float) -> dict:
        means = {name: {"mean": {"fell": 0.0}} for name in ("without margin", "with margin")}
        stats = {"lin_acc_rms": {"relative": relative, "p_value": 0.5}}
        return {"condition": condition, "forward_velocity": 1.0, "variants": means, "statistics": stats}

    for changes, span in (((0.35, 0.16, 0.2), "+16 % to +35 %"), ((-0.12, -0.14), "−12 % to −14 %")):
        report = {"grid": [cell(f"c{k}", change) for k, change in enumerate(changes)]}
        assert f"lin. acc. {span} (p < 0.05 in 0 / {len(changes)})" in module._mismatch_text(report, 1.0)


def test_headline_rough_rows_count_falls_and_their_causes_over_every_seeds_episodes() -> None:
    """--rough: per command of a report evaluated on rough ground, the falls and each cause as counts over seeds ×
    episodes (fractions × episodes, summed over seeds), the metrics "without → with" with the report's own p."""
    module = _study("headline_table")

    def rough_variants(falls: list[float], thigh: list[float], shift: float) -> dict:
        variants = {}
        for name, fell, thighs in (("without margin", falls, thigh), ("with margin", [0.0] * 3, [0.0] * 3)):
            runs = []
            for seed in range(3):
                metrics = {key: 1.0 + shift * (name == "with margin") + 0.01 * seed for key in SUMMARY_METRICS}
                metrics.update({key: 0.0 for key in TERRAIN_METRICS})
                metrics.update({"fell": fell[seed], "termination/thigh_contact": thighs[seed]})
                metrics["termination/tilt"] = fell[seed] - thighs[seed]
                runs.append({"seed": seed, "metrics": metrics})
            keys = [*SUMMARY_METRICS, *TERRAIN_METRICS]
            mean = {k: float(np.mean([r["metrics"][k] for r in runs])) for k in keys}
            std = {k: float(np.std([r["metrics"][k] for r in runs])) for k in keys}
            variants[name] = {"margin_weight": 0.1 * (name == "with margin"), "runs": runs, "mean": mean, "std": std}
        return variants

    main_cell = rough_variants([0.25, 0.125, 0.0], [0.125, 0.0, 0.0], shift=-0.5)
    slow_cell = rough_variants([0.0, 0.125, 0.0], [0.0, 0.125, 0.0], shift=-0.2)
    statistics = {k: asdict(d) for k, d in compare_variants(main_cell).items()}
    report = {
        "settings": {"eval_episodes": 8, "forward_velocity": 0.75},
        "variants": main_cell,
        "statistics": statistics,
        "grid": [
            {
                "condition": "nominal",
                "forward_velocity": 0.5,
                "variants": slow_cell,
                "statistics": {k: asdict(d) for k, d in compare_variants(slow_cell).items()},
            }
        ],
    }
    slow, main = module.rough_rows("0.75", module.as_report(report))  # commands ascending
    assert slow.startswith("| 0.75 | 0.5 | 3 | 1 / 24 → 0 / 24 | 1 / 0 / 0 / 0 → 0 / 0 / 0 / 0 |")
    assert main.startswith("| 0.75 | 0.75 | 3 | 3 / 24 → 0 / 24 | 1 / 0 / 2 / 0 → 0 / 0 / 0 / 0 |")
    p_value = statistics["lin_acc_rms"]["p_value"]
    assert f"(−50 %, **p {'< 0.001' if p_value < 0.001 else f'= {p_value:.2g}'}**)" in main
    for cell in (main_cell, *(c["variants"] for c in report["grid"])):  # a report made before the terrain columns
        for variant in cell.values():
            variant["mean"] = {k: v for k, v in variant["mean"].items() if k in SUMMARY_METRICS}
    with pytest.raises(ValueError, match="not evaluated on rough ground"):
        module.rough_rows("0.75", module.as_report(report))


def test_headline_cost_rows_are_the_runs_episode_metrics_tested_over_seeds() -> None:
    """--cost-rows: joint-torque RMS, the share of steps at a torque limit and the margin term's share of the reward,
    "without → with" means over the runs' own episode metrics with Welch's p over seeds (the field study's pilot)."""
    module = _study("headline_table")
    pilot = ROOT / "docs" / "comparison" / "field" / "pilot_c" / "compare.json"
    report = module.as_report(json.loads(pilot.read_text()))
    lines = module.robot_table(report, {}, [], cost_rows=True)
    rows = {row.split("|")[1].strip(): [c.strip() for c in row.strip().strip("|").split("|")[1:]] for row in lines[3:]}
    at_075 = module.nominal_cells(report)[1]
    assert at_075["forward_velocity"] == 0.75
    for label, metric, fmt, _ in module.COST_ROWS:
        a, b = ([run["metrics"][metric] for run in at_075["variants"][name]["runs"]] for name in module.VARIANTS)
        text = rows[label][1]
        assert text.startswith(f"{np.mean(a):{fmt}} → {np.mean(b):{fmt}} (")
        if np.std(a) + np.std(b) > 0:
            assert f"{stats.ttest_ind(b, a, equal_var=False).pvalue:.2g}" in text
    assert rows["margin term's share of the reward"][1].startswith("0.000 → ")  # the baseline has no margin term
