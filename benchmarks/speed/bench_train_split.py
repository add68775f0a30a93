"""Benchmark: where a PPO iteration's time goes, and training's rate against the environment alone.

Usage:
    python benchmarks/speed/bench_train_split.py [--env margin_rl/AnymalB-v1] [--iterations 12] [--rounds 3]
        [--configs 128:1 512:1 512:2] [--json PATH]

A configuration ``ENVS:THREADS[:passive]`` trains rsl-rl PPO (the package's runner and PPO settings, margin weight
0.2, the robust recipe's environment) with ``ENVS`` environments and ``THREADS`` torch threads inside the PPO update
(one thread during collection, as in training); ``passive`` also sets ``OMP_WAIT_POLICY=PASSIVE`` (torch's OpenMP
workers sleep instead of spinning after the update). Each configuration runs in its own process (the OpenMP
setting is read at start), rounds interleave the configurations, and the table gives medians over rounds of:

* training rate: environment steps per second over whole iterations (collection and update);
* environment alone: the same steps divided by the time spent inside the environment's step
  (``AnymalCore.step``, the physics and the margin: what the environment alone would run at with the same
  actions);
* their ratio, which is the share of training time spent stepping the environment;
* per iteration: the environment's time, the policy's (``PPO.act``), the update's, and the rest.

The first iterations (warm-up, two) are not timed.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

from benchmarks.harness import machine_line, parser, write_record

WORKER = r"""
import json, os, sys, time
os.environ.setdefault("GIT_PYTHON_REFRESH", "quiet")
import torch
from rsl_rl.runners import OnPolicyRunner
from margin_rl.train.backends.rsl import make_rsl_env
from margin_rl.train.config import RslPPOConfig
from margin_rl.train.recipes import get_recipe, with_recipe

env_id, num_envs, threads, iterations = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
torch.set_num_threads(1)
torch.manual_seed(0)
options = with_recipe(get_recipe("robust"), {"margin_weight": 0.2})
env = make_rsl_env(env_id, num_envs=num_envs, seed=0, **options)
spent = {"env": 0.0, "act": 0.0, "update": 0.0}

def timed(name, function, threads=None):
    def call(*args, **kwargs):
        if threads is not None:
            torch.set_num_threads(threads)
        start = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            spent[name] += time.perf_counter() - start
            if threads is not None:
                torch.set_num_threads(1)
    return call

env.core.step = timed("env", env.core.step)
runner = OnPolicyRunner(env, RslPPOConfig().runner_cfg(False, 10**9), log_dir=None, device="cpu")
runner.alg.act = timed("act", runner.alg.act)
runner.alg.update = timed("update", runner.alg.update, threads)
runner.learn(2)
spent.update(env=0.0, act=0.0, update=0.0)
start = time.perf_counter()
runner.learn(iterations)
wall = time.perf_counter() - start
print(json.dumps({"wall": wall, "steps": iterations * num_envs * RslPPOConfig().num_steps_per_env, **spent}))
"""


def run_config(env_id: str, config: str, iterations: int) -> dict[str, float]:
    parts = config.split(":")
    num_envs, threads = int(parts[0]), int(parts[1])
    environment = dict(os.environ)
    if len(parts) > 2 and parts[2] == "passive":
        environment["OMP_WAIT_POLICY"] = "PASSIVE"
    command = [sys.executable, "-c", WORKER, env_id, str(num_envs), str(threads), str(iterations)]
    out = subprocess.run(command, capture_output=True, text=True, env=environment, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    steps, wall, env = result["steps"], result["wall"], result["env"]
    n = iterations
    return {
        "train_rate": steps / wall,
        "env_rate": steps / env,
        "ratio": env / wall,
        "env_s": env / n,
        "act_s": result["act"] / n,
        "update_s": result["update"] / n,
        "other_s": (wall - env - result["act"] - result["update"]) / n,
    }


def main() -> None:
    p = parser(__doc__)
    p.add_argument("--env", default="margin_rl/AnymalB-v1")
    p.add_argument("--iterations", type=int, default=12)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--configs", nargs="+", default=["128:1", "512:1", "512:2", "512:2:passive"])
    args = p.parse_args()
    samples: dict[str, list[dict[str, float]]] = {config: [] for config in args.configs}
    for _ in range(args.rounds):
        for config in args.configs:
            samples[config].append(run_config(args.env, config, args.iterations))
    print(machine_line())
    print(f"{args.env}, {args.iterations} iterations x {args.rounds} rounds, medians\n")
    print("| envs:update threads | training [steps/s] | environment alone [steps/s] | ratio | per iteration: env / "
          "act / update / other [s] |")  # fmt: skip
    print("|---|---|---|---|---|")
    record = {}
    for config, runs in samples.items():
        med = {key: statistics.median(run[key] for run in runs) for key in runs[0]}
        record[config] = {"median": med, "rounds": runs}
        print(
            f"| {config} | {med['train_rate']:,.0f} | {med['env_rate']:,.0f} | {med['ratio']:.2f} | "
            f"{med['env_s']:.3f} / {med['act_s']:.3f} / {med['update_s']:.3f} / {med['other_s']:.3f} |"
        )
    write_record(args.json, "bench_train_split", args, {"env": args.env, "configs": record})


if __name__ == "__main__":
    main()
