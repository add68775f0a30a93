"""Study: why a policy's environments move between the terrain curriculum's rows.

The curriculum's mean level (``Curriculum/terrain_level_mean``) is the rough trainings' learning curve, but a row
change has two causes a mean hides: an episode that falls early and one that walks too slowly are both demoted
(:func:`margin_rl.envs.terrain.next_levels`). This runs a trained policy (deterministic actions) in its own training
environment — the curriculum terrain, command range, randomisation and pushes of its run's ``config.json`` — with
every environment starting on a given row, and tallies each environment's first episode by row: promoted, stayed,
demoted; for demotions whether the episode fell (a termination) or timed out; and the commanded forward speed of each
group.

Usage::

    python benchmarks/studies/curriculum_moves.py runs/rough_pilot/c_mw0_s0 [--rows 1 2 3 4 5 6] [--envs 32]
        [--seed 7000] [--json FILE]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

import numpy as np

from benchmarks.harness import run_policies, write_record
from margin_rl.envs.core import AnymalCore
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import resolve_env
from margin_rl.train.runs import torch_threads


def episode_ends(policy_path: Path, rows: list[int], envs: int, seed: int) -> list[dict]:
    """The first episode of ``envs`` environments per row: the row it ran on, the row it moves to, whether it fell,
    its commanded forward speed [m/s]."""
    policy = load_policy(policy_path)
    _, config = resolve_env(policy, None, {})
    if not config.terrain_config.curriculum_levels:
        raise SystemExit(f"{policy_path}: trained without a terrain curriculum; nothing moves between rows")
    top = config.terrain_config.curriculum_levels - 1
    if min(rows) < 1 or max(rows) > top - 1:
        # row 0 cannot be demoted and the top row reassigns at random: there a row change does not tell the move
        raise SystemExit(f"--rows must lie in 1..{top - 1} (this curriculum's rows but the first and last), got {rows}")
    core = AnymalCore(config, num_envs=envs * len(rows), seed=seed)
    core.reset(seed=seed)
    core.restart_on_levels(np.repeat(rows, envs))
    obs, ends = core.observe_all(), {}
    while len(ends) < core.num_envs:
        ran_on, speed = core.terrain_level.copy(), core.command[:, 0].copy()
        out = core.step(policy(obs))
        obs = out.observation
        for i in np.flatnonzero(out.terminated | out.truncated):
            ends.setdefault(
                int(i),
                {"row": int(ran_on[i]), "next": int(core.terrain_level[i]), "fell": bool(out.terminated[i]),
                 "command": float(speed[i])},
            )  # fmt: skip
    return list(ends.values())


def tally(ends: list[dict]) -> list[dict]:
    """Per row: episode ends, promoted / stayed / demoted, demotions that fell, mean command of each group."""
    by_row: dict[int, list[dict]] = defaultdict(list)
    for end in ends:
        by_row[end["row"]].append(end)
    rows = []
    for row, group in sorted(by_row.items()):
        moved = np.array([e["next"] - e["row"] for e in group])  # -1, 0 or +1 on the rows episode_ends allows
        promoted, demoted = moved == 1, moved == -1
        fell = np.array([e["fell"] for e in group])
        command = np.array([e["command"] for e in group])
        rows.append(
            {
                "row": row,
                "episodes": len(group),
                "promoted": int(promoted.sum()),
                "demoted": int(demoted.sum()),
                "stayed": int((~promoted & ~demoted).sum()),
                "demoted_fell": int((demoted & fell).sum()),
                "demoted_timed_out": int((demoted & ~fell).sum()),
                "command_promoted": float(command[promoted].mean()) if promoted.any() else None,
                "command_demoted": float(command[demoted].mean()) if demoted.any() else None,
            }
        )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="a run folder (final_model.pt) or a checkpoint .pt")
    parser.add_argument("--rows", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6])
    parser.add_argument("--envs", type=int, default=32, help="environments per row")
    parser.add_argument("--seed", type=int, default=7000)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    (path,) = run_policies(parser, [args.run]).values()
    t0 = time.perf_counter()
    with torch_threads(1):
        ends = episode_ends(path, args.rows, args.envs, args.seed)
    rows = tally(ends)
    print(f"\n{path}: one episode per environment, {args.envs} environments per row\n")
    print(
        "| row | episodes | promoted | stayed | demoted | of them fell / timed out | command promoted / demoted [m/s] |"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        cp = "–" if r["command_promoted"] is None else f"{r['command_promoted']:.2f}"
        cd = "–" if r["command_demoted"] is None else f"{r['command_demoted']:.2f}"
        print(
            f"| {r['row']} | {r['episodes']} | {r['promoted']} | {r['stayed']} | {r['demoted']} "
            f"| {r['demoted_fell']} / {r['demoted_timed_out']} | {cp} / {cd} |"
        )
    print(f"({time.perf_counter() - t0:.0f} s)")
    write_record(args.json, "curriculum_moves", args, {"policy": str(path), "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
