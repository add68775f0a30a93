"""Figure of one planned course: terrain and footholds from above, the side profile, the margins in time."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from margin_rl.planning.checks import CourseCheck
from margin_rl.planning.receding import CourseResult
from margin_rl.plotting import save_figure

LEG_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red")
LEG_NAMES = ("LF", "RF", "LH", "RH")


def executed_footholds(result: CourseResult) -> list[tuple[int, np.ndarray]]:
    """(leg, contact point) of every foothold touched down during the executed part of each plan."""
    out = []
    for plan in result.plans:
        for k, slot in enumerate(plan.schedule.slots):
            if plan.t0 < slot.touchdown <= plan.t0 + result.period + 1e-9:
                out.append((slot.leg, plan.footholds[k]))
    return out


def course_figure(
    result: CourseResult, check: CourseCheck, path: str | Path, contrast: CourseCheck | None = None
) -> Path:
    """Write a PNG: (top) terrain, footholds, CoM path; (middle) side profile; (bottom) margins vs time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hm = result.scenario.height_map
    x_min, x_max, y_min, y_max = hm.extent
    times = check.times
    com = np.array([result.plan_at(float(t)).base_at(float(t))[0] for t in times])
    fig, axes = plt.subplots(3, 1, figsize=(9, 9), gridspec_kw={"height_ratios": [1.2, 0.8, 1.0]})
    ax = axes[0]
    image = ax.imshow(hm.heights, origin="lower", extent=(x_min, x_max, y_min, y_max), cmap="terrain", aspect="equal")
    fig.colorbar(image, ax=ax, label="height [m]", fraction=0.025)
    holds = executed_footholds(result)
    for leg in range(4):
        pts = np.array([p for lg, p in holds if lg == leg]).reshape(-1, 3)
        ax.scatter(pts[:, 0], pts[:, 1], s=14, color=LEG_COLOURS[leg], label=LEG_NAMES[leg], edgecolor="k", lw=0.3)
    ax.plot(com[:, 0], com[:, 1], "k-", lw=1.2, label="CoM")
    ax.set_xlim(
        min(com[:, 0].min(), result.scenario.start_xy[0]) - 0.8, max(com[:, 0].max(), result.scenario.goal_xy[0]) + 0.8
    )
    ax.set_ylim(max(y_min, com[:, 1].mean() - 1.0), min(y_max, com[:, 1].mean() + 1.0))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper right", fontsize=7, ncol=5)
    ax.set_title(
        f"{result.robot}, {result.scenario.name}, {result.gait.name}: {result.scenario.description}", fontsize=9
    )

    ax = axes[1]
    xs = np.linspace(com[:, 0].min() - 0.5, com[:, 0].max() + 0.5, 400)
    for dy, style in ((0.3, "-"), (-0.3, "--")):
        ys = np.full_like(xs, com[:, 1].mean() + dy)
        ax.plot(
            xs,
            hm.height(np.column_stack([xs, ys])),
            "k" + style,
            lw=0.8,
            label=f"terrain at y = {dy:+.1f} m from the path",
        )
    ax.plot(com[:, 0], com[:, 2], "b-", label="CoM height")
    for leg in range(4):
        pts = np.array([p for lg, p in holds if lg == leg]).reshape(-1, 3)
        ax.scatter(pts[:, 0], pts[:, 2], s=8, color=LEG_COLOURS[leg])
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.legend(fontsize=7, loc="upper left")

    ax = axes[2]
    ax.plot(times, check.learned, "b-", lw=1, label="learned m_l (network)")
    ax.plot(times, check.analytic, "r-", lw=1, label="analytic m_a")
    if contrast is not None:
        ax.plot(
            contrast.times, contrast.analytic, color="0.6", lw=0.8, label="analytic m_a, plan without margin constraint"
        )
    ax.axhline(check.min_margin, color="k", ls="--", lw=0.8, label="m_min")
    ax.axhline(check.min_margin - 0.01, color="k", ls=":", lw=0.8, label="m_min - 1 cm")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("margin [m]")
    ax.set_ylim(max(np.nanmin(check.analytic) - 0.05, -0.3), min(np.nanmax(check.learned) + 0.05, 0.4))
    ax.legend(fontsize=7, ncol=2, loc="lower right")
    return save_figure(fig, path, dpi=80)
