"""Benchmark: wall-clock time until a PPO policy meets the walking target on this CPU.

Target (flat ground, command 0.75 m/s): mean absolute velocity-tracking error <= 0.15 m/s and fewer than 5 %
falls over 20 s deterministic episodes, within ``--time-target-min`` minutes of training (default 10).

Usage:
    python benchmarks/studies/bench_learning_speed.py [--env margin_rl/AnymalB-v1] [--backend rsl]
        [--margin-weight 0] [--seed 0] [--num-envs 128] [--total-steps 6000000] [--eval-every 500000]
        [--episodes 16] [--time-target-min 10] [--out DIR]
    python benchmarks/studies/bench_learning_speed.py --from-run RUN_DIR [RUN_DIR ...] [--episodes 16] [--json PATH]
    python benchmarks/studies/bench_learning_speed.py --merge RECORD.json [RECORD.json ...] --json PATH

One training run (``margin_rl.train.commands.train.train``, exactly what ``margin-rl-train`` runs) writes a
checkpoint every
``--eval-every`` steps; the wall time of each checkpoint since the start of training is recorded when it is
written. After training (so evaluation never counts as training time) every checkpoint is evaluated on
``--episodes`` deterministic 20 s episodes from evaluation seed 1000 at 0.75 m/s, and the table (steps, minutes,
velocity error, falls, target met) is printed as Markdown and written to ``<out>/learning_speed.json``.

``--from-run RUN_DIR [RUN_DIR ...]`` trains nothing and evaluates the checkpoints of existing runs trained in
one ``train`` call, never resumed (e.g. a comparison's runs), timing each checkpoint by its file's modification time
against that call's start time recorded in ``config.json`` (whole seconds; the first checkpoint is written before
the first update). With several runs, the time to the target is also summarised per margin weight (mean ± std over
the runs that met it, and how many did), and ``--json`` keeps the whole record (run directories are not committed).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("GIT_PYTHON_REFRESH", "quiet")

VELOCITY_ERROR_TARGET = 0.15  # m/s
FALL_FRACTION_TARGET = 0.05  # strictly below
TIME_TARGET_MIN = 10.0  # minutes of training


def train_with_timeline(args: argparse.Namespace, run_dir: Path) -> list[tuple[int, float, Path]]:
    """Train one run; returns [(env steps, seconds since training started, checkpoint)] per checkpoint."""
    from margin_rl.train.commands.train import make_spec, train

    margin = {"margin_weight": args.margin_weight, "margin": "learned" if args.margin_weight > 0 else "none"}
    spec = make_spec(
        args.env,
        args.backend,
        margin,
        None,
        seed=args.seed,
        num_envs=args.num_envs,
        total_steps=args.total_steps,
        checkpoint_every=args.eval_every,
    )
    timeline: list[tuple[int, float, Path]] = []
    t0 = time.perf_counter()
    train(
        spec,
        run_dir,
        progress=True,
        on_checkpoint=lambda path, steps: timeline.append((steps, time.perf_counter() - t0, path)),
    )
    return timeline


def timeline_of_run(run_dir: Path) -> list[tuple[int, float, Path]]:
    """[(env steps, seconds since training started, checkpoint)] of a finished run trained in one ``train`` call."""
    from datetime import datetime

    from margin_rl.train.runs import CHECKPOINT_DIR, CONFIG_FILE, checkpoint_steps, read_json

    calls = read_json(run_dir / CONFIG_FILE).get("sessions", [])  # one entry per `train` call of the run
    if len(calls) != 1:
        raise SystemExit(f"{run_dir}: trained in {len(calls)} train calls; wall time is only defined for one")
    start = datetime.strptime(calls[0]["started"], "%Y-%m-%dT%H:%M:%S%z").timestamp()
    checkpoints = sorted((run_dir / CHECKPOINT_DIR).glob("ckpt_*.pt"), key=checkpoint_steps)
    return [(checkpoint_steps(p), p.stat().st_mtime - start, p) for p in checkpoints]


def evaluate_timeline(
    timeline: list[tuple[int, float, Path]], episodes: int, time_target_min: float = TIME_TARGET_MIN
) -> list[dict[str, float]]:
    """Deterministic evaluation of every checkpoint: velocity error and fall fraction."""
    from margin_rl.train.commands.evaluate import evaluate

    rows = []
    for steps, seconds, path in timeline:
        report, _ = evaluate(
            path, episodes=episodes, seed=1000, forward_velocity=0.75, out_dir=path.parent / "eval" / path.stem
        )
        s = report["summary"]
        error, falls = s["velocity_error_mean"]["mean"], s["fell"]["mean"]
        met = error <= VELOCITY_ERROR_TARGET and falls < FALL_FRACTION_TARGET and seconds / 60 <= time_target_min
        rows.append({"env_steps": steps, "minutes": seconds / 60, "velocity_error": error, "falls": falls, "met": met})
    return rows


def print_rows(title: str, rows: list[dict[str, float]]) -> dict[str, float] | None:
    """The checkpoint table of one run as Markdown; returns the first row that met the target."""
    print(f"\n{title}\n")
    print("| env steps | training time [min] | velocity error [m/s] | falls | target met |")
    print("|---|---|---|---|---|")
    for r in rows:
        met = "yes" if r["met"] else "no"
        print(f"| {r['env_steps']:,} | {r['minutes']:.1f} | {r['velocity_error']:.3f} | {r['falls']:.2f} | {met} |")
    first = next((r for r in rows if r["met"]), None)
    verdict = f"first met at {first['minutes']:.1f} min ({first['env_steps']:,} steps)" if first else "not met"
    print(f"\ntarget (error <= {VELOCITY_ERROR_TARGET} m/s, falls < {FALL_FRACTION_TARGET:.0%}): {verdict}")
    return first


def summarise_by_weight(records: list[dict]) -> dict[str, dict]:
    """Per environment and margin weight ("<env id> w=<weight>"): runs, how many met the target, minutes to it
    (mean, std over those that met it)."""
    import numpy as np

    groups: dict[str, list[dict]] = {}
    for record in records:
        groups.setdefault(f"{record['env_id']} w={record['margin_weight']:g}", []).append(record)
    summary = {}
    for weight, members in sorted(groups.items()):
        minutes = [m["first_met"]["minutes"] for m in members if m["first_met"] is not None]
        summary[weight] = {
            "runs": len(members),
            "met": len(minutes),
            "minutes_mean": float(np.mean(minutes)) if minutes else None,
            "minutes_std": float(np.std(minutes)) if minutes else None,
        }
    return summary


def print_summary(summary: dict[str, dict], episodes: list[int]) -> None:
    print(f"\n{episodes} deterministic 20 s episodes per checkpoint (seed 1000), command 0.75 m/s\n")
    print("| environment, margin weight | runs | met the target | minutes to the target (mean ± std over those) |")
    print("|---|---|---|---|")
    for group, s in summary.items():
        minutes = f"{s['minutes_mean']:.1f} ± {s['minutes_std']:.1f}" if s["met"] else "–"
        print(f"| {group} | {s['runs']} | {s['met']} | {minutes} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="margin_rl/AnymalB-v1")
    parser.add_argument("--backend", default="rsl", choices=("rsl", "sb3"))
    parser.add_argument("--margin-weight", type=float, default=0.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-envs", type=int, default=128)
    parser.add_argument("--total-steps", type=int, default=6_000_000)
    parser.add_argument("--eval-every", type=int, default=500_000)
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument("--time-target-min", type=float, default=TIME_TARGET_MIN)
    parser.add_argument("--out", type=Path, default=Path("runs") / "bench_learning_speed")
    parser.add_argument("--from-run", type=Path, nargs="+", help="evaluate the checkpoints of these finished runs")
    parser.add_argument("--json", type=Path, help="also write the whole record here (e.g. under docs/)")
    parser.add_argument(
        "--merge", type=Path, nargs="+", help="evaluate nothing: merge the records of earlier --json files into --json"
    )
    args = parser.parse_args()
    from margin_rl.train.runs import CONFIG_FILE, read_json, write_json

    if args.merge is not None:
        if args.json is None:
            parser.error("--merge needs --json")
        records, episodes = [], set()
        for record in map(read_json, args.merge):
            records.extend(record["runs"])
            value = record["episodes"]  # an int per --from-run file, a list per file merged before (repeatable)
            episodes.update(value if isinstance(value, list) else [value])
        write_json(
            args.json, {"episodes": sorted(episodes), "runs": records, "by_margin_weight": summarise_by_weight(records)}
        )
        print_summary(summarise_by_weight(records), sorted(episodes))
        return
    if args.from_run is None:
        if args.out.exists():
            parser.error(f"{args.out} exists: give a fresh --out (the timeline needs a run from step 0)")
        runs = [(args.out, train_with_timeline(args, args.out))]
    else:
        runs = [(run, timeline_of_run(run)) for run in args.from_run]
    records = []
    for run_dir, timeline in runs:
        rows = evaluate_timeline(timeline, args.episodes, args.time_target_min)
        config = read_json(run_dir / CONFIG_FILE)
        weight = config["env_config"]["margin_weight"]
        title = f"{config['env_id']}, {config['backend']}, margin weight {weight:g}, seed {config['seed']} ({run_dir})"
        first = print_rows(title, rows)
        record = {"run": str(run_dir), "env_id": config["env_id"], "margin_weight": weight, "seed": config["seed"]}
        records.append({**record, "rows": rows, "first_met": first})
        write_json(run_dir / "learning_speed.json", {"args": {k: str(v) for k, v in vars(args).items()}, "rows": rows})
    summary = summarise_by_weight(records)
    print_summary(summary, [args.episodes])
    if args.json is not None:
        write_json(args.json, {"episodes": args.episodes, "runs": records, "by_margin_weight": summary})


if __name__ == "__main__":
    main()
