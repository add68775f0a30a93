"""Figures and videos of evaluations: ``episode.png`` (:func:`plot_episode`), ``compare.png``
(:func:`plot_accelerations`), ``episode.mp4`` (:func:`write_video`).

Lazy imports, on purpose: matplotlib is imported inside the plotting functions, after selecting its
non-interactive ``Agg`` back end, so that importing ``evaluate`` or ``compare`` from Python never switches the
back end of a user's interactive Python shell or notebook; imageio (the optional ``video`` extra) is imported by
:func:`write_video` only, which explains how to install it when it is missing.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from margin_rl.plotting import save_figure as save_plot
from margin_rl.train.analysis.episodes import Evaluation

VIDEO_HINT = "install it with: pip install 'margin_rl[video]' (imageio, imageio-ffmpeg)"
COLORS = {"without margin": "tab:blue", "with margin": "tab:red"}  # Fig. 9 of seed 000


def _pyplot() -> Any:
    import matplotlib  # lazy: see the module docstring

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str | Path) -> Path:
    """Lay out, write (creating the folder) and close a matplotlib figure at 110 dpi; returns the path."""
    return save_plot(fig, path, dpi=110)


def _episode_axes(plt: Any, traj: Mapping[str, np.ndarray]) -> Any:
    """Base accelerations, heading velocity, margin and stance width over time."""
    t = traj["time"]
    fig, axes = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    for k, axis in enumerate("xyz"):
        axes[0].plot(t, traj["lin_acc"][:, k], lw=0.8, label=axis)
        axes[1].plot(t, traj["ang_acc"][:, k], lw=0.8, label=axis)
    axes[0].set_ylabel("base lin. acc. [m/s²]")
    axes[1].set_ylabel("base ang. acc. [rad/s²]")
    axes[2].plot(t, traj["forward_velocity"], label="ẋ (base frame)")
    axes[2].plot(t, traj["command"], "k--", lw=1, label="command")
    axes[2].set_ylabel("heading velocity [m/s]")
    axes[3].plot(t, traj["margin"], color="tab:red", label="margin")
    axes[3].set_ylabel("margin [m]", color="tab:red")
    twin = axes[3].twinx()
    twin.plot(t, traj["stance_width"], color="tab:green", label="stance width")
    twin.set_ylabel("stance width [m]", color="tab:green")
    axes[3].set_xlabel("time [s]")
    for ax in axes[:3]:
        ax.legend(loc="upper right", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    return fig


def plot_episode(evaluation: Evaluation, path: str | Path, title: str = "") -> Path:
    """The first episode of an evaluation (PNG): base accelerations, heading velocity, margin and stance width."""
    plt = _pyplot()
    fig = _episode_axes(plt, evaluation.trajectory)
    fig.suptitle(title or "evaluation episode")
    return save_figure(fig, path)


def plot_accelerations(examples: dict[str, Evaluation], path: Path, settings: Any) -> Path:
    """Fig. 9 style: base linear acceleration per base-frame axis over one evaluation episode of each variant
    (``settings``: the :class:`~margin_rl.train.commands.compare.CompareSettings` of the comparison)."""
    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for name, evaluation in examples.items():
        traj = evaluation.trajectory
        after = traj["time"] > settings.warmup_s
        norm_sq = np.sum(traj["lin_acc"][after] ** 2, axis=1)
        rms = float(np.sqrt(norm_sq.mean())) if norm_sq.size else float("nan")
        for k, axis in enumerate("xyz"):
            label = f"{name} (RMS {rms:.2f} m/s² after {settings.warmup_s:g} s)" if k == 0 else None
            axes[k].plot(traj["time"], traj["lin_acc"][:, k], color=COLORS.get(name), lw=0.9, label=label)
            axes[k].set_ylabel(f"base acc. {axis} [m/s²]")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.axvspan(0.0, settings.warmup_s, color="0.9", zorder=0)  # landing after the reset, not in the table
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(
        f"{settings.env_id}, {settings.backend}: base acceleration, command {settings.forward_velocity:g} m/s "
        f"(seed {settings.seeds[0]}, evaluation seed {settings.eval_seed})"
    )
    return save_figure(fig, path)


def write_video(frames: list[np.ndarray], path: str | Path, fps: float) -> tuple[Path | None, str]:
    """Write frames as an MP4 with imageio; returns (path or None, message explaining a missing video)."""
    if not frames:
        return None, "no frames were rendered"
    try:
        import imageio.v2 as imageio  # lazy: the optional video extra, see the module docstring
    except ImportError:
        return None, f"MP4 needs imageio, which is not installed; {VIDEO_HINT}"
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        imageio.mimwrite(path, frames, fps=fps, macro_block_size=1)
    except Exception as exc:  # mostly a missing ffmpeg plugin
        return None, f"imageio could not write {path.name} ({type(exc).__name__}: {exc}); {VIDEO_HINT}"
    return path, ""
