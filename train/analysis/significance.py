"""Comparing one metric between two variants over training seeds: difference, bootstrap interval, Welch test.

The unit of observation is the **training seed**: each seed contributes one value, its mean over its evaluation
episodes. Episodes of one policy are not independent samples of the training outcome (they share the trained
weights), so treating them as observations would shrink the intervals and p-values by a factor that grows with
the number of episodes without saying anything more about the training method. With a few seeds per variant the
tests have little power: "not significant" is not "no difference".

For the values a₁…a_na of variant a (the baseline) and b₁…b_nb of variant b, with means ā, b̄ and sample
variances s_a², s_b² (ddof 1), :func:`compare_seeds` reports

* the difference d = b̄ − ā and the relative difference d / |ā|;
* Welch's two-sided test (unequal variances; ``scipy.stats.ttest_ind(equal_var=False)``)::

      t = d / √(s_a²/n_a + s_b²/n_b)
      ν = (s_a²/n_a + s_b²/n_b)² / [(s_a²/n_a)²/(n_a − 1) + (s_b²/n_b)²/(n_b − 1)]   (Welch–Satterthwaite)
      p = 2 P(T_ν > |t|)                                                           (Student's t with ν df)

  and the difference is *significant* when p < α; the matching 1 − α interval d ± t_{1−α/2, ν} · √(s_a²/n_a +
  s_b²/n_b) (``welch_low``/``welch_high``) excludes 0 exactly when the difference is significant;
* a 1 − α bootstrap confidence interval of d (percentile method): each variant's seeds are resampled with
  replacement, independently of the other's, ``resamples`` times, and the interval runs from the α/2 to the
  1 − α/2 quantile of the resampled differences of means. A fixed generator seed makes it reproducible. With few
  seeds the percentile interval is narrower than its nominal level (a resampled mean varies √((n − 1)/n) times
  as much as the mean does, and three seeds give only 10 distinct resampled means): it describes the spread,
  and significance is decided by the Welch test alone.

Missing values (None, NaN, ±inf: e.g. an acceleration RMS no episode of a seed could give) are dropped, and
``n_a``/``n_b`` count the seeds left. Without a test (fewer than two seeds in a variant, or no variance in
either), ``p_value`` and ``significant`` are None and ``note`` says why; with fewer than two seeds the interval
is None too.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from margin_rl.train.analysis.conditions import DEFAULT_CONDITION
from margin_rl.train.metrics import SUMMARY_METRICS, table_metrics

ALPHA = 0.05
RESAMPLES = 10_000
MIN_RESAMPLES = 100  # fewer puts the interval's ends on a handful of resamples


@dataclass(frozen=True)
class Difference:
    """One metric of variant b against variant a over training seeds (see the module docstring for the maths).

    ``difference`` is b − a; ``relative`` is the difference over |mean_a| (None when mean_a is 0 or missing);
    ``ci_low``/``ci_high`` bound the 1 − ``alpha`` bootstrap interval of the difference; ``p_value`` is Welch's
    two-sided p; ``n_a``/``n_b`` count the seeds with a finite value. Values that could not be computed are None,
    with the reason in ``note``. ``significant`` (derived): p < alpha, None without a test.
    """

    metric: str
    mean_a: float | None
    mean_b: float | None
    difference: float | None
    relative: float | None
    ci_low: float | None
    ci_high: float | None
    p_value: float | None
    n_a: int
    n_b: int
    alpha: float = ALPHA
    note: str | None = None
    welch_low: float | None = None
    welch_high: float | None = None
    significant: bool | None = field(init=False)

    def __post_init__(self) -> None:
        # A field rather than a property, so that dataclasses.asdict (the JSON reports) includes it.
        significant = None if self.p_value is None else bool(self.p_value < self.alpha)
        object.__setattr__(self, "significant", significant)


def finite_seed_values(metric: str, values: Any, group: str = "values") -> np.ndarray:
    """The finite values of a 1-D sequence of numbers (None, NaN and ±inf dropped: seeds without a value).

    Raises ValueError naming ``metric`` and ``group`` for anything else (strings, nested sequences, ...).
    """
    if isinstance(values, np.ndarray):
        items = values.tolist() if values.ndim == 1 else None
    elif isinstance(values, Sequence) and not isinstance(values, (str, bytes)):
        items = list(values)
    else:
        items = None
    if items is None or not all(v is None or isinstance(v, numbers.Real) for v in items):
        raise ValueError(
            f"{metric}: {group} must be a 1-D sequence of numbers (None or NaN for a seed without a value), "
            f"got {values!r}"
        )
    array = np.array([math.nan if v is None else float(v) for v in items], dtype=float)
    return array[np.isfinite(array)]


def _check_settings(alpha: float, resamples: int) -> None:
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must lie in (0, 1), got {alpha}")
    if resamples < MIN_RESAMPLES:
        raise ValueError(f"resamples must be at least {MIN_RESAMPLES}, got {resamples}")


def _resampled_means(values: np.ndarray, resamples: int, rng: np.random.Generator) -> np.ndarray:
    """Means of ``resamples`` resamples of ``values`` with replacement."""
    picks = rng.integers(0, values.size, size=(resamples, values.size))
    return values[picks].mean(axis=1)


def _content_key(values: np.ndarray) -> tuple[int, tuple[float, ...]]:
    return values.size, tuple(np.sort(values).tolist())


def bootstrap_interval(
    values_a: np.ndarray, values_b: np.ndarray, confidence: float, resamples: int = RESAMPLES, seed: int = 0
) -> tuple[float, float]:
    """Percentile bootstrap interval of mean(b) − mean(a), each group resampled independently (non-empty inputs).

    The generator's draws go to the groups in an order fixed by their contents, not by which one is called a,
    so that swapping a and b gives exactly the negated interval; two groups with the same values give the
    symmetric interval ±(``confidence`` quantile of |difference|), the same under either labelling.
    """
    rng = np.random.default_rng(seed)
    key_a, key_b = _content_key(values_a), _content_key(values_b)
    if key_a == key_b:  # the same values in another order: resample one sorted copy, so the order cannot matter
        values_a = values_b = np.sort(values_a)
    if key_b < key_a:
        means_b = _resampled_means(values_b, resamples, rng)
        means_a = _resampled_means(values_a, resamples, rng)
    else:
        means_a = _resampled_means(values_a, resamples, rng)
        means_b = _resampled_means(values_b, resamples, rng)
    differences = means_b - means_a
    if key_a == key_b:
        half_width = float(np.percentile(np.abs(differences), 100 * confidence))
        return 0.0 - half_width, half_width  # 0.0 - 0.0 is 0.0, where -0.0 would print as "-0"
    tail = 50 * (1 - confidence)
    low, high = np.percentile(differences, [tail, 100 - tail])
    return float(low), float(high)


def welch_p_value(values_a: np.ndarray, values_b: np.ndarray) -> float:
    """Two-sided p-value of Welch's t-test (at least two values per group and some variance in one of them)."""
    return float(stats.ttest_ind(values_a, values_b, equal_var=False).pvalue)


