"""``push_recovery``: how well policies survive pushes of increasing impulse, per variant.

Example (the shipped bundles, or any policies)::

    python -m margin_rl.train push-recovery --bundled anymal_b --out results/anymal_b
    python -m margin_rl.train push-recovery --variant "without margin" runs/b0/final_model.pt runs/b1/final_model.pt \\
        --variant "with margin" runs/m0/final_model.pt runs/m1/final_model.pt --out results/push_b

Protocol (:class:`PushProtocol`), the same for every policy (same evaluation seed, so the same push times and
signs): each policy walks at a fixed heading-velocity command; in every episode the base gets one horizontal push
of impulse J [N s] (a constant force J / T for T = ``duration_s``) along the base's heading axis
("longitudinal", forwards or backwards) or across it ("lateral", left or right), sign drawn per episode, at a time
drawn uniformly from ``push_window_s`` (so at a random phase of the gait). An episode *survives* when it does not
terminate (base or thigh contact, base too low, tilt; the training environment's terminations) within
``recovery_s`` after the push starts. Survival is the share of the episodes still walking when the push came
(episodes that fell before it are counted apart, in ``fell_before_push``); a policy's survival curve is one
value per impulse, and a variant's is the mean ± std of its policies' (training seeds') curves.

Each forward velocity gets its own curves; the plot marks a command "trained" (every policy was trained at
exactly it), "in the training range" or "untrained", from the policies' recorded training command ranges.

Outputs in ``--out``: ``push_recovery.json`` (every policy's counts and the variants' mean ± std) and
``push_recovery.png`` (survival vs impulse, one panel per direction and command, both variants).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from margin_rl.envs.core import AnymalCore
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.artifacts.policies import LoadedPolicy, load_policy
from margin_rl.train.commands.evaluate import evaluation_target
from margin_rl.train.commands.options import add_env_arguments, env_overrides
from margin_rl.train.environments import ACTION_SIZE, AnymalTarget
from margin_rl.train.metrics import mean_std
from margin_rl.train.runs import torch_threads, write_json

DIRECTIONS = ("longitudinal", "lateral")
"""Push directions in the base's heading frame: along its x axis, along its y axis."""


@dataclass(frozen=True)
class PushProtocol:
    """Pushes of increasing impulse at random gait phases (see the module docstring)."""

    impulses: tuple[float, ...] = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0)  # [N s]; 15 N s is 0.5 m/s on 30 kg
    directions: tuple[str, ...] = DIRECTIONS
    forward_velocities: tuple[float, ...] = (0.75, 0.5, 1.0)  # commands [m/s]
    episodes: int = 16  # per (direction, impulse, command) and policy
    duration_s: float = 0.1  # push duration [s]
    push_window_s: tuple[float, float] = (2.0, 4.0)  # push start, uniform [s after reset]
    recovery_s: float = 3.0  # [s] after the push start without termination to survive
    seed: int = 7000

    def __post_init__(self) -> None:
        impulses = np.asarray(self.impulses, dtype=float)
        if impulses.ndim != 1 or impulses.size == 0 or not np.all(np.isfinite(impulses)) or np.any(impulses < 0):
            raise ValueError(f"PushProtocol.impulses must be finite impulses >= 0 [N s], got {self.impulses!r}")
        unknown = [d for d in self.directions if d not in DIRECTIONS]
        if unknown or not self.directions:
            raise ValueError(f"PushProtocol.directions must be some of {DIRECTIONS}, got {self.directions!r}")
        if not self.forward_velocities or not all(np.isfinite(v) for v in self.forward_velocities):
            raise ValueError(f"PushProtocol.forward_velocities must be finite [m/s], got {self.forward_velocities!r}")
        if not (isinstance(self.episodes, int) and self.episodes >= 1):
            raise ValueError(f"PushProtocol.episodes must be an integer >= 1, got {self.episodes!r}")
        if not self.duration_s > 0 or not self.recovery_s > 0:
            raise ValueError(
                f"PushProtocol.duration_s and recovery_s must be > 0 [s], got {self.duration_s}, {self.recovery_s}"
            )
        low, high = self.push_window_s
        if not 0 <= low <= high:
            raise ValueError(f"PushProtocol.push_window_s must be 0 <= start <= end [s], got {self.push_window_s!r}")
        if self.recovery_s < self.duration_s:
            raise ValueError(
                f"PushProtocol.recovery_s ({self.recovery_s} s) must cover the push itself ({self.duration_s} s)"
            )


