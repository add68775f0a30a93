"""The fall analysis's measurements: each a JSON-ready dict of per-variant spreads over the policies.

Every figure is computed per policy (a training seed) over its episodes, steps or labelled states, then reported
as mean ± std over the policies of a variant (:func:`spread`); :func:`variant_differences` compares the headline
figures of the two variants over training seeds with the package's
:func:`~margin_rl.train.analysis.significance.compare_seeds` (Welch test and bootstrap interval).

::

    fall_summary     fall fractions (overall, per evaluation seed, early / late), fall times, termination causes
    gait_summary     foot contact shares and contact sets before falls and in the steady gait
    trend_summary    base state and learned margin at fixed times before the fall, against the steady gait
    reward_summary   per-step reward terms, the margin term's share of the return, the margin's clip floor
    margin_summary   learned margin against m_x and m_a on the labelled states
    posture_probe    the change of both margins when steady states are lowered or widened in lambda
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict
from typing import Any

import numpy as np

from benchmarks.studies.fall_episodes import CAUSES, LEGS, Episodes
from margin_rl.envs.core import MARGIN_CLIP
from margin_rl.robot import load_robot
from margin_rl.stability.analytic.extended import extended_margin_batch
from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES
from margin_rl.stability.analytic.margin import STATUSES
from margin_rl.stability.learned.model import LearnedMargin
from margin_rl.train.analysis.significance import compare_seeds, difference_table, finite_seed_values

TREND_OFFSETS_S: tuple[float, ...] = (1.0, 0.5, 0.2, 0.0)  # seconds before the fall step
EARLY_FALL_S = 2.0  # falls this soon after the reset are start-up failures (the baseline's falls cluster there)
STEADY_PERCENTILES: tuple[int, ...] = (5, 95)  # how far the steady gait itself reaches towards fall-step values
PROBE_SHIFT_M = 0.05  # posture probe: CoM this much lower, or stance this much wider
LEFT_LEGS = np.array([leg.startswith("L") for leg in LEGS])
LABELLED = "labelled states"
PATTERNS = "most common patterns (pooled share)"
UNSTABLE_STATUSES = (STATUSES.index("infeasible"), STATUSES.index("no_contact"))  # no Feasible Region

Groups = dict[str, list[Episodes]]
"""Variant -> its policies' episodes."""


# ---------------------------------------------------------------------------------------------------------------------
# statistics
# ---------------------------------------------------------------------------------------------------------------------
def spread(values: Sequence[float | None]) -> dict[str, Any]:
    """Mean ± std (population, as the card) over the policies that gave a finite value, and the values."""
    finite = finite_seed_values("value", list(values))
    return {
        "mean": float(finite.mean()) if finite.size else math.nan,
        "std": float(finite.std()) if finite.size else math.nan,
        "policies": int(finite.size),
        "sum": float(finite.sum()),
        "per_policy": [float(v) if v is not None and math.isfinite(v) else None for v in values],
    }


def masked_mean(values: np.ndarray, mask: np.ndarray) -> float:
    """Mean of ``values`` where ``mask`` holds and the value is finite; NaN when there is none."""
    chosen = values[mask]
    chosen = chosen[np.isfinite(chosen)]
    return float(chosen.mean()) if chosen.size else math.nan


def across(groups: Groups, metric: Callable[[Episodes], float]) -> dict[str, dict[str, Any]]:
    """Variant -> :func:`spread` of ``metric`` over its policies."""
    return {variant: spread([metric(e) for e in policies]) for variant, policies in groups.items()}


def at_fall(episodes: Episodes, values: np.ndarray, seconds_before: float) -> np.ndarray:
    """``values`` (T, N) at ``seconds_before`` the fall step of each falling episode (NaN before the start)."""
    index = episodes.length[episodes.fell] - 1 - round(seconds_before / episodes.dt)
    columns = np.flatnonzero(episodes.fell)
    out = np.full(len(columns), np.nan)
    ok = index >= 0
    out[ok] = values[index[ok], columns[ok]]
    return out


def masked_percentile(values: np.ndarray, mask: np.ndarray, q: float) -> float:
    """``q``-th percentile of the finite masked ``values``; NaN when there is none."""
    chosen = values[mask]
    chosen = chosen[np.isfinite(chosen)]
    return float(np.percentile(chosen, q)) if chosen.size else math.nan


