"""Benchmark: environment steps per second of the native batched vector env against raw ``mujoco.batch``.

Usage:
    python benchmarks/speed/bench_env.py [--env margin_rl/AnymalB-v1] [--num-envs 64] [--steps 300] [--rounds 5]
        [--warp-cpu] [--height-scan] [--json PATH]

Five configurations, measured in interleaved rounds in one run (round r measures all of them, one after the
other), with the median over rounds and the ratios of medians printed as a Markdown table:

* the env with the learned margin (the reward term on), and with ``margin="none"`` (no margin evaluation);
* raw ``mujoco.batch`` stepping of the same model at the same decimation, three ways: the robots standing at
  the keyframe with constant controls and no stage computed after the step (the row of earlier BENCHMARKS);
  the env's own random actions written as servo targets; and the same with the env's ``mjSTAGE_ACC``
  forward pass after the step (the env needs it: sensors, actuator forces and contacts of the new state).

The last raw row is the physics cost of exactly what the env steps; the env's Python work (lambda, margin,
rewards, observations, resets) is the difference. ``--warp-cpu`` adds the env with the learned margin on the MuJoCo
Warp backend on Warp's CPU device (``physics="warp", physics_device="cpu"``; its kernels compile on first use);
``--height-scan`` the env with the learned margin and the actor's height scan (``height_scan=True``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.vector import AutoresetMode
from mujoco import batch

import margin_rl  # noqa: F401  (registers the ids)
from benchmarks.harness import interleave, machine_line, parser, print_table, summarise, write_record


def env_runner(env_id: str, num_envs: int, actions: np.ndarray, **kwargs: object) -> Callable[[int], float]:
    # Same-step autoreset: the mode of the training adapters (and of this benchmark's history); next-step
    # mode costs one more step per episode end (of 1000-step episodes).
    env = gym.make_vec(
        env_id,
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
        **kwargs,
    )
    env.reset(seed=0)
    for a in actions[:20]:  # warm-up
        env.step(a)

    def run(_round: int) -> float:
        t0 = time.perf_counter()
        for a in actions:
            env.step(a)
        return num_envs * len(actions) / (time.perf_counter() - t0)

    return run


def raw_runner(
    env_id: str, num_envs: int, actions: np.ndarray | None, stage: mujoco.mjtStage
) -> Callable[[int], float]:
    env = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point", margin="none")
    core = env.unwrapped.core if hasattr(env, "unwrapped") else env.core
    model, decimation, scale = core.model, core.config.decimation, core.config.action_scale
    key = model.key("standing").id
    b = batch.Batch(model, nsim=num_envs, nthread=0)
    ctrl = b.bind("ctrl")
    steps = 300 if actions is None else len(actions)

    def run(_round: int) -> float:
        b.reset(keyframe=key)
        t0 = time.perf_counter()
        for i in range(steps):
            if actions is not None:
                ctrl[:] = model.key_ctrl[key] + scale * np.clip(actions[i], -1.0, 1.0)
            b.step(nstep=decimation, stage=stage)
        return num_envs * steps / (time.perf_counter() - t0)

    return run


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--env", default="margin_rl/AnymalB-v1")
    args_parser.add_argument("--num-envs", type=int, default=64)
    args_parser.add_argument("--steps", type=int, default=300)
    args_parser.add_argument("--rounds", type=int, default=5)
    args_parser.add_argument("--margin-weights", default=None, help="weights .npz (default: bundled)")
    args_parser.add_argument("--warp-cpu", action="store_true", help="add the env on MuJoCo Warp's CPU device")
    args_parser.add_argument("--height-scan", action="store_true", help="add the env with the actor's height scan")
    args = args_parser.parse_args()
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
    if args.height_scan:
        runners["env, learned margin, height scan"] = env_runner(
            args.env, args.num_envs, actions, margin="learned", height_scan=True, **extra
        )
    if args.warp_cpu:
        runners["env, learned margin, physics='warp' on Warp's CPU device"] = env_runner(
            args.env, args.num_envs, actions, margin="learned", physics="warp", physics_device="cpu", **extra
        )
    rates = {name: summarise(values) for name, values in interleave(runners, args.rounds).items()}
    names = list(runners)
    print(machine_line())
    print(f"{args.env}, {args.num_envs} envs, {args.steps} steps, {args.rounds} interleaved rounds (median, min-max)")
    print()
    print_table(
        ("configuration", "env-steps/s", "range"),
        [(name, f"{r.median:,.0f}", f"{r.low:,.0f}–{r.high:,.0f}") for name, r in rates.items()],
    )
    print()
    with_margin, without = rates[names[0]].median, rates[names[1]].median
    overhead = 100 * (without / with_margin - 1)
    print(f"margin overhead (no margin / learned margin - 1): {overhead:.1f} %")
    of_raw = {raw: 100 * with_margin / rates[raw].median for raw in names if raw.startswith("raw ")}
    for raw, share in of_raw.items():
        print(f"env with the learned margin / {raw}: {share:.0f} %")
    write_record(
        args.json,
        "env_steps",
        args,
        {"env_steps_per_s": rates, "margin_overhead_pct": overhead, "share_of_raw_pct": of_raw},
    )


if __name__ == "__main__":
    main()
