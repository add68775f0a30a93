"""Figures of the crawl experiments, drawn from ``crawl.json`` and ``crawl_series.npz`` (seed 004 Fig. 4, 6).

* ``stance_tests.png``: the displacement test (LF normal force and s against the CoM displacement) and
  the vertical disturbance test (LF knee torque and s against the force), one colour per planner, the
  servo's torque limit and the zeros of s marked (Fig. 4 centre and right);
* ``capacity_map.png``: the model's vertical capacity over the triple stance's support triangle, with
  the planners' CoM positions;
* ``along_crawl.png``: the CWC margin and the FWP factor along the heuristic crawl's triple stances with
  and without the load (Fig. 6);
* ``loaded_crawl.png``: the largest joint torque relative to its limit along the loaded, heavy, hindered
  and rough-ground crawls.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from margin_rl.planning.crawl.planners import PLANNER_NAMES
from margin_rl.plotting import save_figure

PLANNER_COLOURS = {"heuristic": "tab:gray", "cwc": "tab:orange", "fwp": "tab:blue"}


def _load(out: Path) -> tuple[dict, dict]:
    summary = json.loads((out / "crawl.json").read_text())
    with np.load(out / "crawl_series.npz") as series:
        return summary, {k: series[k] for k in series.files}


def stance_tests_figure(summary: dict, series: dict, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex="col")
    for name in PLANNER_NAMES:
        colour = PLANNER_COLOURS[name]
        result = summary["planners"][name]
        shift = series[f"{name}_displacement_shift"]
        axes[0, 0].plot(shift, series[f"{name}_displacement_watched_normal_force"], color=colour, label=name)
        axes[1, 0].plot(shift, series[f"{name}_displacement_s"], color=colour)
        if result["displacement_unload_m"] is not None:
            axes[0, 0].axvline(result["displacement_unload_m"], color=colour, ls=":")
        force = series[f"{name}_vertical_force"]
        axes[0, 1].plot(force, series[f"{name}_vertical_watched_knee_torque"], color=colour, label=name)
        axes[1, 1].plot(force, series[f"{name}_vertical_s"], color=colour)
        if result["vertical_disturbance_limit_N"] is not None:
            axes[0, 1].axvline(result["vertical_disturbance_limit_N"], color=colour, ls=":")
            axes[1, 1].axvline(result["vertical_disturbance_limit_N"], color=colour, ls=":")
    for ax in axes[1]:
        ax.axhline(0.0, color="k", lw=0.8)
    axes[0, 0].set(title="displacement test (CoM moved away from LF)", ylabel="LF normal force [N]")
    axes[1, 0].set(xlabel="CoM reference displacement [m]", ylabel="FWP factor s")
    axes[0, 1].set(title="vertical disturbance test (dotted: first servo at its limit)", ylabel="LF knee torque [N m]")
    axes[1, 1].set(xlabel="downward force on the base [N]", ylabel="FWP factor s")
    axes[0, 0].legend()
    fig.suptitle(f"{summary['robot']}: triple stance (RH up) placed by each planner")
    return save_figure(fig, path)


def capacity_map_figure(summary: dict, path: Path) -> Path:
    import matplotlib.pyplot as plt

    cmap = summary["vertical_capacity_map"]
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    x, y = np.asarray(cmap["x"]), np.asarray(cmap["y"])
    values = np.asarray(cmap["capacity_N"], dtype=float)
    mesh = ax.pcolormesh(x, y, values, shading="nearest", cmap="viridis")
    fig.colorbar(mesh, ax=ax, label="downward force at s = 0 [N]")
    tri = np.asarray(cmap["triangle"])
    ax.plot(*np.vstack([tri, tri[:1]]).T, color="k", lw=1)
    for name, xy in cmap["planner_com_xy"].items():
        ax.plot(*xy, "o", color=PLANNER_COLOURS[name], mec="w", ms=9, label=name)
    ax.plot(*cmap["best_com_xy"], "*", color="w", mec="k", ms=14, label="largest capacity")
    ax.set(xlabel="CoM x [m]", ylabel="CoM y [m]", aspect="equal",
           title=f"{summary['robot']}: vertical capacity of the triple stance (model)")  # fmt: skip
    ax.legend(loc="lower left", fontsize=8)
    return save_figure(fig, path)


def along_crawl_figure(summary: dict, series: dict, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    load = summary["settings"]["load_kg"]
    for label, style in (("unloaded", "-"), ("loaded", "--")):
        t = series[f"along_{label}_time"]
        name = "no load" if label == "unloaded" else f"{load:g} kg load"
        axes[0].plot(t, series[f"along_{label}_cwc_margin"], style, marker=".", label=name)
        axes[1].plot(t, series[f"along_{label}_fwp_factor"], style, marker=".", label=name)
    axes[0].set(ylabel="CWC margin", title=f"{summary['robot']}: heuristic crawl, triple stances only")
    axes[1].set(ylabel="FWP factor s", xlabel="time [s]")
    axes[0].legend()
    return save_figure(fig, path)


def loaded_crawl_figure(summary: dict, series: dict, path: Path) -> Path:
    import matplotlib.pyplot as plt

    settings = summary["settings"]
    titles = {
        "loaded": f"{settings['load_kg']:g} kg on the base",
        "heavy": f"{summary['heavy_load_kg']:g} kg on the base",
        "hindered": f"{settings['hindered_leg']} knee at {settings['hindered_fraction']:.0%} of its limit, "
        f"{settings['load_kg']:g} kg",
        "rough": f"tiles up to {100 * settings['rough_max_height']:g} cm high, {settings['load_kg']:g} kg",
    }
    fig, axes = plt.subplots(len(titles), 1, figsize=(10, 10), sharex=True)
    for ax, (label, title) in zip(axes, titles.items(), strict=True):
        for name in PLANNER_NAMES:
            hits = summary["planners"][name]["crawls"][label]["torque_limit_steps"]
            ax.plot(series[f"{name}_{label}_time"], np.minimum(series[f"{name}_{label}_torque_ratio"], 1.5),
                    color=PLANNER_COLOURS[name], lw=0.8, label=f"{name}: {hits} steps at a limit")  # fmt: skip
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set(ylabel="max |tau| / limit", title=f"{summary['robot']}: {title}")
        ax.legend(fontsize=8, loc="lower right")
    axes[-1].set_xlabel("time [s] (ratios above 1.5 drawn at 1.5)")
    return save_figure(fig, path)


def write_figures(out: str | Path) -> list[Path]:
    """All figures of ``out/crawl.json`` into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    out = Path(out)
    summary, series = _load(out)
    paths = [
        stance_tests_figure(summary, series, out / "stance_tests.png"),
        along_crawl_figure(summary, series, out / "along_crawl.png"),
        loaded_crawl_figure(summary, series, out / "loaded_crawl.png"),
    ]
    if "vertical_capacity_map" in summary:
        paths.append(capacity_map_figure(summary, out / "capacity_map.png"))
    return paths