def mean_at_fall(episodes: Episodes, values: np.ndarray, seconds_before: float) -> float:
    """Mean over the falls of :func:`at_fall` (the falls too early to look that far back left out)."""
    picked = at_fall(episodes, values, seconds_before)
    picked = picked[np.isfinite(picked)]
    return float(picked.mean()) if picked.size else math.nan


def pattern_codes(contacts: np.ndarray) -> np.ndarray:
    """Contact sets (..., 4) as integers 0..15 (bit i: leg i of :data:`LEGS` in contact)."""
    return (contacts.astype(np.int64) << np.arange(len(LEGS))).sum(axis=-1)


def pattern_name(code: int) -> str:
    """'LF+RH' style name of a contact-set code, 'none' for a flight phase."""
    names = [leg for i, leg in enumerate(LEGS) if code >> i & 1]
    return "+".join(names) if names else "none"


def pattern_shares(codes: np.ndarray, top: int | None = None) -> dict[str, float]:
    """Share of each contact set among ``codes``, most common first (the ``top`` first only)."""
    counts = np.bincount(codes, minlength=2 ** len(LEGS))
    order = [int(c) for c in np.argsort(-counts, kind="stable") if counts[c]][:top]
    return {pattern_name(c): float(counts[c] / counts.sum()) for c in order}


# ---------------------------------------------------------------------------------------------------------------------
# the analyses (each returns a JSON-ready dict)
# ---------------------------------------------------------------------------------------------------------------------
def fall_summary(groups: Groups, seeds: Sequence[int]) -> dict[str, Any]:
    """Fall fraction (overall and per evaluation seed), time of the falls and the termination causes."""

    def fraction(seed: int | None) -> Callable[[Episodes], float]:
        def metric(e: Episodes) -> float:
            chosen = np.ones_like(e.fell) if seed is None else e.eval_seed == seed
            return float(e.fell[chosen].mean())

        return metric

    def timed(early: bool) -> Callable[[Episodes], float]:
        def metric(e: Episodes) -> float:
            soon = e.length * e.dt <= EARLY_FALL_S
            return float(np.mean(e.fell & (soon if early else ~soon)))

        return metric

    def cause_share(i: int) -> Callable[[Episodes], float]:
        return lambda e: float(e.causes[e.fell, i].mean()) if e.fell.any() else math.nan

    pooled = {}
    for variant, policies in groups.items():
        times = np.concatenate([e.fall_times() for e in policies])
        episode_s = policies[0].reward.shape[0] * policies[0].dt
        combos = Counter(
            "+".join(c for c, f in zip(CAUSES, flags, strict=True) if f) or "?"
            for e in policies
            for flags in e.causes[e.fell]
        )
        thighs = np.concatenate([e.thighs[e.fell] for e in policies]).sum(axis=0) if len(times) else np.zeros(4)
        pooled[variant] = {
            "episodes": int(sum(len(e.fell) for e in policies)),
            "falls": len(times),
            "fall_time_s": _quantiles(times),
            "falls_within_first_s": {f"{s:g}": int(np.sum(times <= s)) for s in (1.0, 2.0, 5.0)},
            "fall_time_histogram_s": np.histogram(times, bins=np.arange(0.0, episode_s + 1.0, 1.0))[0].tolist(),
            "cause_combinations": dict(combos.most_common()),
            "thigh_contacts_at_fall": dict(zip(LEGS, thighs.astype(int).tolist(), strict=True)),
            "thigh_geoms_on_floor_at_fall": dict(sum((e.thigh_geoms for e in policies), Counter()).most_common()),
        }
    return {
        "fraction": across(groups, fraction(None)),
        "fraction_per_eval_seed": {str(s): across(groups, fraction(s)) for s in seeds},
        f"fraction_within_{EARLY_FALL_S:g}_s": across(groups, timed(early=True)),
        f"fraction_after_{EARLY_FALL_S:g}_s": across(groups, timed(early=False)),
        "fall_time_s_median": across(groups, lambda e: float(np.median(e.fall_times())) if e.fell.any() else math.nan),
        "cause_share": {c: across(groups, cause_share(i)) for i, c in enumerate(CAUSES)},
        "pooled": pooled,
    }


def _quantiles(values: np.ndarray) -> dict[str, float]:
    """Min, quartiles and max of ``values``; empty when there are none."""
    if not len(values):
        return {}
    q = np.percentile(values, [0, 25, 50, 75, 100])
    return dict(zip(("min", "p25", "median", "p75", "max"), q.tolist(), strict=True))


