"""Profile: the torch operations of one environment step of the core on the Warp backend, and its host time.

On a GPU every torch operation that computes is a kernel launch from Python, so the count of operations per step
bounds how fast the core can step whatever the batch size. This runs the core of the GPU benchmark
(:func:`benchmarks.speed.bench_gpu.make_core`) on Warp's CPU device, times the step with and without its physics,
and counts the aten operations per step with ``torch.profiler``::

    python benchmarks/speed/profile_core_ops.py [--num-envs 16] [--steps 20] [--env margin_rl/AnymalC-v1]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

import torch

from benchmarks.speed.bench_gpu import RECIPE, ROBOT_ID, make_core, random_actions


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--steps", type=int, default=20, help="timed and profiled steps, after 5 of warm-up")
    parser.add_argument("--env", default=ROBOT_ID)
    parser.add_argument("--recipe", default=RECIPE)
    parser.add_argument("--top", type=int, default=20, help="operations listed, most frequent first")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    core = make_core(args.num_envs, "cpu", "learned", args.env, args.recipe)
    actions = random_actions(5 + 2 * args.steps, args.num_envs, "cpu")
    physics_step, physics_seconds = core.physics.step, [0.0]

    def timed_physics(nstep: int):  # the core's own call, timed
        start = time.perf_counter()
        result = physics_step(nstep)
        physics_seconds[0] += time.perf_counter() - start
        return result

    core.physics.step = timed_physics
    for k in range(5):
        core.step(actions[k])
    physics_seconds[0] = 0.0
    start = time.perf_counter()
    for k in range(5, 5 + args.steps):
        core.step(actions[k])
    total = (time.perf_counter() - start) / args.steps
    physics = physics_seconds[0] / args.steps
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as profile:
        for k in range(5 + args.steps, 5 + 2 * args.steps):
            core.step(actions[k])
    events = [e for e in profile.key_averages() if e.key.startswith("aten::")]
    per_step = sum(e.count for e in events) / args.steps
    rest = total - physics
    print(
        f"{args.env}, {args.num_envs} environments on Warp's CPU device, per step: {1e3 * total:.2f} ms, of it "
        f"physics {1e3 * physics:.2f} ms, the rest {1e3 * rest:.2f} ms; {per_step:,.0f} aten calls"
    )
    print("\n| operation | calls per step | self CPU time per step [ms] |\n|---|---|---|")
    for event in sorted(events, key=lambda e: -e.count)[: args.top]:
        print(
            f"| `{event.key}` | {event.count / args.steps:.0f} | {event.self_cpu_time_total / args.steps / 1e3:.3f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
