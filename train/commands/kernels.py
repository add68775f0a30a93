"""``kernels``: compile, on a machine without a GPU, the Warp kernels a training's environment launches, for the GPU
that will run it, into a kernel cache that ``WARP_CACHE_PATH`` points Warp at there
(:mod:`margin_rl.envs.warp_kernels`).

Example (ANYmal C on flat and on rough ground, for H100 and H200 GPUs, sm_90)::

    python -m margin_rl.train kernels --env margin_rl/AnymalC-v1 --recipe robust --cache build/warp-kernels
    python -m margin_rl.train kernels --env margin_rl/AnymalC-Rough-v1 --recipe rough --cache build/warp-kernels
    # on the GPU machine:
    WARP_CACHE_PATH=build/warp-kernels python -m margin_rl.train train ... --physics warp --device cuda

The environment is the one ``train`` would build from the same ``--env``, ``--recipe``, ``--env-option`` and
``--physics-option`` (the kernels depend on the model and the simulator's settings, not on the number of
environments), stepped ``--steps`` times on Warp's CPU device with random actions, episodes ending and resetting
inside the window, the physics recorded as graphs as on a GPU. Every module it launches is compiled for
``--arch``, as cubin and PTX (``--format``); ``--cpu`` compiles for Warp's CPU device instead, which is how the cache
is checked without a GPU. A report, ``kernels-<env>-<recipe>.json`` in the cache, lists every module, its files,
seconds and any failure; the cache's size is printed.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

from margin_rl.envs.core import AnymalCore
from margin_rl.envs.warp_kernels import FORMATS, compile_ahead, record_launches, write_report
from margin_rl.train.config import parse_assignments
from margin_rl.train.environments import DEFAULT_ENV


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m margin_rl.train kernels",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--env", default=DEFAULT_ENV, help=f"margin_rl ANYmal id (default {DEFAULT_ENV})")
    parser.add_argument("--recipe", help="the training recipe whose environment is compiled for")
    parser.add_argument("--env-option", action="append", metavar="KEY=VALUE", help="as for train (repeatable)")
    parser.add_argument("--physics-option", action="append", metavar="KEY=VALUE", help="as for train (repeatable)")
    parser.add_argument("--cache", required=True, help="the kernel cache folder (WARP_CACHE_PATH on the GPU)")
    parser.add_argument("--arch", type=int, default=90, help="GPU architecture, e.g. 90 for sm_90 (H100, H200)")
    parser.add_argument("--cpu", action="store_true", help="compile for Warp's CPU device instead of --arch")
    parser.add_argument("--format", choices=("both", *FORMATS), default="both", help="what Warp loads on the GPU")
    parser.add_argument(
        "--num-envs", type=int, default=8, help="environments stepped (the kernels do not depend on it)"
    )
    parser.add_argument("--steps", type=int, default=40, help="policy steps recorded (resets happen inside them)")
    return parser


def recorded_core(args: argparse.Namespace) -> Any:
    """The environment core ``train`` would build for these options, on Warp's CPU device."""
    from margin_rl.train.commands import train as train_command

    argv = ["--env", args.env, "--physics", "warp"]
    argv += ["--recipe", args.recipe] if args.recipe else []
    for option in args.env_option or []:
        argv += ["--env-option", option]
    spec, _, _ = train_command.spec_from_args(train_command.build_parser().parse_args(argv))
    options = parse_assignments(args.physics_option, "--physics-option")
    return AnymalCore(
        spec.env_config, args.num_envs, seed=0, physics="warp", physics_device="cpu", physics_options=options
    )


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.num_envs < 1 or args.steps < 2:
        print("--num-envs must be >= 1 and --steps >= 2 (a reset happens at the second step)", file=sys.stderr)
        return 2
    actions = np.random.default_rng(0).uniform(-1, 1, size=(args.steps, args.num_envs, 12))

    def run() -> None:  # the core's construction too: it sets the model's constants (per-world masses)
        core = recorded_core(args)
        core.reset(seed=0)
        for k, action in enumerate(actions):
            if k == 1:  # end half the episodes at the next step: the masked reset and its forward pass run
                core.episode_step[: max(1, args.num_envs // 2)] = core.max_episode_steps - 1
            core.step(action)
        core.raise_pending_errors()

    try:
        variants = record_launches(run)
    except (ValueError, TypeError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    formats = FORMATS if args.format == "both" else (args.format,)
    report = compile_ahead(variants, args.cache, None if args.cpu else args.arch, formats)
    name = f"{args.env.split('/')[-1]}-{args.recipe or 'default'}"
    path = write_report(report, name)
    target = "Warp's CPU device" if args.cpu else f"sm_{args.arch} ({', '.join(formats)})"
    print(
        f"{len(report.modules)} module variants ({report.kernels} kernels) of {args.env} compiled for {target} in "
        f"{report.seconds:.0f} s into {report.cache_dir} ({report.size_mib:.1f} MiB); report: {path}"
    )
    for failed in report.failed:
        print(f"  not compiled ahead: {failed.name} (block size {failed.block_dim}): {failed.error}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
