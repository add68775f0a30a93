"""Benchmark: environment steps per second of the native batched vector env, margin on vs off.

Usage:
    python benchmarks/bench_env.py [--env margin_rl/AnymalB-v0] [--num-envs 64] [--steps 300]

Random actions, same environments, the three margin modes measured one after the other in one run
(learned margin, margin weight 0 with no margin evaluation, and raw mujoco.batch stepping of the same
model for scale). Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import margin_rl  # noqa: F401  (registers the ids)


def measure(env_id: str, num_envs: int, steps: int, **kwargs: object) -> float:
    env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.3, 0.3, size=(steps, num_envs, 12)).astype(np.float32)
    for a in actions[:20]:  # warm-up
        env.step(a)
    t0 = time.perf_counter()
    for a in actions:
        env.step(a)
    elapsed = time.perf_counter() - t0
    env.close()
    return num_envs * steps / elapsed


def raw_batch(env_id: str, num_envs: int, steps: int) -> float:
    from mujoco import batch

    env = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point", margin="none")
    core = env.unwrapped.core if hasattr(env, "unwrapped") else env.core
    b = batch.Batch(core.model, nsim=num_envs, nthread=0)
    b.reset(keyframe=core.model.key("standing").id)
    t0 = time.perf_counter()
    for _ in range(steps):
        b.step(nstep=core.config.decimation)
    return num_envs * steps / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="margin_rl/AnymalB-v0")
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--margin-weights", default=None, help="weights .npz (default: bundled)")
    args = parser.parse_args()
    extra = {"margin_weights": args.margin_weights} if args.margin_weights else {}
    with_margin = measure(args.env, args.num_envs, args.steps, margin="learned", **extra)
    without = measure(args.env, args.num_envs, args.steps, margin="none")
    raw = raw_batch(args.env, args.num_envs, args.steps)
    print(f"{args.env}, {args.num_envs} envs, {args.steps} steps")
    print()
    print("| configuration | env-steps/s |")
    print("|---|---|")
    print(f"| learned margin (reward term on) | {with_margin:,.0f} |")
    print(f"| no margin evaluation | {without:,.0f} |")
    print(f"| raw mujoco.batch, same model and decimation | {raw:,.0f} |")
    print()
    print(f"margin overhead: {100 * (without / with_margin - 1):.1f} %")


if __name__ == "__main__":
    main()
