"""``train``: PPO (rsl-rl or Stable-Baselines3) on a margin_rl ANYmal environment.

Examples::

    python -m margin_rl.train train --env margin_rl/AnymalB-v1 --backend rsl --margin-weight 0.2 --seed 1 \\
        --num-envs 128 --total-steps 5000000 --env-option reward_params.alive_bonus=0.1   # the defaults
    python -m margin_rl.train train --backend sb3 --margin-weight 0 --run-dir runs/baseline
    python -m margin_rl.train train --resume runs/baseline            # continue a stopped or killed run
    python -m margin_rl.train train --resume runs/baseline --total-steps 10000000   # ... and extend it
    python -m margin_rl.train train --env margin_rl/AnymalB-Rough-v1 --margin-weight 0 --total-steps 3000000 \
        --init-from runs/baseline/final_model.pt --run-dir runs/baseline_rough    # fine-tune a flat policy

Environments: the batched ANYmal ids (``vector_entry_point`` of the batched core), each with an ``EnvConfig``:
``--env-option`` sets its fields, and ``--margin``, ``--margin-weights``, ``--reward-preset``, ``--margin-weight``
too. Any other id is an error naming the ANYmal ids: other Gymnasium environments, e.g. the SLIP hopper, are
trained with plain Stable-Baselines3 (``examples/train_slip_hopper.py``). See :mod:`margin_rl.train.environments`.

Defaults: the command line's long-standing experiment (the first comparison's, now in the bundles' card history),
``--margin-weight 0.2`` and ``--env-option reward_params.alive_bonus=0.1`` unless given
(:mod:`margin_rl.train.commands.options`; ``make_spec`` and ``EnvConfig`` keep the paper's reward: weight 1, no
bonus).

Each run directory (default ``runs/<env>__<backend>__mw<weight>__s<seed>__<time>``) holds ``config.json``
(the environment's ``env_config``, PPO and run settings, package versions; ``--resume`` and ``evaluate`` rebuild
the environment from it), TensorBoard events in ``tb/`` (every reward term, the margin, base linear/angular
acceleration RMS and peak per axis, velocity-tracking error, stance width, terminations, throughput and SB3's
or rsl-rl's own losses), checkpoints in
``checkpoints/`` (every ``--checkpoint-every`` steps, and on SIGINT/SIGTERM), and at the end
``final_model.pt|.zip`` plus ``policy_torchscript.pt`` (deterministic actor). See :mod:`margin_rl.train.runs`
for the layout.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from margin_rl.envs.backends import PHYSICS_BACKENDS, PhysicsChoice, check_physics_choice
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.margin_kinds import check_margin_runs_on
from margin_rl.envs.physics import usable_cores
from margin_rl.provenance import sha256_file
from margin_rl.train.backends.rsl import rsl_vec_env, train_rsl
from margin_rl.train.backends.sb3 import sb3_vec_env, train_sb3
from margin_rl.train.commands import options as cli
from margin_rl.train.config import (
    BACKENDS,
    PPOConfig,
    RslPPOConfig,
    Sb3PPOConfig,
    apply_overrides,
    default_ppo_config,
    from_dict,
    parse_assignments,
    to_dict,
)
from margin_rl.train.distributed import Ranks
from margin_rl.train.environments import (
    DEFAULT_ENV,
    AnymalTarget,
    anymal_id,
    check_margin_available,
    env_target,
    margin_identity,
)
from margin_rl.train.recipes import get_recipe, with_recipe
from margin_rl.train.runs import (
    CONFIG_FILE,
    PROGRESS_FILE,
    TORCHSCRIPT_FILE,
    RunHooks,
    StopRequest,
    checkpoint_steps,
    final_model_name,
    graceful_stop,
    latest_checkpoint,
    read_json,
    run_name,
    torch_threads,
    versions,
    write_json,
)

DEFAULT_BACKEND = "rsl"
DEFAULT_SEED = 1
DEFAULT_NUM_ENVS = 128
DEFAULT_TOTAL_STEPS = 5_000_000
DEFAULT_CHECKPOINT_EVERY = 500_000


@dataclass(frozen=True)
class TrainSpec:
    """Everything that defines a training run (written to ``config.json``): a batched ANYmal id and its
    ``env_config`` (``EnvConfig()`` when not given), PPO and run settings. Build specs with :func:`make_spec`."""

    env_id: str = DEFAULT_ENV
    backend: str = DEFAULT_BACKEND
    seed: int = DEFAULT_SEED
    num_envs: int = DEFAULT_NUM_ENVS
    total_steps: int = DEFAULT_TOTAL_STEPS  # environment steps (policy steps summed over environments)
    env_config: EnvConfig | None = None
    ppo: PPOConfig = field(default_factory=RslPPOConfig)
    checkpoint_every: int = DEFAULT_CHECKPOINT_EVERY  # environment steps between checkpoints
    device: str = "cpu"  # learner device (the simulation's: the physics_device of train(), not part of the run)
    # Warm start: the network weights of this trained model (rsl-rl .pt checkpoint or final model, SB3 .zip) are the
    # run's first weights; steps, optimizer and learning-rate schedule start fresh. None: random initialisation.
    init_from: str | None = None
    # The training recipe the run started from (margin_rl.train.recipes), a record only: the settings above are what
    # the run uses. None: no recipe (options given one by one).
    recipe: str | None = None

    def __post_init__(self) -> None:
        if self.env_config is None:
            object.__setattr__(self, "env_config", EnvConfig())  # frozen: set once, here
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        expected = RslPPOConfig if self.backend == "rsl" else Sb3PPOConfig
        if not isinstance(self.ppo, expected):
            raise TypeError(f"backend {self.backend!r} needs a {expected.__name__}, got {type(self.ppo).__name__}")
        for name in ("num_envs", "total_steps", "checkpoint_every"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.init_from is not None and not isinstance(self.init_from, str):
            raise TypeError(f"init_from must be None or a path (str), got {self.init_from!r}")
        if self.recipe is not None:
            get_recipe(self.recipe)  # an unknown name: the error listing the recipes

    @property
    def target(self) -> AnymalTarget:
        """The spec's environment."""
        return AnymalTarget(self.env_id, self.env_config)

    @property
    def steps_per_iteration(self) -> int:
        """Environment steps collected per PPO update."""
        return self.num_envs * self.ppo.steps_per_env

    @property
    def total_iterations(self) -> int:
        """PPO updates needed for ``total_steps`` (rounded up)."""
        return math.ceil(self.total_steps / self.steps_per_iteration)

    @property
    def save_interval(self) -> int:
        """Iterations between checkpoints."""
        return max(1, round(self.checkpoint_every / self.steps_per_iteration))

    def backend_config(self, run: str = "") -> dict[str, Any]:
        """The exact settings handed to the backend (the rsl-rl ``train_cfg`` or SB3's PPO keyword arguments)."""
        if isinstance(self.ppo, RslPPOConfig):
            return self.ppo.runner_cfg(self.env_config.privileged_observations, self.save_interval, run)
        kwargs = self.ppo.ppo_kwargs(self.num_envs)
        policy = dict(kwargs.pop("policy_kwargs"))
        policy["activation_fn"] = policy["activation_fn"].__name__
        return {**kwargs, "policy_kwargs": policy}

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict (``config.json``)."""
        return {
            "env_id": self.env_id,
            "backend": self.backend,
            "seed": self.seed,
            "num_envs": self.num_envs,
            "total_steps": self.total_steps,
            "checkpoint_every": self.checkpoint_every,
            "device": self.device,
            "init_from": self.init_from,
            "recipe": self.recipe,
            "env_config": to_dict(self.env_config),
            "ppo": to_dict(self.ppo),
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> TrainSpec:
        """Inverse of :meth:`to_json`.

        Raises:
            ValueError: the run's id is not a batched ANYmal id, or its config has no ``env_config``.
        """
        backend = data["backend"]
        ppo_class = RslPPOConfig if backend == "rsl" else Sb3PPOConfig
        if data.get("env_config") is None:
            anymal_id(data["env_id"])  # e.g. a run of another environment: the clear error
            raise ValueError(f"run config of {data['env_id']} has no env_config")
        return cls(
            env_id=data["env_id"],
            backend=backend,
            seed=int(data["seed"]),
            num_envs=int(data["num_envs"]),
            total_steps=int(data["total_steps"]),
            checkpoint_every=int(data["checkpoint_every"]),
            device=str(data.get("device", "cpu")),
            env_config=from_dict(EnvConfig, data["env_config"], "env_config"),
            ppo=from_dict(ppo_class, data["ppo"], "ppo"),
            init_from=data.get("init_from"),  # absent in runs recorded before warm starts existed
            recipe=data.get("recipe"),  # absent in runs recorded before recipes existed
        )


@dataclass(frozen=True)
class TrainResult:
    """Outcome of :func:`train`."""

    run_dir: Path
    env_steps: int  # environment steps trained on so far (over every train call of the run)
    finished: bool  # reached total_steps; final_model and torchscript written
    stopped: bool  # stopped by a signal or request; resumable from `checkpoint`
    checkpoint: Path | None
    final_model: Path | None
    torchscript: Path | None
    session_steps: int  # steps trained in this call
    elapsed_s: float  # wall time of this call

    @property
    def steps_per_second(self) -> float:
        return self.session_steps / self.elapsed_s if self.elapsed_s > 0 else 0.0


def make_spec(
    env_id: str = DEFAULT_ENV,
    backend: str = DEFAULT_BACKEND,
    env_overrides: dict[str, Any] | None = None,
    ppo_overrides: dict[str, Any] | None = None,
    **run: Any,
) -> TrainSpec:
    """A :class:`TrainSpec` from a batched ANYmal id, EnvConfig field overrides, PPO field overrides and run
    settings.

    Raises:
        ValueError: not a batched ANYmal id (:func:`~margin_rl.train.environments.anymal_id`).
        TypeError: unknown option names or badly typed values.
    """
    config = env_target(env_id, env_overrides).config
    ppo = apply_overrides(default_ppo_config(backend), dict(ppo_overrides or {}))
    return TrainSpec(env_id=env_id, backend=backend, ppo=ppo, env_config=config, **run)


def check_environment(spec: TrainSpec) -> None:
    """Fail before a run directory is made when the spec's environment cannot be built as asked: the id must be a
    batched ANYmal one (:func:`~margin_rl.train.environments.anymal_id`) and the learned margin's weights must load
    (:func:`~margin_rl.train.environments.check_margin_available`).

    Raises:
        ValueError: with a hint on what to change.
    """
    anymal_id(spec.env_id, "train")
    check_margin_available(spec.env_config)


INIT_FROM_SUFFIX = {"rsl": ".pt", "sb3": ".zip"}
"""File type of a warm start per backend: an rsl-rl training checkpoint or final model, an SB3 model."""


def check_init_from(path: str, backend: str) -> None:
    """A warm start must be an existing model file of the run's backend (its sizes are checked when it is loaded).

    Raises:
        FileNotFoundError: no such file.
        ValueError: a file of the other backend, or a TorchScript actor (it holds no critic to continue from).
    """
    file = Path(path)
    if not file.is_file():
        raise FileNotFoundError(f"--init-from {path}: no such file; give a finished run's final model or a checkpoint")
    wanted = INIT_FROM_SUFFIX[backend]
    if file.suffix != wanted or file.name == TORCHSCRIPT_FILE:
        raise ValueError(
            f"--init-from {path}: a {backend} run starts from a {backend} model ({wanted}: the run's "
            f"{final_model_name(backend)} or a checkpoints/ckpt_<steps>{wanted}), not {file.name!r}"
        )


def write_run_config(spec: TrainSpec, run_dir: Path, command: list[str] | None) -> Path:
    """``config.json``: the spec, the exact backend settings, versions, time and command line.

    A resumed run keeps its first command and start time and lists the later ``train`` calls' commands.
    """
    now = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    data = {
        **spec.to_json(),
        "backend_config": spec.backend_config(run_dir.name),
        "versions": versions(),
        "created": now,
        "command": command if command is not None else [],
        "sessions": [{"started": now, "command": command if command is not None else []}],
    }
    path = run_dir / CONFIG_FILE
    previous = read_json(path) if path.is_file() else {}
    if spec.init_from is not None:  # what the run started from: a resumed run keeps the first call's checksum
        data["init_from_sha256"] = previous.get("init_from_sha256") or sha256_file(spec.init_from)
    # the learned margin's identity is the first call's: the weights a run started with are the ones it is
    # trained and bundled with (runs recorded before this field existed fall back to the current weights)
    data["learned_margin"] = previous.get("learned_margin") or margin_identity(spec.env_config)
    if previous:
        data["created"] = previous.get("created", now)
        data["command"] = previous.get("command", data["command"])
        data["sessions"] = [*previous.get("sessions", []), *data["sessions"]]
    return write_json(path, data)


def check_same_margin(spec: TrainSpec, run_dir: Path) -> None:
    """A resumed run must compute the learned margin its first ``train`` call computed.

    Raises:
        ValueError: the weights recorded in ``config.json`` (e.g. the robot's default network when the run
            started) differ from the ones the spec would load now, e.g. after the default network was replaced.
    """
    recorded = read_json(run_dir / CONFIG_FILE).get("learned_margin") if (run_dir / CONFIG_FILE).is_file() else None
    current = margin_identity(spec.env_config)
    if recorded is None or current is None or recorded["sha256"] == current["sha256"]:
        return
    raise ValueError(
        f"{run_dir} was trained with the learned margin {recorded['source']!r} of sha256 {recorded['sha256'][:12]}…, "
        f"but {current['source']!r} now loads weights of sha256 {current['sha256'][:12]}…: resume with "
        "--margin-weights pointing at the weights the run started with, or start a new run"
    )


def load_spec(run_dir: str | Path) -> TrainSpec:
    """The spec of an existing run (its ``config.json``)."""
    return TrainSpec.from_json(read_json(Path(run_dir) / CONFIG_FILE))


class _Progress:
    """tqdm progress bar over environment steps (disabled with ``enabled=False``)."""

    def __init__(self, total: int, initial: int, enabled: bool, label: str) -> None:
        self.bar = tqdm(
            total=total,
            initial=initial,
            unit="step",
            unit_scale=True,
            dynamic_ncols=True,
            disable=not enabled,
            desc=label,
            smoothing=0.1,
        )

    def update(self, steps: int, mean_return: float | None) -> None:
        if steps > self.bar.n:
            self.bar.update(steps - self.bar.n)
        if mean_return is not None:
            self.bar.set_postfix_str(f"return {mean_return:.2f}", refresh=False)

    def close(self) -> None:
        self.bar.close()


def train(
    spec: TrainSpec,
    run_dir: str | Path,
    *,
    resume: bool = False,
    progress: bool = True,
    verbose: bool = False,
    stop: StopRequest | None = None,
    on_checkpoint: Any = None,
    command: list[str] | None = None,
    threads: int | None = 1,
    update_threads: int | None = None,
    physics: str = "mujoco",
    physics_device: str | None = None,
    physics_options: dict[str, Any] | None = None,
) -> TrainResult:
    """Train (or, with ``resume``, continue from the latest checkpoint of ``run_dir``) one PPO run.

    SIGINT/SIGTERM (or ``stop.request()``) stop at the next safe point with a checkpoint; ``on_checkpoint(path,
    steps)`` is called after every checkpoint. ``threads``: torch intra-op threads while training (see
    :func:`margin_rl.train.runs.torch_threads`; None keeps torch's setting); ``update_threads``: torch threads
    inside the PPO update of either backend (None: one per core this process may run on, :func:`usable_cores`).
    Threads change the speed, not what PPO computes. ``physics``, ``physics_device``, ``physics_options``: the
    simulator (:func:`margin_rl.envs.backends.make_physics`), chosen per call like the threads: not part of the run's
    config, so a run trained on one backend resumes and evaluates on another. Raises FileExistsError when
    ``run_dir`` already holds checkpoints and ``resume`` is False, ValueError when the environment cannot be built
    (:func:`check_environment`).
    """
    run_dir = Path(run_dir)
    check_environment(spec)
    ranks = Ranks.from_environment()
    if ranks.distributed:
        spec, physics_device = for_rank(spec, ranks, physics, physics_device)
    checkpoint = latest_checkpoint(run_dir)
    if checkpoint is not None and not resume:
        raise FileExistsError(f"{run_dir} already holds checkpoints; use --resume to continue it, or another --run-dir")
    if not resume:
        checkpoint = None
    if checkpoint is None and spec.init_from is not None:  # a resumed run continues from its own checkpoint
        check_init_from(spec.init_from, spec.backend)
    if checkpoint is not None:
        check_same_margin(spec, run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    if ranks.writes:
        write_run_config(spec, run_dir, command)
    start = checkpoint_steps(checkpoint) if checkpoint is not None else 0
    stop = stop or StopRequest()
    label = f"{spec.backend} {run_dir.name}"
    bar = _Progress(spec.total_iterations * spec.steps_per_iteration, start, progress and ranks.writes, label)
    latest: list[Path | None] = [checkpoint]

    def checkpointed(path: Path, steps: int) -> None:
        latest[0] = path
        if ranks.writes:
            write_json(run_dir / PROGRESS_FILE, {"env_steps": steps, "checkpoint": path.name, "finished": False})
        if on_checkpoint is not None:
            on_checkpoint(path, steps)

    hooks = RunHooks(lambda: stop.requested, bar.update, checkpointed, verbose)
    t0 = time.perf_counter()
    try:
        with graceful_stop(stop, verbose=True), torch_threads(threads):
            simulator = PhysicsChoice(physics, physics_device, dict(physics_options or {}))
            steps, stopped, torchscript = _run_backend(
                spec, run_dir, checkpoint, hooks, update_threads, simulator, ranks.seed(spec.seed)
            )
    finally:
        bar.close()
    elapsed = time.perf_counter() - t0
    final = None if stopped or not ranks.writes else run_dir / final_model_name(spec.backend)
    if ranks.writes:
        write_json(
            run_dir / PROGRESS_FILE,
            {
                "env_steps": steps,
                "checkpoint": latest[0].name if latest[0] is not None else None,
                "finished": not stopped,
                "stopped": stopped,
                "stop_reason": stop.signal_name if stopped else None,
                "final_model": final.name if final is not None else None,
                "torchscript": torchscript.name if torchscript is not None else None,
                "session_steps_per_s": (steps - start) / elapsed if elapsed > 0 else None,
            },
        )
    return TrainResult(run_dir, steps, not stopped, stopped, latest[0], final, torchscript, steps - start, elapsed)


def for_rank(spec: TrainSpec, ranks: Ranks, physics: str, physics_device: str | None) -> tuple[TrainSpec, str]:
    """The spec and physics device of one of several training processes (:mod:`margin_rl.train.distributed`): the
    learner and the environments on the process's GPU.

    Raises:
        ValueError: a backend other than rsl-rl (SB3 has no distributed PPO), physics other than Warp, or a device
            given that is not the process's GPU.
    """
    where = f"training in {ranks.world_size} processes (torchrun)"
    if spec.backend != "rsl":
        raise ValueError(f"{where} runs rsl-rl's distributed PPO: use --backend rsl, not {spec.backend!r}")
    if physics != "warp":
        raise ValueError(f"{where} puts each process's environments on its GPU: use --physics warp, not {physics!r}")
    for name, given in (("--physics-device", physics_device), ("--device", spec.device)):
        if given not in (None, "cpu", "cuda", ranks.device):
            raise ValueError(
                f"{where}: process {ranks.rank} runs on {ranks.device} (LOCAL_RANK {ranks.local_rank}); leave "
                f"{name} out or give cuda, not {given!r}"
            )
    return dataclasses.replace(spec, device=ranks.device), ranks.device


def _run_backend(
    spec: TrainSpec,
    run_dir: Path,
    checkpoint: Path | None,
    hooks: RunHooks,
    update_threads: int | None,
    simulator: PhysicsChoice,
    seed: int,
) -> tuple[int, bool, Any]:
    """Seed (``seed``: the run's, or a process's own among several), build the backend's vector environment over the
    spec's environment on ``simulator``, and hand over to the backend."""
    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)
    final = run_dir / final_model_name(spec.backend)
    threads = usable_cores() if update_threads is None else update_threads
    learner = {"init_from": spec.init_from, "update_threads": threads}
    if isinstance(spec.ppo, RslPPOConfig):
        # The env's tensors go to the learner's device: with the physics there too (Warp on that GPU), no copy at all.
        env = rsl_vec_env(spec.target, spec.num_envs, seed, spec.device, *simulator.arguments)
        cfg = spec.backend_config(run_dir.name)
        return train_rsl(env, cfg, run_dir, spec.device, spec.total_iterations, checkpoint, hooks, final, **learner)
    venv = sb3_vec_env(spec.target, spec.num_envs, seed, *simulator.arguments)
    total = spec.total_iterations * spec.steps_per_iteration
    every = spec.checkpoint_every
    return train_sb3(venv, spec.ppo, run_dir, spec.seed, spec.device, total, every, checkpoint, hooks, final, **learner)


