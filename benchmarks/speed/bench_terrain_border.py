"""Benchmark: does the rough terrain's flat border (``TerrainConfig.border``) cost step throughput?

Usage:
    MUJOCO_GL=egl python benchmarks/speed/bench_terrain_border.py [--robot anymal_b] [--num-envs 64] [--steps 300]
        [--rounds 5] [--border 0 16] [--json PATH]

One batched ANYmal core per border width on ``terrain="rough"`` (learned margin and knee term on, as the comparison
trains), stepped with the same uniform random actions in interleaved rounds (round r steps every core once); prints
the median env-steps/s per border width and the median of the per-round ratios against the first width. The border
makes the heightfield larger (24 m of tiles inside 16 m of flat ground: 1121² samples instead of 481²); MuJoCo's
heightfield collision only looks at the cells under a geom, so the step should not slow down.
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import numpy as np

from benchmarks.harness import interleave, machine_line, median_ratio, parser, print_table, write_record
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.terrain import TerrainConfig


def stepper(core: AnymalCore, actions: np.ndarray) -> Callable[[int], float]:
    """Env-steps/s of one pass over ``actions`` after a reset seeded with the round's index."""

    def run(round_index: int) -> float:
        core.reset(seed=round_index)
        start = time.perf_counter()
        for action in actions:
            core.step(action)
        return core.num_envs * len(actions) / (time.perf_counter() - start)

    return run


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--robot", default="anymal_b")
    args_parser.add_argument("--num-envs", type=int, default=64)
    args_parser.add_argument("--steps", type=int, default=300)
    args_parser.add_argument("--rounds", type=int, default=5)
    args_parser.add_argument("--border", type=float, nargs="+", default=[0.0, 16.0], help="border widths [m]")
    args = args_parser.parse_args()

    def config(border: float) -> EnvConfig:
        terrain = TerrainConfig(border=border)
        return EnvConfig(
            robot=args.robot, terrain="rough", terrain_config=terrain, reward_params={"knee_clearance": 5.0}
        )

    cores = {border: AnymalCore(config(border), num_envs=args.num_envs, seed=0) for border in args.border}
    actions = np.random.default_rng(0).uniform(-1, 1, size=(args.steps, args.num_envs, 12))
    rates = interleave({border: stepper(core, actions) for border, core in cores.items()}, args.rounds)
    first = args.border[0]
    print(machine_line())
    print(f"{args.robot}, rough terrain, {args.num_envs} envs, {args.steps} steps, {args.rounds} interleaved rounds")
    rows, record = [], []
    for border, core in cores.items():
        ratio = median_ratio(rates[border], rates[first])
        side = core.terrain.heights.shape[0]
        median = statistics.median(rates[border])
        rows.append((f"{border:g}", side, f"{median:,.0f}", f"{ratio:.3f}"))
        record.append({"border_m": border, "heightfield_side": side, "env_steps_per_s": rates[border], "ratio": ratio})
    print_table(
        ("border [m]", "heightfield side [samples]", "env-steps/s (median)", "ratio to the first (median per round)"),
        rows,
    )
    write_record(args.json, "terrain_border", args, record)


if __name__ == "__main__":
    main()