def gait_summary(groups: Groups, window_s: float) -> dict[str, Any]:
    """Foot contact shares and feet-in-contact counts before falls and in the steady gait."""
    windows: dict[str, Callable[[Episodes], np.ndarray]] = {
        f"last {window_s:g} s before fall": lambda e: e.before_fall(window_s),
        "steady (non-falling, after 1 s)": Episodes.steady,
    }
    out: dict[str, Any] = {}
    for label, window in windows.items():
        entry: dict[str, Any] = {}
        for i, leg in enumerate(LEGS):
            entry[f"{leg} in contact"] = across(groups, lambda e, i=i, w=window: masked_mean(e.contacts[..., i], w(e)))
        for k in range(len(LEGS) + 1):
            entry[f"{k} feet in contact"] = across(
                groups, lambda e, k=k, w=window: masked_mean((e.contacts.sum(axis=-1) == k).astype(float), w(e))
            )
        entry[PATTERNS] = {
            variant: pattern_shares(np.concatenate([pattern_codes(e.contacts[window(e)]) for e in policies]), top=6)
            for variant, policies in groups.items()
        }
        out[label] = entry
    out["pattern at the fall step (pooled share)"] = {
        variant: pattern_shares(
            np.concatenate([pattern_codes(e.contacts[e.length[e.fell] - 1, np.flatnonzero(e.fell)]) for e in policies])
        )
        for variant, policies in groups.items()
    }
    return out


def trend_summary(groups: Groups) -> dict[str, Any]:
    """Base state and learned margin at fixed times before the fall, and their steady-gait means."""
    quantities: dict[str, Callable[[Episodes], np.ndarray]] = {
        "base height [m]": lambda e: e.height,
        "lowest knee height [m]": lambda e: e.knee_height,
        "stance width [m]": lambda e: e.stance_width,
        "tilt [deg]": lambda e: np.degrees(e.tilt),
        "forward velocity [m/s]": lambda e: e.lin_vel[..., 0],
        "|lateral velocity| [m/s]": lambda e: np.abs(e.lin_vel[..., 1]),
        "vertical velocity [m/s]": lambda e: e.lin_vel[..., 2],
        "|roll rate| [rad/s]": lambda e: np.abs(e.ang_vel[..., 0]),
        "|pitch rate| [rad/s]": lambda e: np.abs(e.ang_vel[..., 1]),
        "|yaw rate| [rad/s]": lambda e: np.abs(e.ang_vel[..., 2]),
        "feet in contact": lambda e: e.contacts.sum(axis=-1).astype(float),
        "learned margin [m]": lambda e: e.learned,
    }
    out: dict[str, Any] = {}
    for name, values in quantities.items():
        row = {"steady": across(groups, lambda e, v=values: masked_mean(v(e), e.steady()))}
        for q in STEADY_PERCENTILES:
            row[f"steady, {q}th percentile"] = across(
                groups, lambda e, v=values, q=q: masked_percentile(v(e), e.steady(), q)
            )
        for offset in TREND_OFFSETS_S:
            row[f"{offset:g} s before fall"] = across(groups, lambda e, v=values, o=offset: mean_at_fall(e, v(e), o))
        out[name] = row
    return out


def reward_summary(groups: Groups, window_s: float) -> dict[str, Any]:
    """Per-step means of every reward term and the total, the margin term's share of the return, and how
    often the margin sat at its clip floor, per class of steps."""
    classes: dict[str, Callable[[Episodes], np.ndarray]] = {
        "non-falling episodes": lambda e: e.alive() & ~e.fell[None, :],
        "falling episodes": lambda e: e.alive() & e.fell[None, :],
        f"last {window_s:g} s before fall": lambda e: e.before_fall(window_s),
    }
    terms = list(next(iter(groups.values()))[0].terms)
    out: dict[str, Any] = {}
    for label, steps in classes.items():
        entry = {f"{t} per step": across(groups, lambda e, t=t, s=steps: masked_mean(e.terms[t], s(e))) for t in terms}
        entry["total per step"] = across(groups, lambda e, s=steps: masked_mean(e.reward, s(e)))
        entry["margin term / return"] = across(groups, lambda e, s=steps: _share(e.terms["margin"], e.reward, s(e)))
        entry["margin at clip floor (share of steps)"] = across(
            groups, lambda e, s=steps: masked_mean((e.margin_env <= MARGIN_CLIP[0]).astype(float), s(e))
        )
        entry["return per episode"] = across(groups, lambda e, s=steps: _episode_return(e, s(e)))
        out[label] = entry
    return out