# ---------------------------------------------------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="margin-rl-train",
        description=__doc__,
        epilog=f"Defaults: {cli.DEFAULTS_HELP}.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cli.add_env_arguments(parser)
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default=None,
        help=f"PPO library (default {DEFAULT_BACKEND})",
    )
    parser.add_argument(
        "--margin-weight",
        type=float,
        help=f"weight of the margin reward term (0: baseline; default the recipe's, {cli.CLI_MARGIN_WEIGHT:g} without)",
    )
    parser.add_argument("--seed", type=int, default=None, help=f"random seed (default {DEFAULT_SEED})")
    parser.add_argument("--num-envs", type=int, default=None, help=f"parallel environments ({DEFAULT_NUM_ENVS})")
    parser.add_argument("--total-steps", type=int, default=None, help=f"environment steps ({DEFAULT_TOTAL_STEPS})")
    parser.add_argument(
        "--checkpoint-every", type=int, default=None, help=f"steps between checkpoints ({DEFAULT_CHECKPOINT_EVERY})"
    )
    parser.add_argument("--ppo-option", action="append", metavar="KEY=VALUE", help="PPO config field (repeatable)")
    cli.add_recipe_argument(
        parser,
        "start from a training recipe (margin_rl.train.recipes): its environment options, margin weight, --num-envs, "
        "--total-steps and PPO options, each replaced by the option given here",
    )
    parser.add_argument("--run-dir", type=Path, help="run directory (default: <runs-root>/<generated name>)")
    parser.add_argument("--runs-root", type=Path, default=Path("runs"), help="parent of generated run directories")
    parser.add_argument(
        "--resume",
        type=Path,
        metavar="RUN_DIR",
        help="continue this run from its latest checkpoint with its config.json's settings (--total-steps may "
        "extend it, --checkpoint-every and --device change; options that define the run are refused)",
    )
    parser.add_argument(
        "--init-from",
        metavar="MODEL",
        help="warm start: begin with the weights of this trained model (rsl: a run's final_model.pt or checkpoint; "
        "sb3: .zip), e.g. a flat-ground policy to fine-tune on rough ground; steps and optimizer start fresh",
    )
    parser.add_argument("--device", default=None, help="learner device, e.g. cpu or cuda (default cpu)")
    parser.add_argument(
        "--torch-threads", type=int, default=1, help="torch intra-op threads (default 1: leaves the cores to MuJoCo)"
    )
    parser.add_argument(
        "--update-threads",
        type=int,
        default=None,
        help="torch threads inside the PPO update (default: the cores this process may run on); with several "
        "trainings on one machine give each its share of the cores (1 for two runs on two cores: the default's "
        "threads spin against the other run's and its updates took 7x longer)",
    )
    parser.add_argument(
        "--physics",
        choices=PHYSICS_BACKENDS,
        default=PHYSICS_BACKENDS[0],
        help="simulator: mujoco (mujoco.batch, the default) or warp (MuJoCo Warp, the gpu extra). Not part of the "
        "run's config: a run resumes and evaluates on either",
    )
    parser.add_argument(
        "--physics-device",
        default=None,
        help="the simulator's device for warp: cuda:0, ... or cpu (default: the first GPU)",
    )
    parser.add_argument(
        "--physics-option",
        action="append",
        metavar="KEY=VALUE",
        help="a setting of the simulator (warp: nconmax, njmax; repeatable), e.g. --physics-option nconmax=96",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--verbose", action="store_true", help="also print the backend's own logs")
    return parser


RUN_DEFINING_OPTIONS = (
    "--env",
    "--backend",
    "--margin",
    "--margin-weight",
    "--reward-preset",
    "--terrain-difficulty",
    "--env-option",
    "--seed",
    "--num-envs",
    "--ppo-option",
    "--recipe",
    "--run-dir",
)
"""The options that define a run: refused with ``--resume``, which continues the run with
the settings its ``config.json`` recorded (``--margin-weights`` may point at the weights it started with)."""


def spec_from_args(args: argparse.Namespace) -> tuple[TrainSpec, Path, bool]:
    """(spec, run directory, resume) from parsed arguments."""
    if args.resume is not None:
        if args.init_from is not None:
            raise ValueError("--init-from starts a new run; --resume continues one from its own checkpoint: give one")
        fixed = [option for option in RUN_DEFINING_OPTIONS if getattr(args, option[2:].replace("-", "_")) is not None]
        if fixed:
            raise ValueError(
                f"--resume continues {args.resume} with the settings in its config.json; {', '.join(fixed)} would "
                "change the run: drop them, or start a new run with --run-dir (--total-steps, --checkpoint-every, "
                "--physics and --device may change on resume)"
            )
        spec = load_spec(args.resume)
        changes = {
            key: value
            for key, value in (
                ("total_steps", args.total_steps),
                ("checkpoint_every", args.checkpoint_every),
                ("device", args.device),
            )
            if value is not None
        }
        if changes:
            spec = TrainSpec.from_json({**spec.to_json(), **changes})
        if getattr(args, "margin_weights", None) is not None:  # e.g. the weights the run started with
            spec = dataclasses.replace(
                spec, env_config=dataclasses.replace(spec.env_config, margin_weights=args.margin_weights)
            )
        if spec.init_from is not None and latest_checkpoint(args.resume) is None:  # stopped before its first one
            check_init_from(spec.init_from, spec.backend)
        return spec, args.resume, True
    env_id = args.env or DEFAULT_ENV
    backend = args.backend or DEFAULT_BACKEND
    recipe = cli.recipe_of(args.recipe)
    run = {
        "seed": DEFAULT_SEED if args.seed is None else args.seed,
        "num_envs": args.num_envs or (recipe.num_envs if recipe else DEFAULT_NUM_ENVS),
        "total_steps": args.total_steps or (recipe.total_steps if recipe else DEFAULT_TOTAL_STEPS),
        "checkpoint_every": args.checkpoint_every or DEFAULT_CHECKPOINT_EVERY,
        "device": args.device or "cpu",
        "init_from": args.init_from,
        "recipe": recipe.name if recipe else None,
    }
    overrides = cli.env_overrides(args)
    ppo_overrides = parse_assignments(args.ppo_option, "--ppo-option")
    if recipe is not None:
        overrides = with_recipe(recipe, overrides)
        overrides.setdefault("margin_weight", recipe.margin_weight)
        ppo_overrides = {**recipe.ppo_overrides(backend), **ppo_overrides}
    overrides = cli.with_training_defaults(env_id, overrides)
    spec = make_spec(env_id, backend, overrides, ppo_overrides, **run)
    if spec.init_from is not None:
        check_init_from(spec.init_from, spec.backend)
    run_dir = args.run_dir or args.runs_root / run_name(env_id, backend, spec.target.margin_weight, spec.seed)
    return spec, run_dir, False


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns 0 when the run finished, 128 + signal number when it was stopped."""
    parser = build_parser()
    args = parser.parse_args(argv)
    for name in ("torch_threads", "update_threads"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    try:
        spec, run_dir, resume = spec_from_args(args)
        check_environment(spec)
        check_margin_runs_on(spec.target.config.margin, args.physics)
        physics_options = parse_assignments(args.physics_option, "--physics-option")
        check_physics_choice(args.physics, args.physics_device, physics_options)  # before the run folder is written
        if resume:
            check_same_margin(spec, run_dir)
    except (ValueError, TypeError, FileNotFoundError, ImportError) as exc:
        parser.error(str(exc))
    # recorded as a user types it, whatever path or module launched it (the bundle cards quote it)
    command = ["margin-rl-train", *(sys.argv[1:] if argv is None else argv)]
    stop = StopRequest()
    try:
        result = train(
            spec,
            run_dir,
            resume=resume,
            progress=not args.no_progress,
            verbose=args.verbose,
            stop=stop,
            command=command,
            threads=args.torch_threads,
            update_threads=args.update_threads,
            physics=args.physics,
            physics_device=args.physics_device,
            physics_options=physics_options,
        )
    except FileExistsError as exc:
        parser.error(str(exc))
    rate = f"{result.steps_per_second:,.0f} steps/s"
    if result.stopped:
        print(f"stopped at {result.env_steps:,} steps ({rate}); checkpoint {result.checkpoint}")
        print(f"resume with: python -m margin_rl.train train --resume {result.run_dir}")
        signum = getattr(signal.Signals, stop.signal_name, None) if stop.signal_name else None
        return 128 + int(signum) if signum is not None else 1
    print(f"finished {result.env_steps:,} steps ({rate}) in {result.run_dir}")
    print(f"final model {result.final_model}; TorchScript actor {result.torchscript}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