@dataclass(frozen=True)
class SurvivalCurve:
    """One policy's pushes in one direction at one command: counts per impulse."""

    direction: str
    forward_velocity: float
    impulses: tuple[float, ...]  # [N s]
    pushed: tuple[int, ...]  # episodes still walking when the push came
    survived: tuple[int, ...]  # of those, episodes without a termination within recovery_s
    fell_before_push: tuple[int, ...]

    @property
    def survival(self) -> tuple[float | None, ...]:
        """Share of pushed episodes that survived, per impulse (None where no episode was pushed)."""
        return tuple(s / p if p else None for s, p in zip(self.survived, self.pushed, strict=True))


@dataclass(frozen=True)
class PolicyPushes:
    """Every survival curve of one policy."""

    policy: str
    seed: int  # training seed
    curves: tuple[SurvivalCurve, ...] = field(default_factory=tuple)
    training_forward_velocity: tuple[float, float] | None = None  # the training command range [m/s], if recorded

    def curve(self, direction: str, forward_velocity: float) -> SurvivalCurve:
        for c in self.curves:
            if c.direction == direction and c.forward_velocity == forward_velocity:
                return c
        raise KeyError(f"no curve for {direction} pushes at {forward_velocity} m/s in {self.policy}")


def push_forces(direction: str, impulse: np.ndarray, signs: np.ndarray, duration_s: float) -> np.ndarray:
    """Heading-frame push forces (N, 3) [N]: ``sign * impulse / duration_s`` along x (longitudinal: forwards
    for +1) or y (lateral: to the left for +1); see :meth:`AnymalCore.push` for the heading frame."""
    forces = np.zeros((len(signs), 3))
    forces[:, DIRECTIONS.index(direction)] = signs * np.asarray(impulse, dtype=float) / duration_s
    return forces