def _share(term: np.ndarray, reward: np.ndarray, mask: np.ndarray) -> float:
    """Sum of ``term`` over the masked steps divided by the sum of the reward (signed)."""
    total = float(reward[mask].sum())
    return float(term[mask].sum()) / total if mask.any() and total != 0 else math.nan


def _episode_return(episodes: Episodes, mask: np.ndarray) -> float:
    """Mean undiscounted return of the episodes that have masked steps, over those steps."""
    per_episode = np.where(mask, episodes.reward, 0.0).sum(axis=0)
    chosen = mask.any(axis=0)
    return float(per_episode[chosen].mean()) if chosen.any() else math.nan


def _learned_positive(e: Episodes) -> np.ndarray:
    return e.learned > 0


def _extended_negative(e: Episodes) -> np.ndarray:
    return e.extended < 0


def _no_region(e: Episodes) -> np.ndarray:
    return np.isin(e.status, UNSTABLE_STATUSES)


def _analytic_unstable(e: Episodes) -> np.ndarray:
    """m_a < 0, or no m_a because the state has no Feasible Region (infeasible load, no contact)."""
    return _no_region(e) | (e.analytic < 0)


MARGIN_CONDITIONS: dict[str, Callable[[Episodes], np.ndarray]] = {
    "learned > 0": _learned_positive,
    "m_x < 0": _extended_negative,
    "learned > 0 and m_x < 0": lambda e: _learned_positive(e) & _extended_negative(e),
    "learned > 0 and (m_a < 0 or undefined)": lambda e: _learned_positive(e) & _analytic_unstable(e),
    "m_a undefined (no Feasible Region)": _no_region,
    "sign agreement learned vs m_x": lambda e: (e.learned >= 0) == (e.extended >= 0),
}
"""Shares of labelled states reported by :func:`margin_summary` (each a (T, N) condition)."""

MARGIN_MEANS: dict[str, Callable[[Episodes], np.ndarray]] = {
    "learned mean [m]": lambda e: e.learned,
    "m_x mean [m]": lambda e: e.extended,
    "m_a mean where defined [m]": lambda e: e.analytic,
    "learned - m_x mean [m]": lambda e: e.learned - e.extended,
}


def _share_where(condition: np.ndarray, mask: np.ndarray) -> float:
    return float(condition[mask].mean()) if mask.any() else math.nan


def margin_summary(groups: Groups, window_s: float, weight: float) -> dict[str, Any]:
    """Learned margin against m_x and m_a on the labelled states, before falls and elsewhere; ``weight``: the
    margin weight of the reward (what each margin would have paid per step)."""
    classes: dict[str, Callable[[Episodes], np.ndarray]] = {
        f"last {window_s:g} s before fall": lambda e: e.before_fall(window_s),
        "falling episodes, earlier": lambda e: e.alive() & e.fell[None, :] & ~e.before_fall(window_s),
        "non-falling episodes": lambda e: e.alive() & ~e.fell[None, :],
    }
    paid: dict[str, Callable[[Episodes], np.ndarray]] = {
        f"{weight:g} x clip(learned): the margin term at weight {weight:g}": lambda e: (
            weight * np.clip(e.learned, *MARGIN_CLIP)
        ),
        f"{weight:g} x clip(m_x): the same term with m_x": lambda e: weight * np.clip(e.extended, *MARGIN_CLIP),
    }
    out: dict[str, Any] = {}
    for label, steps in classes.items():

        def labelled(e: Episodes, steps: Callable[[Episodes], np.ndarray] = steps) -> np.ndarray:
            return steps(e) & (e.status >= 0)

        entry = {LABELLED: across(groups, lambda e, m=labelled: float(m(e).sum()))}
        for name, condition in MARGIN_CONDITIONS.items():
            entry[name] = across(groups, lambda e, c=condition, m=labelled: _share_where(c(e), m(e)))
        for name, values in {**MARGIN_MEANS, **paid}.items():
            entry[name] = across(groups, lambda e, v=values, m=labelled: masked_mean(v(e), m(e)))
        out[label] = entry
    return out


# ---------------------------------------------------------------------------------------------------------------------
# posture probe
# ---------------------------------------------------------------------------------------------------------------------
def lower_com(lams: np.ndarray, drop: float) -> np.ndarray:
    """lambda with the CoM ``drop`` metres lower over the same feet (feet are relative to the CoM in H)."""
    out = lams.copy()
    feet = out[:, LAMBDA_SLICES["feet"]].reshape(-1, len(LEGS), 3)
    feet[..., 2] += drop
    out[:, LAMBDA_SLICES["feet"]] = feet.reshape(len(out), -1)
    return out


