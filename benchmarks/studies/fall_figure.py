"""The fall analysis's summary figure: fall times, reward terms, base state and margins before falls, learned vs m_x."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.studies.fall_episodes import Episodes
from benchmarks.studies.fall_report import Groups, at_fall

SCATTER_POINTS = 4000  # states per variant drawn away from falls in the learned-vs-m_x panel


def aligned(episodes: Episodes, values: np.ndarray, horizon: int) -> np.ndarray:
    """(falls, horizon + 1) ``values`` over the ``horizon`` steps up to each fall step (NaN before the start)."""
    return np.stack([at_fall(episodes, values, k * episodes.dt) for k in range(horizon, -1, -1)], axis=1)


def column_means(traces: np.ndarray) -> np.ndarray:
    """Mean of each column over its finite entries; NaN for a column without any."""
    finite = np.isfinite(traces)
    sums = np.where(finite, traces, 0.0).sum(axis=0)
    return np.where(finite.any(axis=0), sums / np.maximum(finite.sum(axis=0), 1), np.nan)


def plot(groups: Groups, report: dict[str, Any], window_s: float, path: Path) -> None:
    """Fall times, reward terms per class, base state and margins before falls, contacts, learned vs m_x."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from margin_rl.plotting import save_figure

    colours = {"with margin": "tab:red", "without margin": "tab:blue"}
    fig, axes = plt.subplots(2, 3, figsize=(16, 9))
    ax = axes[0, 0]
    for variant, pooled in report["falls"]["pooled"].items():
        counts = pooled["fall_time_histogram_s"]
        ax.step(np.arange(len(counts)), counts, where="post", label=variant, color=colours.get(variant))
    ax.set(xlabel="time of the fall in the episode [s] (1 s bins)", ylabel="falls (all policies, seeds)")
    ax.set_title("When the falls happen")
    ax.legend()

    ax = axes[0, 1]
    classes = list(report["rewards"])
    terms = [k for k in next(iter(report["rewards"].values())) if k.endswith("per step")]
    width = 0.8 / (len(classes) * len(groups))
    for j, (variant, label) in enumerate((v, c) for v in groups for c in classes):
        means = [report["rewards"][label][t][variant]["mean"] for t in terms]
        stds = [report["rewards"][label][t][variant]["std"] for t in terms]
        ax.bar(
            np.arange(len(terms)) + j * width,
            means,
            width,
            yerr=stds,
            label=f"{variant}: {label}",
            color=colours.get(variant),
            alpha=0.35 + 0.65 * (classes.index(label) + 1) / len(classes),
        )
    ax.set_xticks(np.arange(len(terms)) + 0.4 - width / 2, [t.removesuffix(" per step") for t in terms])
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set(ylabel="reward per step (mean ± std over policies)")
    ax.set_title("Weighted reward terms")
    ax.legend(fontsize=7)

    horizon = round(window_s / next(iter(groups.values()))[0].dt) - 1  # the window's steps, fall step included
    offsets = -np.arange(horizon, -1, -1) * next(iter(groups.values()))[0].dt
    for ax, name, values in (
        (axes[0, 2], "base height [m]", lambda e: e.height),
        (axes[1, 0], "lowest knee height [m]", lambda e: e.knee_height),
    ):
        for variant, policies in groups.items():
            traces = np.concatenate([aligned(e, values(e), horizon) for e in policies])
            if len(traces):
                ax.plot(
                    offsets,
                    column_means(traces),
                    color=colours.get(variant),
                    label=f"{variant} ({len(traces)} falls)",
                )
            steady = report["trends"][name]["steady"][variant]["mean"]
            ax.axhline(steady, color=colours.get(variant), ls=":", lw=1)
        ax.set(xlabel="time to the fall [s]", ylabel=name)
        ax.set_title(f"{name} before falls (dotted: steady gait)")
        ax.legend(fontsize=8)

    ax = axes[1, 1]
    for variant, policies in groups.items():
        learned = np.concatenate([aligned(e, e.learned, horizon) for e in policies])
        extended = np.concatenate([aligned(e, e.extended, horizon) for e in policies])
        if len(learned):
            ax.plot(offsets, column_means(learned), color=colours.get(variant), label=f"{variant}: learned")
            ax.plot(offsets, column_means(extended), color=colours.get(variant), ls="--", label=f"{variant}: m_x")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set(xlabel="time to the fall [s]", ylabel="margin [m] (mean over falls)")
    ax.set_title("Learned margin (the reward's) vs extended margin m_x")
    ax.legend(fontsize=8)

    ax = axes[1, 2]
    for variant, policies in groups.items():
        fall = np.concatenate([e.before_fall(window_s) for e in policies], axis=1)
        learned = np.concatenate([e.learned for e in policies], axis=1)
        extended = np.concatenate([e.extended for e in policies], axis=1)
        labelled = np.isfinite(extended) & np.isfinite(learned)
        # A fixed subsample of the other states, so that the few pre-fall states stay visible on top.
        rest = np.flatnonzero((labelled & ~fall).ravel())
        rest = np.random.default_rng(0).choice(rest, size=min(SCATTER_POINTS, len(rest)), replace=False)
        ax.scatter(extended.ravel()[rest], learned.ravel()[rest], s=2, alpha=0.15, color=colours.get(variant))
        ax.scatter(
            extended[labelled & fall],
            learned[labelled & fall],
            s=5,
            alpha=0.5,
            marker="x",
            color=colours.get(variant),
            label=f"{variant}: last {window_s:g} s before falls",
        )
    lim = (-1.2, 0.6)
    ax.plot(lim, lim, "k", lw=0.5)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set(xlim=lim, xlabel="extended margin m_x [m]", ylabel="learned margin [m]")
    ax.set_title("Learned vs m_x (dots: elsewhere, crosses: before falls)")
    ax.legend(fontsize=8)
    save_figure(fig, path)