def push_schedule(
    protocol: PushProtocol, num_envs: int, dt: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Push start steps (N,) uniform in the protocol's window, and signs (N,) of +-1."""
    low, high = (round(t / dt) for t in protocol.push_window_s)
    return rng.integers(low, high + 1, size=num_envs), rng.choice(np.array([-1.0, 1.0]), size=num_envs)


def run_pushes(policy: LoadedPolicy, target: AnymalTarget, protocol: PushProtocol, direction: str) -> SurvivalCurve:
    """All impulses of one direction at the target's command, in one batch of ``episodes * len(impulses)``
    environments (environment i gets impulse ``impulses[i // episodes]``)."""
    n_imp, n_ep = len(protocol.impulses), protocol.episodes
    core = AnymalCore(target.config, num_envs=n_imp * n_ep, seed=protocol.seed, autoreset=False, truncate=False)
    policy.check(int(core.observation_size), ACTION_SIZE, f"{target.config.robot} ({target.config.terrain})")
    impulse = np.repeat(np.asarray(protocol.impulses, dtype=float), n_ep)
    # The schedule depends on the seed only, so every policy meets the same push times and signs.
    start, signs = push_schedule(protocol, core.num_envs, core.dt, np.random.default_rng(protocol.seed))
    end = start + round(protocol.recovery_s / core.dt)
    core.reset()
    obs = core.observe_all()
    standing = np.iinfo(np.int64).max  # fell_at of an episode that has not fallen (yet)
    fell_at = np.full(core.num_envs, standing)
    for step in range(int(end.max())):
        due = np.nonzero(start == step)[0]
        if due.size:
            forces = push_forces(direction, impulse[due], signs[due], protocol.duration_s)
            core.push(due, forces, protocol.duration_s, frame="heading")
        out = core.step(policy(obs))
        obs = out.observation
        newly = out.terminated & (fell_at == standing)
        fell_at[newly] = step
        if np.all((fell_at < standing) | (step + 1 >= end)):
            break
    fell_before = fell_at < start
    survived = ~fell_before & (fell_at >= end)
    per = lambda mask: tuple(int(v) for v in mask.reshape(n_imp, n_ep).sum(axis=1))  # noqa: E731
    return SurvivalCurve(
        direction=direction,
        forward_velocity=float(target.config.command.forward_velocity[0]),
        impulses=tuple(float(j) for j in protocol.impulses),
        pushed=per(~fell_before),
        survived=per(survived),
        fell_before_push=per(fell_before),
    )


def policy_pushes(
    policy_path: str | Path, seed: int, protocol: PushProtocol, env_overrides: dict[str, Any] | None = None
) -> PolicyPushes:
    """Every direction and command of the protocol for one policy, in its training environment (with
    ``env_overrides``: EnvConfig fields)."""
    policy = load_policy(policy_path)
    curves = []
    with torch_threads(1):  # see margin_rl.train.runs.torch_threads
        for velocity in protocol.forward_velocities:
            target = evaluation_target(policy, None, env_overrides, velocity)
            for direction in protocol.directions:
                curves.append(run_pushes(policy, target, protocol, direction))
    return PolicyPushes(str(policy_path), seed, tuple(curves), training_command_range(policy))


def training_command_range(policy: LoadedPolicy) -> tuple[float, float] | None:
    """The forward-velocity command range [m/s] the policy was trained on (its run's ``config.json``), or None
    when its file does not record one."""
    command = ((policy.train_config or {}).get("env_config") or {}).get("command") or {}
    bounds = command.get("forward_velocity")
    return None if bounds is None else (float(bounds[0]), float(bounds[-1]))


def command_label(report: dict[str, Any], forward_velocity: float) -> str:
    """How a command relates to the policies' training commands: "trained" (every policy was trained at exactly
    this command), "in the training range", "untrained" (outside every policy's range), or "" when not recorded
    or mixed."""
    ranges = [
        policy.get("training_forward_velocity")
        for variant in report["variants"].values()
        for policy in variant["policies"]
    ]
    if not ranges or any(r is None for r in ranges):
        return ""
    inside = [low - 1e-9 <= forward_velocity <= high + 1e-9 for low, high in ranges]
    if all(inside):
        exact = all(abs(low - forward_velocity) < 1e-9 and abs(high - forward_velocity) < 1e-9 for low, high in ranges)
        return "trained" if exact else "in the training range"
    return "untrained" if not any(inside) else ""


def variant_survival(results: list[PolicyPushes], direction: str, forward_velocity: float) -> dict[str, list]:
    """Mean and std over policies (training seeds) of the survival per impulse; impulses no policy was pushed at
    are None."""
    curves = [r.curve(direction, forward_velocity).survival for r in results]
    columns = list(zip(*curves, strict=True))
    stats = [mean_std([v for v in column if v is not None]) for column in columns]
    return {"mean": [m for m, _ in stats], "std": [s for _, s in stats], "n_policies": len(results)}


def push_recovery_report(
    variants: dict[str, list[PolicyPushes]], protocol: PushProtocol, env_options: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The JSON report: protocol, per-policy counts and per-variant mean ± std survival."""
    report: dict[str, Any] = {"protocol": asdict(protocol), "env_overrides": dict(env_options or {}), "variants": {}}
    for name, results in variants.items():
        report["variants"][name] = {
            "policies": [
                {
                    "policy": r.policy,
                    "seed": r.seed,
                    "curves": [{**asdict(c), "survival": list(c.survival)} for c in r.curves],
                    "training_forward_velocity": r.training_forward_velocity,
                }
                for r in results
            ],
            "survival": {
                f"{direction}@{v:g}": variant_survival(results, direction, v)
                for v in protocol.forward_velocities
                for direction in protocol.directions
            },
        }
    return report


def plot_push_survival(report: dict[str, Any], path: str | Path, title: str = "") -> Path:
    """Survival vs impulse, mean ± std over seeds per variant: one row per command, one column per direction."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from margin_rl.train.analysis.media import COLORS

    protocol = report["protocol"]
    velocities, directions = protocol["forward_velocities"], protocol["directions"]
    impulses = np.asarray(protocol["impulses"], dtype=float)
    fig, axes = plt.subplots(
        len(velocities), len(directions), figsize=(4.2 * len(directions), 2.8 * len(velocities)), squeeze=False
    )
    for row, v in enumerate(velocities):
        for col, direction in enumerate(directions):
            ax = axes[row, col]
            for name, variant in report["variants"].items():
                s = variant["survival"][f"{direction}@{v:g}"]
                mean = np.array([np.nan if m is None else m for m in s["mean"]], dtype=float)
                std = np.array([np.nan if x is None else x for x in s["std"]], dtype=float)
                label = f"{name} ({s['n_policies']} seeds)"
                ax.plot(impulses, mean, "o-", color=COLORS.get(name), label=label, ms=3)
                ax.fill_between(impulses, mean - std, mean + std, color=COLORS.get(name), alpha=0.2)
            relation = command_label(report, v)
            ax.set_title(f"{direction} push, {v:g} m/s" + (f" ({relation})" if relation else ""), fontsize=9)
            ax.set_ylim(-0.05, 1.05)
            ax.grid(alpha=0.3)
            if row == len(velocities) - 1:
                ax.set_xlabel("impulse [N s]")
            if col == 0:
                ax.set_ylabel("survival")
    axes[0, 0].legend(fontsize=7, loc="lower left")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def survival_table(report: dict[str, Any]) -> list[str]:
    """Markdown: survival mean ± std per variant, one row per (direction, command) and variant."""
    impulses = report["protocol"]["impulses"]
    lines = [
        "| push | variant | " + " | ".join(f"{j:g} N s" for j in impulses) + " |",
        "|---|---|" + "---|" * len(impulses),
    ]
    for key in next(iter(report["variants"].values()))["survival"]:
        direction, v = key.split("@")
        for name, variant in report["variants"].items():
            s = variant["survival"][key]
            cells = ["–" if m is None else f"{m:.2f} ± {x:.2f}" for m, x in zip(s["mean"], s["std"], strict=True)]
            lines.append(f"| {direction}, {v} m/s | {name} | " + " | ".join(cells) + " |")
    return lines


def run_push_recovery(
    variants: dict[str, list[tuple[int, Path]]],
    protocol: PushProtocol,
    out: str | Path,
    env_options: dict[str, Any] | None = None,
    title: str = "",
) -> dict[str, Any]:
    """Push every policy of every variant; writes ``push_recovery.json``/``.png``/``.md`` into ``out``."""
    out = Path(out)
    results = {
        name: [policy_pushes(path, seed, protocol, env_options) for seed, path in policies]
        for name, policies in variants.items()
    }
    report = push_recovery_report(results, protocol, env_options)
    report["plot"] = plot_push_survival(report, out / "push_recovery.png", title).name
    (out / "push_recovery.md").write_text("\n".join(survival_table(report)) + "\n")
    write_json(out / "push_recovery.json", report)
    return report


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="margin-rl-push-recovery", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_env_arguments(parser)
    d = PushProtocol()
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--bundled", metavar="NAME", help="a policy bundle (shipped name, e.g. anymal_b, or folder)")
    source.add_argument(
        "--variant",
        nargs="+",
        action="append",
        metavar=("NAME", "POLICY"),
        help="a variant's name and its policies, one per training seed (repeatable)",
    )
    parser.add_argument("--impulses", type=float, nargs="+", default=list(d.impulses), help="[N s]")
    parser.add_argument("--directions", nargs="+", choices=DIRECTIONS, default=list(d.directions))
    parser.add_argument(
        "--forward-velocities", type=float, nargs="+", default=list(d.forward_velocities), help="commands [m/s]"
    )
    parser.add_argument("--episodes", type=int, default=d.episodes, help="per impulse, direction and command")
    parser.add_argument("--duration-s", type=float, default=d.duration_s)
    parser.add_argument("--recovery-s", type=float, default=d.recovery_s)
    parser.add_argument("--seed", type=int, default=d.seed)
    parser.add_argument("--out", type=Path, required=True)
    return parser


def _variants_from_args(args: argparse.Namespace) -> tuple[dict[str, list[tuple[int, Path]]], dict[str, Any]]:
    """The variants' policies, and the EnvConfig overrides they are evaluated with (a bundle's margin weights)."""
    if args.bundled is not None:
        bundle = load_bundle(args.bundled)  # verifies every checksum once
        return {name: list(runs) for name, (_, runs) in bundle.variants().items()}, bundle.env_overrides()
    variants: dict[str, list[tuple[int, Path]]] = {}
    for entry in args.variant:
        if len(entry) < 2:
            raise ValueError(f"--variant needs a name and at least one policy, got {entry}")
        name, *paths = entry
        missing = [p for p in paths if not Path(p).is_file()]
        if missing:
            raise ValueError(f"--variant {name!r}: no such policy file {missing[0]}")
        variants[name] = [(i, Path(p)) for i, p in enumerate(paths)]
    return variants, {}


def main(argv: list[str] | None = None) -> int:
    """Console entry point."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        protocol = PushProtocol(
            impulses=tuple(args.impulses),
            directions=tuple(args.directions),
            forward_velocities=tuple(args.forward_velocities),
            episodes=args.episodes,
            duration_s=args.duration_s,
            recovery_s=args.recovery_s,
            seed=args.seed,
        )
        variants, bundle_options = _variants_from_args(args)
        options = {**bundle_options, **env_overrides(args)}
        report = run_push_recovery(variants, protocol, args.out, options)
    except (ValueError, TypeError) as exc:
        parser.error(str(exc))
    print("\n".join(survival_table(report)))
    print(f"wrote {args.out / 'push_recovery.json'}, {args.out / 'push_recovery.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
