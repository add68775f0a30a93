"""Benchmark: training on one GPU with the MuJoCo Warp backend, side by side in one run, stage by stage.

Usage (on a machine with a GPU; about 5 minutes including Warp's kernel compile)::

    python benchmarks/speed/bench_gpu.py --device cuda:0 --out "$OUT"
    python benchmarks/speed/bench_gpu.py --smoke --out /tmp/bench_gpu      # every stage, small, on Warp's CPU device
    python benchmarks/speed/bench_gpu.py --env margin_rl/AnymalC-Rough-v1 --recipe rough --stages physics_and_env

``--env`` and ``--recipe`` choose the environment and training recipe of every stage (default: the robust recipe
on flat ANYmal C); the rough recipe's environment has the terrain curriculum and the actor's height scan.

Stages, in this order, each appended to ``<out>/bench_gpu.json`` as soon as it is measured (a run cut short keeps
what it measured):

0. ``graph_parity``: the environment's step replayed as one CUDA graph (``envs/step_graph.py``) against the same
   step launched eagerly, same seed and actions, at the smallest ``--num-envs``; and two replayed cores against each
   other (determinism). On Warp's CPU device both cores step eagerly (torch records no graph there).
1. ``physics``: raw Warp physics of the environments' model: the same random actions written as servo targets, the
   decimated step (4 physics steps and the forward pass, a CUDA graph on a GPU), no environment work; env-steps/s
   at each ``--num-envs``.
2. ``env``: the batched environment core on the same device (``AnymalCore(physics="warp")``: lambda, the learned
   margin's torch form, rewards, terminations, observations, resets), with the learned margin and with
   ``margin="none"``, the same actions, each step replayed as one graph on a GPU; there also the learned margin's
   step with its torch stages launched eagerly (``env_learned_eager``: the step before the step graph);
   env-steps/s and the ratio to stage 1.
3. ``ppo``: rsl-rl PPO end to end (``make_rsl_env(..., physics="warp")``, ``OnPolicyRunner.learn``: rollouts and
   updates, the learner on the same device), the recipe's PPO settings; env-steps/s.
4. ``training``: the recipe on the environment (default: robust, ANYmal C), both variants (margin weight 0 and
   the recipe's), ``--train-envs`` environments for ``--train-steps`` steps each through ``margin_rl.train``'s own
   ``train`` (checkpoints, the run directory), then every checkpoint evaluated after training with the standard
   protocol of ``benchmarks/studies/bench_learning_speed.py`` (deterministic 20 s episodes at 0.75 m/s from
   evaluation seed 1000 on ``mujoco.batch``): the time to the walking target (error <= 0.15 m/s, < 5 % falls)
   and to the end.

Medians over ``--rounds`` interleaved rounds for stages 1 and 2 (round r measures every configuration once). On a
GPU every timing waits for the device (``torch.cuda.synchronize``) before the clock is read. The JSON also lists
the Warp modules compiled during the run (``warp_modules_compiled``: name and seconds) and the kernel cache used
(``WARP_CACHE_PATH``, e.g. one compiled ahead by ``python -m margin_rl.train kernels``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

os.environ.setdefault("GIT_PYTHON_REFRESH", "quiet")

import numpy as np
import torch

from benchmarks.harness import machine, machine_line
from margin_rl.atomic import atomic_write_text
from margin_rl.envs.warp_kernels import counting_compiles

ROBOT_ID = "margin_rl/AnymalC-v1"
RECIPE = "robust"
JSON_NAME = "bench_gpu.json"
LIBRARIES = ("mujoco", "mujoco-warp", "warp-lang", "torch", "rsl-rl-lib", "numpy")

SMOKE = {
    "device": "cpu",
    "num_envs": [4, 8],
    "steps": 6,
    "rounds": 2,
    "ppo_iterations": 1,
    "train_envs": 8,
    "train_steps": 8 * 24 * 2,
    "episodes": 2,
    "episode_steps": 10,
    "parity_steps": 4,
}
"""Every stage, small, on Warp's CPU device (what the CI test runs): checks the script, measures nothing useful."""