def widen_stance(lams: np.ndarray, extra: float) -> np.ndarray:
    """lambda with the left feet ``extra / 2`` further left and the right feet as much further right."""
    out = lams.copy()
    feet = out[:, LAMBDA_SLICES["feet"]].reshape(-1, len(LEGS), 3)
    feet[..., 1] += np.where(LEFT_LEGS, 0.5 * extra, -0.5 * extra)
    out[:, LAMBDA_SLICES["feet"]] = feet.reshape(len(out), -1)
    return out


PROBES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    f"CoM {100 * PROBE_SHIFT_M:g} cm lower": lambda lams: lower_com(lams, PROBE_SHIFT_M),
    f"stance {100 * PROBE_SHIFT_M:g} cm wider": lambda lams: widen_stance(lams, PROBE_SHIFT_M),
}
"""Posture changes applied to visited states: does each margin reward them?"""


def posture_probe(groups: Groups, model: LearnedMargin, states: int, workers: int) -> dict[str, Any]:
    """Change in the learned margin and in m_x when a labelled steady-gait state is lowered or widened
    (:data:`PROBES`), on up to ``states`` states per policy (fixed random subsample); m_x of the changed states
    is labelled here."""
    rng = np.random.default_rng(0)
    picked: list[tuple[str, Episodes, np.ndarray]] = []
    for policies in groups.values():
        for e in policies:
            candidates = np.flatnonzero((e.steady() & (e.status >= 0)).ravel())
            chosen = rng.choice(candidates, size=min(states, len(candidates)), replace=False)
            picked.append((e.variant, e, chosen))
    base = np.concatenate([e.lam.reshape(-1, e.lam.shape[-1])[i] for _, e, i in picked])
    robot = load_robot(picked[0][1].robot)
    out: dict[str, Any] = {}
    for name, change in PROBES.items():
        moved = change(base)
        moved_x = extended_margin_batch(robot, moved, workers=workers).margin
        moved_l = np.asarray(model(moved))
        per_policy: dict[str, dict[str, list[float]]] = {}
        start = 0
        for variant, e, chosen in picked:
            part = slice(start, start + len(chosen))
            start = part.stop
            d_learned = moved_l[part] - e.learned.ravel()[chosen]
            d_extended = moved_x[part] - e.extended.ravel()[chosen]
            rows = per_policy.setdefault(variant, {})
            for key, delta in (("learned", d_learned), ("m_x", d_extended)):
                finite = delta[np.isfinite(delta)]
                rows.setdefault(f"{key} change [m]", []).append(float(finite.mean()) if finite.size else math.nan)
                rows.setdefault(f"{key} rises (share)", []).append(
                    float((finite > 0).mean()) if finite.size else math.nan
                )
        keys = next(iter(per_policy.values()))
        out[name] = {k: {v: spread(per_policy[v][k]) for v in per_policy} for k in keys}
        out[name]["states per policy"] = {
            v: spread([float(len(c)) for w, _, c in picked if w == v]) for v in per_policy
        }
    return out


# ---------------------------------------------------------------------------------------------------------------------
# the two variants over training seeds
# ---------------------------------------------------------------------------------------------------------------------
def headline(report: dict[str, Any], window_s: float) -> dict[str, dict[str, dict[str, Any]]]:
    """The figures the two variants are compared on: label -> variant -> :func:`spread`."""
    falls, trends, margins = report["falls"], report["trends"], report["margins"]
    before = f"last {window_s:g} s before fall"
    rows = {
        "fall fraction": falls["fraction"],
        f"falling within the first {EARLY_FALL_S:g} s": falls[f"fraction_within_{EARLY_FALL_S:g}_s"],
        f"falling after {EARLY_FALL_S:g} s": falls[f"fraction_after_{EARLY_FALL_S:g}_s"],
    }
    for name in ("base height [m]", "lowest knee height [m]", "stance width [m]", "tilt [deg]", "feet in contact"):
        rows[f"steady gait: {name}"] = trends[name]["steady"]
    rows["reward per step, non-falling episodes"] = report["rewards"]["non-falling episodes"]["total per step"]
    for label in (before, "non-falling episodes"):
        rows[f"learned > 0 and m_x < 0, {label}"] = margins[label]["learned > 0 and m_x < 0"]
    return rows


