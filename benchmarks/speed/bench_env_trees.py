"""Benchmark: env-steps/s of two source trees side by side, to show that a change to the environments costs nothing.

Usage:
    git worktree add /tmp/base <revision> && pip install --no-deps --target /tmp/base_pkg /tmp/base
    python benchmarks/speed/bench_env_trees.py --base /tmp/base_pkg --base-env margin_rl/AnymalB-v0 [--rounds 6]
        [--steps 1000] [--num-envs 64] [--warp-cpu] [--json PATH]

Each round steps the native vector env (``gym.make_vec``, same-step autoreset: the training adapters' mode) of
both trees, each in a fresh process (the base tree first on ``PYTHONPATH``, this tree as installed), in an order
that alternates between rounds, for ``margin="learned"`` and ``margin="none"``; the same seeded random actions
for both (``--warp-cpu``: both on MuJoCo Warp on Warp's CPU device, the device step). Prints the medians over
rounds, the median of the per-round ratios (this tree / base) and every round's ratio: on a shared machine only
the ratios of one run compare.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

from benchmarks.harness import interleave, machine_line, median_ratio, parser, print_table, summarise, write_record

STEPPER = r"""
import json, sys, time
import gymnasium as gym, numpy as np
import margin_rl  # registers the ids
env_id, margin, num_envs, steps = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
options = json.loads(sys.argv[5])
if gym.spec(env_id).version >= 1:  # v0 had same-step autoreset only, and no option to ask for it
    options["autoreset_mode"] = gym.vector.AutoresetMode.SAME_STEP
env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", margin=margin, **options)
env.reset(seed=0)
actions = np.random.default_rng(0).uniform(-1, 1, size=(steps + 20, num_envs, 12))
for a in actions[:20]:  # warm-up
    env.step(a)
t0 = time.perf_counter()
for a in actions[20:]:
    env.step(a)
print(json.dumps(num_envs * steps / (time.perf_counter() - t0)))
"""


def env_steps_per_s(
    pythonpath: str | None, env_id: str, margin: str, num_envs: int, steps: int, options: dict | None = None
) -> float:
    """One measurement in a fresh interpreter (``pythonpath`` first on its path: the other tree); ``options``: more
    keyword arguments of the environment (the physics backend)."""
    env = dict(os.environ, GIT_PYTHON_REFRESH="quiet")
    if pythonpath:
        env["PYTHONPATH"] = os.pathsep.join(p for p in (pythonpath, env.get("PYTHONPATH")) if p)
    command = [sys.executable, "-c", STEPPER, env_id, margin, str(num_envs), str(steps), json.dumps(options or {})]
    out = subprocess.run(command, env=env, cwd="/", capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"the stepper failed for {env_id} ({pythonpath or 'this tree'}):\n{out.stderr[-2000:]}")
    return float(out.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = parser(__doc__)
    ap.add_argument("--base", required=True, help="site folder of the other tree (pip install --target)")
    ap.add_argument("--base-env", default="margin_rl/AnymalB-v0", help="the id in the other tree")
    ap.add_argument("--env", default="margin_rl/AnymalB-v1", help="the id in this tree")
    ap.add_argument("--num-envs", type=int, default=64)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument(
        "--warp-cpu", action="store_true", help="both trees on MuJoCo Warp on Warp's CPU device (the device step)"
    )
    args = ap.parse_args()
    options = {"physics": "warp", "physics_device": "cpu"} if args.warp_cpu else {}
    if not Path(args.base, "margin_rl").is_dir():
        ap.error(f"--base {args.base} holds no margin_rl package: pip install --no-deps --target {args.base} <tree>")
    print(machine_line())
    rows, record = [], {}
    for margin in ("learned", "none"):
        runners = {
            "base": lambda _r, m=margin: env_steps_per_s(
                args.base, args.base_env, m, args.num_envs, args.steps, options
            ),
            "this": lambda _r, m=margin: env_steps_per_s(None, args.env, m, args.num_envs, args.steps, options),
        }
        values = interleave(runners, args.rounds, alternate=True)
        ratios = [t / b for t, b in zip(values["this"], values["base"], strict=True)]
        rows.append(
            (
                f"env, margin={margin}",
                f"{summarise(values['base']).median:,.0f}",
                f"{summarise(values['this']).median:,.0f}",
                f"{median_ratio(values['this'], values['base']):.2f}",
                ", ".join(f"{r:.2f}" for r in ratios),
            )
        )
        record[margin] = values
    print_table(["configuration", "base, median", "this tree, median", "ratio (median)", "per-round ratios"], rows)
    if args.json:
        write_record(args.json, "bench_env_trees", args, {"env_steps_per_s": record})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