def welch_interval(values_a: np.ndarray, values_b: np.ndarray, confidence: float) -> tuple[float, float]:
    """The ``confidence`` interval of mean(b) − mean(a) that inverts Welch's test (testable groups only)."""
    va, vb = values_a.var(ddof=1) / values_a.size, values_b.var(ddof=1) / values_b.size
    share_a, share_b = va / (va + vb), vb / (va + vb)  # scale-free: tiny variances would underflow when squared
    df = 1.0 / (share_a**2 / (values_a.size - 1) + share_b**2 / (values_b.size - 1))
    half_width = float(stats.t.ppf(0.5 + confidence / 2, df) * math.sqrt(va + vb))
    difference = float(values_b.mean() - values_a.mean())
    return difference - half_width, difference + half_width


def _untestable(values_a: np.ndarray, values_b: np.ndarray, names: tuple[str, str]) -> str | None:
    """Why the two groups admit no test, or None when they do."""
    for values, name in zip((values_a, values_b), names, strict=True):
        if values.size < 2:
            return f"fewer than 2 seeds with a value in {name}: {values.size}"
    # Welch's squared standard error, as the test computes it: zero (or underflowed) leaves t undefined.
    if values_a.var(ddof=1) / values_a.size + values_b.var(ddof=1) / values_b.size == 0:
        return "no variance over seeds in either variant: Welch's t is undefined"
    return None


