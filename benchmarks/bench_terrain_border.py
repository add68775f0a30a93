"""Benchmark: does the rough terrain's flat border (``TerrainConfig.border``) cost step throughput?

Usage:
    MUJOCO_GL=egl python benchmarks/bench_terrain_border.py [--robot anymal_b] [--num-envs 64] [--steps 300]
        [--rounds 5] [--border 0 16]

One batched ANYmal core per border width on ``terrain="rough"`` (learned margin and knee term on, as the comparison
trains), stepped with the same uniform random actions in interleaved rounds (round r steps every core once); prints
the median env-steps/s per border width and the median of the per-round ratios against the first width. The border
makes the heightfield larger (24 m of tiles inside 16 m of flat ground: 1121² samples instead of 481²); MuJoCo's
heightfield collision only looks at the cells under a geom, so the step should not slow down.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.terrain import TerrainConfig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="anymal_b")
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--border", type=float, nargs="+", default=[0.0, 16.0], help="border widths [m]")
    args = parser.parse_args()

    def config(border: float) -> EnvConfig:
        terrain = TerrainConfig(border=border)
        return EnvConfig(robot=args.robot, terrain="rough", terrain_config=terrain, knee_clearance=5.0)

    cores = {border: AnymalCore(config(border), num_envs=args.num_envs, seed=0) for border in args.border}
    actions = np.random.default_rng(0).uniform(-1, 1, size=(args.steps, args.num_envs, 12))
    rates: dict[float, list[float]] = {border: [] for border in cores}
    for round_index in range(args.rounds):
        for border, core in cores.items():
            core.reset(seed=round_index)
            start = time.perf_counter()
            for action in actions:
                core.step(action)
            rates[border].append(args.num_envs * args.steps / (time.perf_counter() - start))
    first = args.border[0]
    print(f"{args.robot}, rough terrain, {args.num_envs} envs, {args.steps} steps, {args.rounds} interleaved rounds")
    print("| border [m] | heightfield side [samples] | env-steps/s (median) | ratio to the first (median per round) |")
    print("|---|---|---|---|")
    for border, core in cores.items():
        ratio = np.median(np.array(rates[border]) / np.array(rates[first]))
        side = core.terrain.heights.shape[0]
        print(f"| {border:g} | {side} | {np.median(rates[border]):,.0f} | {ratio:.3f} |")


if __name__ == "__main__":
    main()