class Record:
    """The benchmark's JSON record, rewritten atomically after every stage."""

    def __init__(self, path: Path, settings: dict[str, Any]) -> None:
        self.path = path
        self.data: dict[str, Any] = {
            "command": " ".join([Path(sys.executable).name, *sys.argv]),
            "machine": machine(LIBRARIES),
            "gpu": torch.cuda.get_device_name(settings["device"]) if settings["device"].startswith("cuda") else None,
            "settings": settings,
            "stages": {},
        }
        self.write()

    def stage(self, name: str, result: Any) -> None:
        self.data["stages"][name] = result
        self.write()
        print(f"[{name}] {json.dumps(result, default=float)[:2000]}", flush=True)

    def write(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.path, json.dumps(self.data, indent=2, default=float) + "\n")


STARTED = time.perf_counter()


def progress(message: str) -> None:
    """A line with the seconds since the script started: a run cut short by its time limit shows where it was."""
    print(f"[{time.perf_counter() - STARTED:7.1f} s] {message}", flush=True)


def synchronize(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize(device)


def timed_rate(step: Callable[[int], None], steps: int, num_envs: int, device: str) -> float:
    """env-steps/s of ``steps`` calls of ``step(k)``, waiting for the device before each clock read."""
    synchronize(device)
    t0 = time.perf_counter()
    for k in range(steps):
        step(k)
    synchronize(device)
    return num_envs * steps / (time.perf_counter() - t0)


def make_core(
    num_envs: int, device: str, margin: str, env_id: str = ROBOT_ID, recipe: str = RECIPE, step_graph: bool = True
) -> Any:
    """The environment core of ``recipe`` on ``env_id`` (default: the robust recipe on flat ANYmal C) on the Warp
    backend at ``device``; ``step_graph=False``: its torch stages launched eagerly on a GPU, the physics still
    replaying its own Warp graphs (the step before ``envs/step_graph.py``)."""
    from margin_rl.envs.core import DEVICE_CHECK_STEPS, AnymalCore
    from margin_rl.train.commands.train import build_parser, spec_from_args

    spec, _, _ = spec_from_args(build_parser().parse_args(["--env", env_id, "--recipe", recipe]))
    config = spec.env_config.replace(margin=margin)
    core = AnymalCore(config, num_envs, seed=0, physics="warp", physics_device=device)
    if not step_graph:
        core._step_graph = None
    core.check_every = DEVICE_CHECK_STEPS  # its checks read once per rollout, as the rsl-rl adapter sets them
    core.reset(seed=0)
    return core


def random_actions(steps: int, num_envs: int, device: str) -> torch.Tensor:
    generator = torch.Generator(device="cpu").manual_seed(0)
    return (torch.rand((steps, num_envs, 12), generator=generator, dtype=torch.float64) * 2 - 1).to(device)


def step_runners(
    num_envs: int, steps: int, device: str, env_id: str = ROBOT_ID, recipe: str = RECIPE, step_graph: bool = True
) -> dict[str, Callable[[int], None]]:
    """Configuration -> ``run(k)``, policy step k of one fixed sequence of random actions: the raw physics (the
    servo targets the core would write, computed beforehand, then the decimated step) and the core with and without
    the learned margin (``step_graph=False``: every core's torch stages eager)."""
    actions = random_actions(steps, num_envs, device)
    raw = make_core(num_envs, device, "none", env_id, recipe)
    physics, decimation = raw.physics, raw.config.decimation
    targets = (raw._key_ctrl + raw.config.action_scale * actions).to(physics.ctrl.dtype)

    def raw_step(k: int) -> None:
        physics.ctrl[:] = targets[k]
        physics.step(decimation)

    def env_step(margin: str, graph: bool) -> Callable[[int], None]:
        core = make_core(num_envs, device, margin, env_id, recipe, graph)
        return lambda k: core.step(actions[k])

    runners = {
        "physics": raw_step,
        "env_learned": env_step("learned", step_graph),
        "env_no_margin": env_step("none", step_graph),
    }
    if step_graph and device.startswith("cuda"):  # the same steps, the torch stages launched one by one
        runners["env_learned_eager"] = env_step("learned", False)
    return runners


def graph_parity(
    num_envs: int,
    steps: int,
    device: str,
    partial: Callable[[dict[str, Any]], None],
    env_id: str = ROBOT_ID,
    recipe: str = RECIPE,
) -> dict:
    """Stage 0: the step replayed as one graph (``envs/step_graph.py``) against the same step launched eagerly, from
    the same seed and actions, step by step (largest differences of the observation, reward, done flags and the
    physics' qpos); and two replayed cores against each other (whether a replayed run is deterministic). Raises,
    after ``partial`` got the rows, where the step could not be recorded (it then ran eagerly)."""
    actions = random_actions(steps, num_envs, device)
    cores = {
        "graph": make_core(num_envs, device, "learned", env_id, recipe),
        "again": make_core(num_envs, device, "learned", env_id, recipe),
        "eager": make_core(num_envs, device, "learned", env_id, recipe, step_graph=False),
    }
    rows = []
    for k in range(steps):
        out = {name: core.step(actions[k]) for name, core in cores.items()}
        row = {}
        for first, second in (("graph", "eager"), ("graph", "again")):
            a, b = out[first], out[second]
            row[f"{first}_vs_{second}"] = {
                "observation": float((a.observation - b.observation).abs().max()),
                "reward": float((a.reward - b.reward).abs().max()),
                "done_differs": int(((a.terminated | a.truncated) != (b.terminated | b.truncated)).sum()),
                "qpos": float((cores[first].physics.qpos - cores[second].physics.qpos).abs().max()),
            }
        rows.append(row)
    recorder = cores["graph"]._step_graph
    result = {
        "num_envs": num_envs,
        "steps": steps,
        "recorded": recorder is not None and recorder.recordings > 0,
        "failure": None if recorder is None else recorder.failure,
        "per_step": rows,
        "max": {pair: {key: max(row[pair][key] for row in rows) for key in rows[0][pair]} for pair in rows[0]},
    }
    if result["failure"] is not None:
        partial(result)
        raise RuntimeError(f"the step was not recorded as a CUDA graph: {result['failure']}")
    return result


def physics_and_env(
    sizes: list[int],
    steps: int,
    rounds: int,
    device: str,
    partial: Callable[[dict[str, Any]], None],
    env_id: str = ROBOT_ID,
    recipe: str = RECIPE,
    step_graph: bool = True,
) -> dict[str, Any]:
    """Stages 1 and 2: raw physics and the environment core, interleaved per round, at every size (``partial``
    is called with the results so far after each size; ``step_graph`` as in :func:`step_runners`)."""
    results: dict[str, Any] = {}
    for num_envs in sizes:
        clock = time.perf_counter()
        runners = step_runners(num_envs, steps, device, env_id, recipe, step_graph)
        setup = {"build_s": time.perf_counter() - clock}
        progress(f"{num_envs} environments: three cores built in {setup['build_s']:.1f} s")
        for name, run in runners.items():  # warm-up: kernels compiled and loaded, graphs captured, modules built
            clock = time.perf_counter()
            for k in range(min(3, steps)):
                run(k)
            synchronize(device)
            setup[f"warm_up_{name}_s"] = time.perf_counter() - clock
            progress(f"{num_envs} environments: {name} warmed up in {setup[f'warm_up_{name}_s']:.1f} s")
        rates: dict[str, list[float]] = {name: [] for name in runners}
        for round_index in range(rounds):
            for name, run in runners.items():
                rates[name].append(timed_rate(run, steps, num_envs, device))
            progress(f"{num_envs} environments: round {round_index + 1} of {rounds}")
        medians = {name: float(np.median(values)) for name, values in rates.items()}
        results[str(num_envs)] = {
            "env_steps_per_s": medians,
            "rounds": rates,
            **{f"{name}_over_physics": medians[name] / medians["physics"] for name in medians if name != "physics"},
            "setup_seconds": setup,
        }
        del runners
        partial(results)
    return results


def ppo(
    sizes: list[int],
    iterations: int,
    device: str,
    partial: Callable[[dict[str, Any]], None],
    env_id: str = ROBOT_ID,
    recipe: str = RECIPE,
) -> dict[str, Any]:
    """Stage 3: rsl-rl PPO end to end with the recipe's settings on the learner's device (``partial`` as
    in :func:`physics_and_env`)."""
    from rsl_rl.runners import OnPolicyRunner

    from margin_rl.train.backends.rsl import rsl_vec_env
    from margin_rl.train.commands.train import build_parser, spec_from_args
    from margin_rl.train.runs import quiet_stdout

    results: dict[str, Any] = {}
    for num_envs in sizes:
        argv = ["--env", env_id, "--recipe", recipe, "--num-envs", str(num_envs), "--device", device]
        spec, _, _ = spec_from_args(build_parser().parse_args(argv))
        env = rsl_vec_env(spec.target, num_envs, 0, device, "warp", device)  # what `train --physics warp` builds
        progress(f"PPO, {num_envs} environments: environment built")
        with quiet_stdout(True):  # rsl-rl prints the networks and a block per iteration
            runner = OnPolicyRunner(env, spec.backend_config("bench"), log_dir=None, device=device)
            env.set_rollout_length(int(runner.cfg["num_steps_per_env"]))  # as train's runner sets it
            runner.learn(num_learning_iterations=1)  # warm-up: graphs, kernels, the optimizer's state
            synchronize(device)
            t0 = time.perf_counter()
            runner.learn(num_learning_iterations=iterations)
            synchronize(device)
            elapsed = time.perf_counter() - t0
        steps = iterations * num_envs * spec.ppo.steps_per_env
        results[str(num_envs)] = {"env_steps_per_s": steps / elapsed, "iterations": iterations, "env_steps": steps}
        progress(f"PPO, {num_envs} environments: {steps / elapsed:,.0f} env-steps/s")
        del runner, env
        partial(results)
    return results


def training(
    args: argparse.Namespace, settings: dict[str, Any], partial: Callable[[dict[str, Any]], None]
) -> dict[str, Any]:
    """Stage 4: both variants of the recipe, each trained then evaluated checkpoint by checkpoint
    (``partial`` as in :func:`physics_and_env`, after each variant)."""
    from benchmarks.studies.bench_learning_speed import FALL_FRACTION_TARGET, VELOCITY_ERROR_TARGET
    from margin_rl.train.commands.evaluate import evaluate
    from margin_rl.train.commands.train import build_parser, spec_from_args, train
    from margin_rl.train.recipes import get_recipe

    device = settings["device"]
    results: dict[str, Any] = {}
    runs_root = Path(args.runs_root) if args.runs_root else Path(tempfile.mkdtemp(prefix="bench_gpu_runs_"))
    for weight in (0.0, get_recipe(settings["recipe"]).margin_weight):
        argv = [
            "--env", settings["env_id"], "--recipe", settings["recipe"], "--margin-weight", str(weight),
            "--num-envs", str(settings["train_envs"]), "--total-steps", str(settings["train_steps"]),
            "--checkpoint-every", str(max(1, settings["train_steps"] // 5)), "--device", device,
        ]  # fmt: skip
        spec, _, _ = spec_from_args(build_parser().parse_args(argv))
        run_dir = runs_root / f"mw{weight:g}"
        timeline: list[tuple[int, float, Path]] = []
        t0 = time.perf_counter()

        def checkpointed(path: Path, steps: int, timeline: list = timeline, t0: float = t0) -> None:
            if not timeline or timeline[-1][0] != steps:  # the final checkpoint is reported again at the end
                timeline.append((steps, time.perf_counter() - t0, path))

        progress(f"training, margin weight {weight:g}: started")
        result = train(spec, run_dir, progress=False, physics="warp", physics_device=device, on_checkpoint=checkpointed)
        rows = []
        for steps, seconds, path in timeline:
            report, _ = evaluate(
                path, episodes=settings["episodes"], seed=1000, forward_velocity=0.75,
                out_dir=path.parent / "eval" / path.stem, max_steps=settings["episode_steps"],
            )  # fmt: skip
            summary = report["summary"]
            error, falls = summary["velocity_error_mean"]["mean"], summary["fell"]["mean"]
            met = bool(error <= VELOCITY_ERROR_TARGET and falls < FALL_FRACTION_TARGET)
            rows.append({"env_steps": steps, "seconds": seconds, "velocity_error": error, "falls": falls, "met": met})
        first = next((r for r in rows if r["met"]), None)
        results[f"margin_weight_{weight:g}"] = {
            "train_seconds": result.elapsed_s,
            "env_steps": result.env_steps,
            "env_steps_per_s": result.steps_per_second,
            "seconds_to_walking_target": None if first is None else first["seconds"],
            "checkpoints": rows,
            "final_model": str(result.final_model),
        }
        partial(results)
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--smoke", action="store_true", help="every stage, small, on Warp's CPU device")
    parser.add_argument("--device", default="cuda:0", help="Warp and torch device (default cuda:0)")
    parser.add_argument("--out", type=Path, default=Path(os.environ.get("OUT", ".")), help="folder of the JSON")
    parser.add_argument("--env", default=ROBOT_ID, help=f"the environment id (default {ROBOT_ID})")
    parser.add_argument("--recipe", default=RECIPE, help=f"the training recipe of every stage (default {RECIPE})")
    parser.add_argument("--num-envs", type=int, nargs="+", default=[1024, 4096, 8192])
    parser.add_argument("--steps", type=int, default=100, help="policy steps per round (stages 1, 2)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--ppo-iterations", type=int, default=3, help="timed PPO iterations (stage 3)")
    parser.add_argument("--train-envs", type=int, default=4096)
    parser.add_argument("--train-steps", type=int, default=10_000_000)
    parser.add_argument("--episodes", type=int, default=16, help="evaluation episodes per checkpoint (stage 4)")
    parser.add_argument("--runs-root", help="where stage 4's runs go (default: a temporary folder)")
    parser.add_argument(
        "--stages", nargs="+", default=["graph_parity", "physics_and_env", "ppo", "training"],
        choices=["graph_parity", "physics_and_env", "ppo", "training"],
    )  # fmt: skip
    parser.add_argument("--parity-steps", type=int, default=50, help="steps compared in stage 0")
    args = parser.parse_args(argv)
    settings: dict[str, Any] = {
        "device": args.device,
        "env_id": args.env,
        "recipe": args.recipe,
        "num_envs": args.num_envs,
        "steps": args.steps,
        "rounds": args.rounds,
        "ppo_iterations": args.ppo_iterations,
        "train_envs": args.train_envs,
        "train_steps": args.train_steps,
        "episodes": args.episodes,
        "episode_steps": None,  # whole 20 s episodes
        "parity_steps": args.parity_steps,
    }
    if args.smoke:
        settings.update(SMOKE)
    if settings["device"].startswith("cuda") and not torch.cuda.is_available():
        parser.error(f"--device {settings['device']}: torch finds no GPU here; use --smoke for Warp's CPU device")
    print(machine_line(LIBRARIES), flush=True)
    record = Record(args.out / JSON_NAME, {**settings, "smoke": args.smoke})
    started = time.perf_counter()
    stages: dict[str, Callable[[Callable[[dict[str, Any]], None]], dict[str, Any]]] = {
        "graph_parity": lambda partial: graph_parity(
            min(settings["num_envs"]),
            settings["parity_steps"],
            settings["device"],
            partial,
            settings["env_id"],
            settings["recipe"],
        ),
        "physics_and_env": lambda partial: physics_and_env(
            settings["num_envs"],
            settings["steps"],
            settings["rounds"],
            settings["device"],
            partial,
            settings["env_id"],
            settings["recipe"],
            step_graph="graph_parity" not in failed,  # a step graph that failed to record: eager cores only
        ),
        "ppo": lambda partial: ppo(
            settings["num_envs"],
            settings["ppo_iterations"],
            settings["device"],
            partial,
            settings["env_id"],
            settings["recipe"],
        ),
        "training": lambda partial: training(args, settings, partial),
    }
    record.data["warp_cache_path"] = os.environ.get("WARP_CACHE_PATH")  # a kernel cache compiled ahead, if any
    with counting_compiles() as compiled:  # the modules Warp compiled here rather than loaded from its cache
        record.data["warp_modules_compiled"] = compiled  # the same list, filled as modules compile
        failed: list[str] = []
        for name in (name for name in stages if name in args.stages):
            if not run_stage(record, name, stages[name]):
                failed.append(name)
    record.data["warp_compile_seconds"] = sum(seconds for _, seconds in compiled)
    record.data["wall_seconds"] = time.perf_counter() - started
    record.write()
    print(f"wrote {record.path} ({record.data['wall_seconds']:.0f} s)" + (f"; failed: {failed}" if failed else ""))
    return 1 if failed else 0


def run_stage(record: Record, name: str, measure: Callable[[Callable[[dict[str, Any]], None]], dict[str, Any]]) -> bool:
    """Run one stage, writing its results as they come; a stage that raises is recorded with its traceback and the
    next one runs (on a new device one failure must not cost the other stages' figures). True when it completed."""

    def partial(results: dict[str, Any]) -> None:
        record.data["stages"][name] = {**results, "complete": False}
        record.write()

    try:
        record.stage(name, {**measure(partial), "complete": True})
        return True
    except Exception as exc:
        so_far = record.data["stages"].get(name, {})
        error = f"{type(exc).__name__}: {exc}"
        record.stage(name, {**so_far, "complete": False, "error": error, "traceback": traceback.format_exc()})
        print(traceback.format_exc(), file=sys.stderr, flush=True)
        return False


if __name__ == "__main__":
    raise SystemExit(main())
