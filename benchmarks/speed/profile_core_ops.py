"""Profile: the torch operations of one environment step of the core on the Warp backend, and its host time.

On a GPU every torch operation that computes is a kernel launch from Python, so the count of operations per step
bounds how fast the core can step whatever the batch size, and every host read stalls it. This runs the core of the
GPU benchmark (:func:`benchmarks.speed.bench_gpu.make_core`) on Warp's CPU device, times the step with and without
its physics, counts the aten operations it dispatches per step (the views among them, and the bytes the others read
and write), its host reads and random numbers (:class:`~benchmarks.tools.host_reads.DispatchCounter`, a
``TorchDispatchMode``: top-level operations, not torch.profiler's nested ones), and with ``--rsl`` the host reads of
rsl-rl's training loop over the adapter::

    python benchmarks/speed/profile_core_ops.py [--num-envs 16] [--steps 20] [--env margin_rl/AnymalC-v1] [--rsl]
        [--by-source 30]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

import torch

from benchmarks.speed.bench_gpu import RECIPE, ROBOT_ID, make_core, random_actions
from benchmarks.tools.host_reads import DispatchCounter


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--steps", type=int, default=20, help="timed and profiled steps, after 5 of warm-up")
    parser.add_argument("--env", default=ROBOT_ID)
    parser.add_argument("--recipe", default=RECIPE)
    parser.add_argument("--top", type=int, default=20, help="operations listed, most frequent first")
    parser.add_argument("--rsl", action="store_true", help="also count the host reads of rsl-rl's training loop")
    parser.add_argument(
        "--by-source",
        type=int,
        default=0,
        metavar="K",
        help="also the operations per module and the K source lines that dispatch the most (slower)",
    )
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
    counter = DispatchCounter(by_source=args.by_source > 0)
    with counter:
        for k in range(5 + args.steps, 5 + 2 * args.steps):
            core.step(actions[k])
    rest = total - physics
    print(
        f"{args.env}, {args.num_envs} environments on Warp's CPU device, per step: {1e3 * total:.2f} ms, of it "
        f"physics {1e3 * physics:.2f} ms, the rest {1e3 * rest:.2f} ms; {counter.total / args.steps:,.0f} aten "
        f"operations dispatched ({counter.views / args.steps:,.0f} views, {counter.kernels / args.steps:,.0f} "
        f"kernels), {sum(counter.host_reads.values()) / args.steps:.1f} host reads ({dict(counter.host_reads)}), "
        f"{counter.random_numbers / args.steps:,.0f} random numbers; the kernels read and write "
        f"{counter.bytes_moved / args.steps / 2**20:.2f} MiB per step, "
        f"{counter.bytes_moved / args.steps / args.num_envs / 1024:.1f} KiB per environment"
    )
    print("\n| operation | dispatched per step |\n|---|---|")
    for name, count in counter.ops.most_common(args.top):
        print(f"| `{name}` | {count / args.steps:.0f} |")
    if args.by_source:
        print("\n" + by_source(counter, args.steps, args.by_source))
    if args.rsl:
        print("\n" + rsl_host_reads(args.env, args.recipe, args.num_envs))
    return 0


def by_source(counter: DispatchCounter, steps: int, top: int) -> str:
    """Markdown: the operations per step each module of the package dispatches and the KiB its kernels move, then the
    ``top`` source lines that dispatch the most, with their operations."""
    modules: dict[str, list[float]] = {}
    for line, ops in counter.sources.items():
        totals = modules.setdefault(line.rsplit(":", 1)[0], [0.0, 0.0])
        totals[0] += sum(ops.values()) / steps
        totals[1] += counter.source_bytes[line] / steps / 1024
    lines = ["| module | operations per step | KiB moved per step |", "|---|---|---|"]
    ranked_modules = sorted(modules.items(), key=lambda item: -item[1][0])
    lines += [f"| `{m}` | {n:.0f} | {kib:,.1f} |" for m, (n, kib) in ranked_modules]
    lines += ["", "| source line | operations per step | KiB moved per step | of them |", "|---|---|---|---|"]
    ranked = sorted(counter.sources.items(), key=lambda item: -sum(item[1].values()))[:top]
    for line, ops in ranked:
        detail = ", ".join(f"{name} {n / steps:g}" for name, n in ops.most_common())
        kib = counter.source_bytes[line] / steps / 1024
        lines.append(f"| `{line}` | {sum(ops.values()) / steps:g} | {kib:,.1f} | {detail} |")
    return "\n".join(lines)


def rsl_host_reads(env_id: str, recipe: str, num_envs: int, rollout: int = 8) -> str:
    """Host reads in rsl-rl's training loop over the adapter, one iteration of ``rollout`` steps: per environment step
    in the rollout (the adapter, the policy, rsl-rl's NaN check and logger) and in the update (once per iteration),
    with rsl-rl's NaN check on and off; and the adapter's step alone."""
    from rsl_rl.runners import OnPolicyRunner

    from margin_rl.train import make_rsl_env
    from margin_rl.train.config import RslPPOConfig
    from margin_rl.train.recipes import get_recipe, with_recipe
    from margin_rl.train.runs import quiet_stdout

    def reads(counter: DispatchCounter) -> int:
        return sum(counter.host_reads.values())

    lines = [
        "| rsl-rl's loop (logger on) | host reads per rollout step | in the update, per iteration |",
        "|---|---|---|",
    ]
    options = with_recipe(get_recipe(recipe), {})
    for check_for_nan in (True, False):
        env = make_rsl_env(env_id, num_envs, seed=0, physics="warp", physics_device="cpu", **options)
        config = RslPPOConfig(num_steps_per_env=rollout).runner_cfg(False, 50) | {"check_for_nan": check_for_nan}
        with tempfile.TemporaryDirectory() as logs, quiet_stdout(True):
            runner = OnPolicyRunner(env, config, log_dir=logs)
            env.set_rollout_length(rollout)
            runner.learn(num_learning_iterations=1)  # kernels, first rollout
            total, update = DispatchCounter(), DispatchCounter()
            learner_update = runner.alg.update

            def counted_update(*args, _update=learner_update, _counter=update, **kwargs):
                with _counter:
                    return _update(*args, **kwargs)

            runner.alg.update = counted_update
            with total:
                runner.learn(num_learning_iterations=1)
        in_rollout = (reads(total) - reads(update)) / rollout
        lines.append(f"| `check_for_nan={check_for_nan}` | {in_rollout:.1f} | {reads(update)} |")
    adapter = make_rsl_env(env_id, num_envs, seed=0, physics="warp", physics_device="cpu", **options)
    adapter.set_rollout_length(rollout)
    counter = DispatchCounter()
    with counter:
        for _ in range(rollout):
            adapter.step(torch.zeros(num_envs, 12))
    lines.append(f"| the adapter's step alone | {reads(counter) / rollout:.1f} | – |")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
