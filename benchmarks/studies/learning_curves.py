"""Study: learning curves of training runs from their TensorBoard logs, per variant, against environment steps.

What a user with another budget (a GPU, more CPU) needs to plan a training: how the curriculum level, the falls or any
logged scalar move with the steps taken. Each run's scalars are read from ``<run>/tb`` (TensorBoard's own reader,
every event file, the last value where a resumed run logged a step twice), put on the environment-step axis (rsl-rl
logs per PPO iteration: num_envs x num_steps_per_env steps each, from the run's ``config.json``; Stable-Baselines3
logs environment steps), averaged within bins of ``--bin-steps``, and grouped by margin weight ("without margin" 0,
"with margin" otherwise): mean and the spread (min, max) over a variant's runs per bin.

Usage::

    python benchmarks/studies/learning_curves.py runs/rough_pilot/c_mw0_s0 runs/rough_pilot/c_mw0.1_s0 \\
        --tags Curriculum/terrain_level_mean Episode_Termination/fell --bin-steps 1000000 \\
        --out docs/comparison/rough_pilot/learning_curves      # writes .png and .json
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

TENSORBOARD_DIR = "tb"
CONFIG_FILE = "config.json"
DEFAULT_TAGS = ("Curriculum/terrain_level_mean", "Episode_Termination/fell", "Episode_Metrics/velocity_error_mean")


@dataclass(frozen=True)
class Curve:
    """One run's scalar against environment steps."""

    run: str
    margin_weight: float
    steps: np.ndarray  # (K,) environment steps at each logged value
    values: np.ndarray  # (K,)


def steps_per_logged_step(config: dict) -> int:
    """Environment steps per TensorBoard step: a PPO iteration's batch for rsl-rl, 1 for Stable-Baselines3."""
    if config["backend"] == "rsl":
        return int(config["num_envs"]) * int(config["backend_config"]["num_steps_per_env"])
    if config["backend"] == "sb3":
        return 1
    raise ValueError(f"{config['backend']!r}: unknown training backend (rsl or sb3)")


def read_curve(run: Path, tag: str) -> Curve:
    """``tag``'s values in ``run``'s TensorBoard logs on the environment-step axis.

    Raises:
        ValueError: ``run`` is not a training run (no config.json or tb folder), or never logged ``tag`` (the message
            lists the scalars it has).
    """
    from tensorboard.backend.event_processing.event_accumulator import SCALARS, EventAccumulator

    config_path, logs = run / CONFIG_FILE, run / TENSORBOARD_DIR
    if not (config_path.is_file() and logs.is_dir()):
        raise ValueError(f"{run}: not a training run (needs {CONFIG_FILE} and {TENSORBOARD_DIR}/)")
    config = json.loads(config_path.read_text())
    events = EventAccumulator(str(logs), size_guidance={SCALARS: 0})  # 0: keep every value
    events.Reload()
    available = events.Tags()["scalars"]
    if tag not in available:
        raise ValueError(f"{run}: no scalar {tag!r} in its logs; it has {sorted(available)}")
    latest = {event.step: event.value for event in events.Scalars(tag)}  # a resumed run's repeat: the later value
    steps = np.array(sorted(latest), dtype=np.int64)
    values = np.array([latest[s] for s in steps], dtype=np.float64)
    weight = float(config["env_config"]["margin_weight"])
    # rsl-rl logs iteration i after its batch: i + 1 batches taken (SB3's steps: the count itself, off by one step)
    return Curve(str(run), weight, (steps + 1) * steps_per_logged_step(config), values)


def binned(curve: Curve, bin_steps: int, bins: int) -> np.ndarray:
    """(bins,) mean of the curve's finite values in [k bin_steps, (k + 1) bin_steps); NaN where it has none."""
    out = np.full(bins, np.nan)
    index = (curve.steps - 1) // bin_steps
    for k in range(bins):
        chosen = curve.values[(index == k) & np.isfinite(curve.values)]
        if chosen.size:
            out[k] = chosen.mean()
    return out


def variant_name(weight: float) -> str:
    return "without margin" if weight == 0 else f"with margin ({weight:g})"


def summarise(curves: Sequence[Curve], bin_steps: int) -> dict:
    """Per variant: bin centres [steps], and the mean, min and max over its runs per bin."""
    bins = int(max(c.steps.max() for c in curves) // bin_steps) + 1
    groups: dict[str, list[Curve]] = {}
    for curve in curves:
        groups.setdefault(variant_name(curve.margin_weight), []).append(curve)
    result = {}
    for name, members in groups.items():
        table = np.array([binned(c, bin_steps, bins) for c in members])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a bin no run reached stays NaN
            result[name] = {
                "runs": [c.run for c in members],
                "steps": ((np.arange(bins) + 0.5) * bin_steps).tolist(),
                "mean": np.nanmean(table, axis=0).tolist(),
                "min": np.nanmin(table, axis=0).tolist(),
                "max": np.nanmax(table, axis=0).tolist(),
            }
    return result


def plot(curves_by_tag: dict[str, dict], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from margin_rl.plotting import save_figure

    fig, axes = plt.subplots(1, len(curves_by_tag), figsize=(5 * len(curves_by_tag), 3.6), squeeze=False)
    for ax, (tag, variants) in zip(axes[0], curves_by_tag.items(), strict=True):
        for name, v in variants.items():
            steps = np.array(v["steps"]) / 1e6
            (line,) = ax.plot(steps, v["mean"], label=f"{name} ({len(v['runs'])} run(s))")
            ax.fill_between(steps, v["min"], v["max"], color=line.get_color(), alpha=0.2)
        ax.set_xlabel("environment steps [M]")
        ax.set_title(tag, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    return save_figure(fig, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, nargs="+", help="training run folders")
    parser.add_argument("--tags", nargs="+", default=list(DEFAULT_TAGS), help="TensorBoard scalars to draw")
    parser.add_argument("--bin-steps", type=int, default=1_000_000, help="environment steps per point")
    parser.add_argument("--out", type=Path, required=True, help="output stem: writes <out>.png and <out>.json")
    args = parser.parse_args(argv)
    if args.bin_steps < 1:
        parser.error("--bin-steps must be >= 1")
    try:
        by_tag = {tag: summarise([read_curve(run, tag) for run in args.runs], args.bin_steps) for tag in args.tags}
    except ValueError as error:
        parser.error(str(error))
    figure = plot(by_tag, args.out.with_suffix(".png"))
    record = {"command": " ".join([Path(sys.executable).name, *sys.argv]), "bin_steps": args.bin_steps, "tags": by_tag}
    args.out.with_suffix(".json").write_text(json.dumps(record, indent=2, allow_nan=True) + "\n")
    for tag, variants in by_tag.items():
        for name, v in variants.items():
            # A variant's runs may stop short of the longest run's last bin: quote its own last filled bin.
            filled = [(step, m) for step, m in zip(v["steps"], v["mean"], strict=True) if np.isfinite(m)]
            if not filled:
                print(f"{tag}: {name}: no value")
                continue
            step, last = filled[-1]
            print(f"{tag}: {name}: {last:.3g} in its last filled bin (centred at {step / 1e6:.2f}M steps)")
    print(f"wrote {figure} and {args.out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