def compare_seeds(
    metric: str,
    values_a: Sequence[float | None] | np.ndarray,
    values_b: Sequence[float | None] | np.ndarray,
    alpha: float = ALPHA,
    resamples: int = RESAMPLES,
    seed: int = 0,
    names: tuple[str, str] = ("a", "b"),
) -> Difference:
    """Compare ``metric`` of variant b (``values_b``: one value per training seed) against variant a.

    ``names``: the variants' names, used in notes and error messages. Raises ValueError for values that are not
    a 1-D sequence of numbers (naming the metric), alpha outside (0, 1) or fewer than 100 resamples.
    """
    _check_settings(alpha, resamples)
    a = finite_seed_values(metric, values_a, names[0])
    b = finite_seed_values(metric, values_b, names[1])
    mean_a = float(a.mean()) if a.size else None
    mean_b = float(b.mean()) if b.size else None
    difference = None if mean_a is None or mean_b is None else mean_b - mean_a
    relative = None if difference is None or mean_a == 0 else difference / abs(mean_a)
    note = _untestable(a, b, names)
    p_value = None if note else welch_p_value(a, b)
    welch_low, welch_high = (None, None) if note else welch_interval(a, b, 1 - alpha)
    # No interval from a single seed: its resampled mean never varies, which would pass for certainty.
    ci_low, ci_high = (None, None) if min(a.size, b.size) < 2 else bootstrap_interval(a, b, 1 - alpha, resamples, seed)
    return Difference(
        metric,
        mean_a,
        mean_b,
        difference,
        relative,
        ci_low,
        ci_high,
        p_value,
        int(a.size),
        int(b.size),
        alpha,
        note,
        welch_low,
        welch_high,
    )


def seed_values(variant: Mapping[str, Any], metric: str) -> list[float | None]:
    """One value per run of a ``compare`` report's variant (None where the run has none)."""
    return [run["metrics"].get(metric) for run in variant["runs"]]