def variant_differences(
    report: dict[str, Any], window_s: float, baseline: str = "without margin", other: str = "with margin"
) -> dict[str, dict[str, Any]]:
    """Each :func:`headline` figure of ``other`` against ``baseline`` over the policies (training seeds):
    :class:`~margin_rl.train.analysis.significance.Difference` as dicts; empty unless both variants were run."""
    rows = headline(report, window_s)
    if not rows or not {baseline, other} <= set(next(iter(rows.values()))):
        return {}
    return {
        label: asdict(
            compare_seeds(
                label, by_variant[baseline]["per_policy"], by_variant[other]["per_policy"], names=(baseline, other)
            )
        )
        for label, by_variant in rows.items()
    }


# ---------------------------------------------------------------------------------------------------------------------
# output
# ---------------------------------------------------------------------------------------------------------------------
def cell(stats: dict[str, Any], total: int, digits: int = 3) -> str:
    """'mean ± std', with '(k/n policies)' when fewer than all policies gave a value; '–' when none did."""
    if not stats["policies"]:
        return "–"
    text = f"{stats['mean']:.{digits}g} ± {stats['std']:.2g}"
    return text if stats["policies"] == total else f"{text} ({stats['policies']}/{total})"


def print_table(title: str, rows: dict[str, dict[str, dict[str, Any]]], variants: Sequence[str], total: int) -> None:
    """``rows``: row label -> variant -> spread; one column per variant."""
    print(f"\n{title}\n\n| | " + " | ".join(variants) + " |\n|---|" + "---|" * len(variants))
    for label, by_variant in rows.items():
        if label == LABELLED:  # a count: the total over the policies says more than its spread
            print(f"| {label} (all policies) | " + " | ".join(f"{by_variant[v]['sum']:,.0f}" for v in variants) + " |")
        else:
            print(f"| {label} | " + " | ".join(cell(by_variant[v], total) for v in variants) + " |")


def print_report(report: dict[str, Any], variants: Sequence[str], total: int) -> None:
    """Every table of the report, one column per variant (``total``: policies per variant)."""
    falls = report["falls"]
    rows = {"fall fraction": falls["fraction"]}
    rows |= {f"fall fraction, eval seed {s}": v for s, v in falls["fraction_per_eval_seed"].items()}
    rows[f"falling within the first {EARLY_FALL_S:g} s"] = falls[f"fraction_within_{EARLY_FALL_S:g}_s"]
    rows[f"falling after {EARLY_FALL_S:g} s"] = falls[f"fraction_after_{EARLY_FALL_S:g}_s"]
    rows["median fall time [s]"] = falls["fall_time_s_median"]
    rows |= {f"falls with {c}": v for c, v in falls["cause_share"].items()}
    print_table("## Falls (mean ± std over policies)", rows, variants, total)
    for variant, pooled in falls["pooled"].items():
        print(
            f"\n{variant}: {pooled['falls']} falls in {pooled['episodes']} episodes; fall time {pooled['fall_time_s']}"
        )
        print(f"  causes {pooled['cause_combinations']}; thighs at fall {pooled['thigh_contacts_at_fall']}")
        print(f"  thigh geoms on the terrain at the fall step: {pooled['thigh_geoms_on_floor_at_fall']}")
        print(f"  fall-time histogram (1 s bins) {pooled['fall_time_histogram_s']}")
        print(f"  falls within the first 1 / 2 / 5 s: {list(pooled['falls_within_first_s'].values())}")
    for window, entry in report["gait"].items():
        if window.startswith("pattern"):
            print(f"\n{window}: {entry}")
            continue
        shares_only = {k: v for k, v in entry.items() if k != PATTERNS}
        print_table(f"## Gait: {window}", shares_only, variants, total)
        for variant, shares in entry[PATTERNS].items():
            print(f"{variant} patterns: " + ", ".join(f"{p} {s:.0%}" for p, s in shares.items()))
    for name, row in report["trends"].items():
        print_table(f"## Trend: {name}", row, variants, total)
    for label, entry in report["rewards"].items():
        print_table(f"## Reward per step: {label}", entry, variants, total)
    for label, entry in report["margins"].items():
        print_table(f"## Learned vs extended/analytic margin: {label}", entry, variants, total)
    for label, entry in report["posture_probe"].items():
        print_table(f"## Posture probe on steady-gait states: {label}", entry, variants, total)
    if report.get("differences"):
        print("\n## With − without margin over training seeds (Welch test, bootstrap interval)\n")
        rows = [((label,), difference) for label, difference in report["differences"].items()]
        print("\n".join(difference_table(rows, ("quantity",), "difference (with − without)")))
