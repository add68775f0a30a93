"""Figures of the learned margin like seed 000 Fig. 1/2 (command line).

    python -m margin_rl.stability.learned.figures --robot anymal_c --out docs/learned_margin

writes ``<robot>_margin_map.png`` (learned and analytic margin of the standing robot over a grid of base
x-y offsets, static, flat ground, four feet) and ``<robot>_learned_vs_analytic.png`` (scatter of m_l
against m_a and the error histogram on fresh Table I states).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from margin_rl.robot import load_robot
from margin_rl.stability.analytic.margin import STATUSES, analytic_margin_batch
from margin_rl.stability.analytic.sampling import nominal_feet, sample_states, standing_state
from margin_rl.stability.learned.model import LearnedMargin


def offset_grid_states(robot_name: str, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """lambda of the static standing robot with its base (CoM) moved by (x, y): feet shift by -(x, y)."""
    robot = load_robot(robot_name)
    feet = nominal_feet(robot)
    return np.array([standing_state(robot, feet=feet - [x, y, 0.0], mu=0.7) for y in ys for x in xs])


def margin_map(robot_name: str, out: Path, workers: int | None = None) -> Path:
    model = LearnedMargin.load(robot_name)
    xs, ys = np.linspace(-0.35, 0.35, 36), np.linspace(-0.25, 0.25, 26)
    lams = offset_grid_states(robot_name, xs, ys)
    learned = np.asarray(model(lams)).reshape(len(ys), len(xs))
    labels = analytic_margin_batch(robot_name, lams, workers=workers)
    analytic = np.where(labels.status == STATUSES.index("ok"), labels.margin, np.nan).reshape(len(ys), len(xs))
    vmin, vmax = np.nanmin([learned.min(), np.nanmin(analytic)]), np.nanmax([learned.max(), np.nanmax(analytic)])
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    for ax, values, title in ((axes[0], learned, "learned $m_l$"), (axes[1], analytic, "analytic $m_a$")):
        mesh = ax.pcolormesh(xs, ys, values, vmin=vmin, vmax=vmax, cmap="plasma_r", shading="auto")
        ax.contour(xs, ys, values, levels=[0.0], colors="k", linewidths=1.0)
        ax.set(title=f"{robot_name}: {title}", xlabel="base x offset [m]", ylabel="base y offset [m]", aspect="equal")
    fig.colorbar(mesh, ax=axes, label="margin [m] (black: 0)")
    path = out / f"{robot_name}_margin_map.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def learned_vs_analytic(robot_name: str, out: Path, n: int, workers: int | None = None) -> Path:
    model = LearnedMargin.load(robot_name)
    lams = sample_states(load_robot(robot_name), n, seed=987654)
    labels = analytic_margin_batch(robot_name, lams, workers=workers)
    ok = labels.status == STATUSES.index("ok")
    m_a, m_l = labels.margin[ok], np.asarray(model(lams[ok]))
    err = m_l - m_a
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    ax1.scatter(m_a, m_l, s=3, alpha=0.3)
    lim = [min(m_a.min(), m_l.min()), max(m_a.max(), m_l.max())]
    ax1.plot(lim, lim, "k--", lw=1)
    ax1.set(
        xlabel="analytic $m_a$ [m]", ylabel="learned $m_l$ [m]", title=f"{robot_name}: {ok.sum()} fresh Table I states"
    )
    ax2.hist(100 * err, bins=80)
    ax2.set(
        xlabel="$m_l - m_a$ [cm]",
        ylabel="states",
        title=f"RMSE {100 * np.sqrt(np.mean(err**2)):.2f} cm, sign agreement {np.mean((m_a >= 0) == (m_l >= 0)):.1%}",
    )
    path = out / f"{robot_name}_learned_vs_analytic.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m margin_rl.stability.learned.figures", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--robot", default="anymal_c")
    parser.add_argument("--out", default="docs/learned_margin")
    parser.add_argument("--n", type=int, default=2000, help="fresh Table I states for the scatter")
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for path in (margin_map(args.robot, out, args.workers), learned_vs_analytic(args.robot, out, args.n, args.workers)):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