def compare_variants(
    variants_report: Mapping[str, Mapping[str, Any]],
    baseline: str = "without margin",
    other: str = "with margin",
    *,
    alpha: float = ALPHA,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> dict[str, Difference]:
    """Every column of the report (:func:`~margin_rl.train.metrics.table_metrics`: the summary metrics, and on
    rough ground the terrain metrics) of ``other`` against ``baseline``.

    ``variants_report``: ``report["variants"]`` of :func:`margin_rl.train.commands.compare.evaluate_variants` (each
    variant
    has ``runs``, each run ``metrics: {metric: value}``). Raises ValueError when either variant is missing.
    """
    missing = [name for name in (baseline, other) if name not in variants_report]
    if missing:
        raise ValueError(f"no variant {missing[0]!r} in the report (variants: {sorted(variants_report)})")
    a, b = variants_report[baseline], variants_report[other]
    return {
        metric: compare_seeds(
            metric, seed_values(a, metric), seed_values(b, metric), alpha, resamples, seed, (baseline, other)
        )
        for metric in table_metrics({baseline: a, other: b})
    }


def _number_cell(value: float | None, spec: str) -> str:
    return "n/a" if value is None else f"{value:{spec}}"


def _interval_cell(difference: Mapping[str, Any], low_key: str = "ci_low", high_key: str = "ci_high") -> str:
    low, high = difference.get(low_key), difference.get(high_key)
    return "n/a" if low is None or high is None else f"[{low:+.3g}, {high:+.3g}]"


def _significant_cell(difference: Mapping[str, Any]) -> str:
    if difference["significant"] is None:
        return f"n/a ({difference['note']})"
    return "yes" if difference["significant"] else "no"


def difference_table(
    rows: Iterable[tuple[Sequence[str], Mapping[str, Any]]],
    row_headers: Sequence[str] = ("metric",),
    difference_header: str = "difference (b − a)",
) -> list[str]:
    """Markdown lines of a table of differences: per row its label cells, then the difference, relative
    difference, Welch interval, Welch p, whether it is significant (n/a with the note without a test) and the
    bootstrap interval.

    ``rows``: (label cells, :class:`Difference` as a dict, e.g. from ``dataclasses.asdict`` or a JSON report),
    all with the same ``alpha`` (the header states the first row's).
    """
    rows = list(rows)
    alpha = rows[0][1]["alpha"] if rows else ALPHA  # one test level per table: the first row's
    level = f"{100 * (1 - alpha):g} % CI"
    headers = [
        *row_headers,
        difference_header,
        "relative",
        f"{level} (Welch)",
        "p (Welch)",
        f"significant (p < {alpha:g})",
        f"{level} (bootstrap)",
    ]
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for labels, d in rows:
        cells = [
            *labels,
            _number_cell(d["difference"], "+.4g"),
            _number_cell(d["relative"], "+.1%"),
            _interval_cell(d, "welch_low", "welch_high"),
            _number_cell(d["p_value"], ".3g"),
            _significant_cell(d),
            _interval_cell(d),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


GRID_METRICS: tuple[tuple[str, str], ...] = (
    ("fell", ".3f"),
    ("velocity_error_mean", ".3f"),
    ("lin_acc_rms", ".2f"),
    ("ang_acc_rms", ".1f"),
)
"""Metrics of the grid table (key, format)."""
GRID_VARIANTS = ("without margin", "with margin")
"""The grid table's variants, baseline first."""


def grid_table(report: dict[str, Any]) -> list[str]:
    """Markdown lines: one row per evaluation cell (conditions in the settings' order, commands ascending, the main
    cell among them), per metric both variants' mean over training seeds as "without → with" and Welch's p over
    seeds of the difference.

    ``report``: a ``compare`` report (its ``settings``, the main cell's ``variants`` and ``statistics``, and
    ``grid``), or the same keys from a bundle card (:func:`margin_rl.train.artifacts.bundle.card_markdown`)."""
    s = report["settings"]
    main = {"condition": DEFAULT_CONDITION, "forward_velocity": s["forward_velocity"], **report}
    order = list(dict.fromkeys((DEFAULT_CONDITION, *s.get("grid_conditions", ()))))
    cells = sorted([main, *report["grid"]], key=lambda c: (order.index(c["condition"]), c["forward_velocity"]))
    header = " | ".join(SUMMARY_METRICS.get(metric, metric) for metric, _ in GRID_METRICS)
    lines = [
        "Across evaluation conditions (margin_rl.train.analysis.conditions) and commands, the same policies, "
        "episodes and seeds: without → with margin, each the mean over training seeds, and Welch's two-sided p over "
        "seeds of the difference (– with fewer than two seeds per variant).",
        "",
        f"| condition | command [m/s] | {header} |",
        "|---|---|" + "---|" * len(GRID_METRICS),
    ]
    for cell in cells:
        row = f"| {cell['condition']} | {cell['forward_velocity']:g} |"
        for metric, fmt in GRID_METRICS:
            means = [cell["variants"].get(name, {}).get("mean", {}).get(metric) for name in GRID_VARIANTS]
            text = " → ".join("–" if m is None else f"{m:{fmt}}" for m in means)
            p_value = cell.get("statistics", {}).get(metric, {}).get("p_value")
            row += f" {text}{'' if p_value is None else f' (p = {p_value:.2g})'} |"
        lines.append(row)
    return lines
