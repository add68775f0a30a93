"""Benchmark: environment steps per second of the native batched vector env against raw ``mujoco.batch``.

Usage:
    python benchmarks/bench_env.py [--env margin_rl/AnymalB-v0] [--num-envs 64] [--steps 300] [--rounds 5]

Five configurations, measured in interleaved rounds in one run (round r measures all of them, one after the
other), with the median over rounds and the ratios of medians printed as a Markdown table:

* the env with the learned margin (the reward term on), and with ``margin="none"`` (no margin evaluation);
* raw ``mujoco.batch`` stepping of the same model at the same decimation, three ways: the robots standing at
  the keyframe with constant controls and no stage computed after the step (the row of earlier BENCHMARKS);
  the env's own random actions written as servo targets; and the same with the env's ``mjSTAGE_ACC``
  forward pass after the step (the env needs it: sensors, actuator forces and contacts of the new state).

The last raw row is the physics cost of exactly what the env steps; the env's Python work (lambda, margin,
rewards, observations, resets) is the difference.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import gymnasium as gym
import mujoco
import numpy as np
from mujoco import batch

import margin_rl  # noqa: F401  (registers the ids)


def env_runner(env_id: str, num_envs: int, actions: np.ndarray, **kwargs: object) -> Callable[[], float]:
    env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
    env.reset(seed=0)
    for a in actions[:20]:  # warm-up
        env.step(a)

    def run() -> float:
        t0 = time.perf_counter()
        for a in actions:
            env.step(a)
        return num_envs * len(actions) / (time.perf_counter() - t0)

    return run


def raw_runner(env_id: str, num_envs: int, actions: np.ndarray | None, stage: mujoco.mjtStage) -> Callable[[], float]:
    env = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point", margin="none")
    core = env.unwrapped.core if hasattr(env, "unwrapped") else env.core
    model, decimation, scale = core.model, core.config.decimation, core.config.action_scale
    key = model.key("standing").id
    b = batch.Batch(model, nsim=num_envs, nthread=0)
    ctrl = b.bind("ctrl")
    steps = 300 if actions is None else len(actions)

    def run() -> float:
        b.reset(keyframe=key)
        t0 = time.perf_counter()
        for i in range(steps):
            if actions is not None:
                ctrl[:] = model.key_ctrl[key] + scale * np.clip(actions[i], -1.0, 1.0)
            b.step(nstep=decimation, stage=stage)
        return num_envs * steps / (time.perf_counter() - t0)

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="margin_rl/AnymalB-v0")
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--margin-weights", default=None, help="weights .npz (default: bundled)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.3, 0.3, size=(args.steps, args.num_envs, 12)).astype(np.float32)
    extra = {"margin_weights": args.margin_weights} if args.margin_weights else {}
    runners = {
        "env, learned margin (reward term on)": env_runner(args.env, args.num_envs, actions, margin="learned", **extra),
        "env, no margin evaluation": env_runner(args.env, args.num_envs, actions, margin="none"),
        "raw mujoco.batch: standing, constant controls, no stage": raw_runner(
            args.env, args.num_envs, None, mujoco.mjtStage.mjSTAGE_NONE
        ),
        "raw mujoco.batch: the env's actions, no stage": raw_runner(
            args.env, args.num_envs, actions, mujoco.mjtStage.mjSTAGE_NONE
        ),
        "raw mujoco.batch: the env's actions, mjSTAGE_ACC (as the env)": raw_runner(
            args.env, args.num_envs, actions, mujoco.mjtStage.mjSTAGE_ACC
        ),
    }
    rates: dict[str, list[float]] = {name: [] for name in runners}
    for _ in range(args.rounds):
        for name, run in runners.items():
            rates[name].append(run())
    median = {name: statistics.median(values) for name, values in rates.items()}
    names = list(runners)
    print(f"{args.env}, {args.num_envs} envs, {args.steps} steps, {args.rounds} interleaved rounds (median, min-max)")
    print()
    print("| configuration | env-steps/s | range |")
    print("|---|---|---|")
    for name in names:
        print(f"| {name} | {median[name]:,.0f} | {min(rates[name]):,.0f}–{max(rates[name]):,.0f} |")
    print()
    with_margin, without = median[names[0]], median[names[1]]
    print(f"margin overhead (no margin / learned margin - 1): {100 * (without / with_margin - 1):.1f} %")
    for raw in names[2:]:
        print(f"env with the learned margin / {raw}: {100 * with_margin / median[raw]:.0f} %")


if __name__ == "__main__":
    main()
