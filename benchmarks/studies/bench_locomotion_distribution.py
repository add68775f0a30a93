"""The distribution of lambda over walking-policy rollouts, against seed 000's Table I sampler.

Usage:
    python benchmarks/studies/bench_locomotion_distribution.py --robot anymal_b --bundle anymal_b \
        [--bundle-seeds 0 1 2] [--policy runs/<run>/policy_torchscript.pt ...] [--num-envs 16] [--steps 250] \
        [--json docs/learned_margin/locomotion_distribution_anymal_b.json] [--figure ...png]

Each policy (every policy of ``--bundle``, both variants, and any ``--policy`` file) walks ``--num-envs``
environments for ``--steps`` policy steps under each condition of :data:`CONDITIONS` (the default command; the
environment's command range forward 0.25–1.0 m/s, lateral ±0.3 m/s, yaw ±0.5 rad/s; pushes; friction
randomisation 0.4–1.0; the rough id), with its ``info["lambda"]`` recorded at every step. Reported per lambda
component: the 0.5, 50 and 99.5 percentiles, the Table I range (uniform half-widths; 2 std for normals), and
the share of visited states inside it; then the contact patterns and the share of states inside every Table I
range at once. ``--json`` writes the percentiles (the input of a widened sampler), ``--figure`` histograms of
the acceleration, velocity and friction components with the Table I ranges.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import margin_rl
from margin_rl.envs.config import CommandConfig, RandomizationConfig
from margin_rl.stability import TableI, from_lambda, lambda_names
from margin_rl.stability.analytic.sampling import nominal_feet
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.artifacts.policies import load_policy

CONDITIONS: dict[str, tuple[str, dict]] = {
    "flat, 0.75 m/s": ("{robot}-v1", {}),
    "flat, command range": (
        "{robot}-v1",
        {"command": CommandConfig(forward_velocity=(0.25, 1.0), lateral_velocity=(-0.3, 0.3), yaw_rate=(-0.5, 0.5))},
    ),
    "flat, pushes": ("{robot}-v1", {"randomization": RandomizationConfig(push_interval_s=2.0)}),
    "flat, friction 0.4-1.0": ("{robot}-v1", {"randomization": RandomizationConfig(friction=(0.4, 1.0))}),
    "rough, 0.75 m/s": ("{robot}-Rough-v1", {}),
}
ENV_NAMES = {"anymal_b": "margin_rl/AnymalB", "anymal_c": "margin_rl/AnymalC"}


def table_i_ranges(robot: margin_rl.Robot, t: TableI = TableI()) -> dict[str, tuple[float, float]]:  # noqa: B008
    """Per lambda component, the Table I sampler's range (uniforms exactly; normals at 2 std; feet about nominal)."""
    names = lambda_names()
    ranges: dict[str, tuple[float, float]] = {}
    tilt = np.sin(t.roll_pitch_half_width)
    nominal = nominal_feet(robot)
    for name in names:
        field, _, axis = name.partition(".")
        leaf = name.rsplit(".", 1)[-1]
        if field == "gravity_axis":
            ranges[name] = (-tilt, tilt) if leaf in "xy" else (np.cos(np.hypot(t.roll_pitch_half_width, 0)), 1.0)
        elif field == "com_vel":
            h = t.com_vel_xy_half_width if leaf in "xy" else 2 * t.com_vel_z_std
            ranges[name] = (-h, h)
        elif field == "com_acc":
            h = t.com_acc_xy_half_width if leaf in "xy" else t.com_acc_z_half_width
            ranges[name] = (-h, h)
        elif field == "base_ang_acc":
            h = t.ang_acc_xy_half_width if leaf in "xy" else 2 * t.ang_acc_z_std
            ranges[name] = (-h, h)
        elif field == "ext_force":
            ranges[name] = (-2 * t.ext_force_std, 2 * t.ext_force_std)
        elif field == "ext_torque":
            ranges[name] = (-2 * t.ext_torque_std, 2 * t.ext_torque_std)
        elif field == "mu":
            ranges[name] = (t.mu_low, t.mu_high)
        elif field == "feet":
            leg = ("LF", "RF", "LH", "RH").index(axis.split(".")[0])
            k = "xyz".index(leaf)
            h = t.foot_x_half_width if leaf == "x" else t.foot_yz_half_width
            ranges[name] = (nominal[leg, k] - h, nominal[leg, k] + h)
        elif field == "normals":
            s = np.sin(2 * t.normal_tilt_std)
            ranges[name] = (-s, s) if leaf in "xy" else (np.cos(2 * t.normal_tilt_std) ** 2, 1.0)
        else:  # contacts
            ranges[name] = (0.0, 1.0)
    return ranges


def rollout_lambdas(env_id: str, options: dict, policy, num_envs: int, steps: int, seed: int) -> np.ndarray:
    # Same-step autoreset: every step's info holds the lambda of a simulated state (next-step mode would add
    # a masked reset step per episode end with no state).
    env = gym.make_vec(env_id, num_envs=num_envs, margin="none", autoreset_mode=AutoresetMode.SAME_STEP, **options)
    obs, _ = env.reset(seed=seed)
    lams = []
    for _ in range(steps):
        obs, _, _, _, info = env.step(policy(obs))
        lams.append(np.array(info["lambda"]))
    env.close()
    return np.concatenate(lams)


def pattern(contacts: np.ndarray) -> str:
    """Feet in contact, e.g. ``LF RF -- RH`` (``--``: a foot in the air)."""
    return " ".join(leg if c > 0.5 else "--" for leg, c in zip(("LF", "RF", "LH", "RH"), contacts, strict=True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="anymal_b", choices=sorted(ENV_NAMES))
    parser.add_argument("--bundle", default=None, help="policy bundle (both variants), e.g. anymal_b")
    parser.add_argument(
        "--bundle-seeds", type=int, nargs="+", default=None, help="only the bundle's policies of these training seeds"
    )
    parser.add_argument("--policy", action="append", default=[], help="more policy files (TorchScript, rsl, sb3)")
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--steps", type=int, default=250)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument(
        "--states",
        type=Path,
        default=None,
        help="write every visited lambda here (npz, key 'lam'; data: never committed)",
    )
    args = parser.parse_args()
    policies = []
    if args.bundle:
        runs = [r for r in load_bundle(args.bundle).runs if args.bundle_seeds is None or r.seed in args.bundle_seeds]
        policies += [(f"{r.variant} s{r.seed}", load_policy(r.policy)) for r in runs]
    policies += [(Path(p).parent.name, load_policy(p)) for p in args.policy]
    if not policies:
        parser.error("give --bundle or --policy")
    robot = margin_rl.load_robot(args.robot)
    per_condition: dict[str, np.ndarray] = {}
    for condition, (env_pattern, options) in CONDITIONS.items():
        env_id = env_pattern.format(robot=ENV_NAMES[args.robot])
        chunks = [
            rollout_lambdas(env_id, options, policy, args.num_envs, args.steps, seed=100 + i)
            for i, (_, policy) in enumerate(policies)
        ]
        per_condition[condition] = np.concatenate(chunks)
    lams = np.concatenate(list(per_condition.values()))
    names = lambda_names()
    ranges = table_i_ranges(robot)
    low, high = np.array([ranges[n][0] for n in names]), np.array([ranges[n][1] for n in names])
    inside = (lams >= low - 1e-9) & (lams <= high + 1e-9)
    p = np.percentile(lams, [0.5, 50, 99.5], axis=0)
    print(f"{args.robot}: {len(lams):,} states, {len(policies)} policies x {len(CONDITIONS)} conditions x "
          f"{args.num_envs} envs x {args.steps} steps\n")  # fmt: skip
    print("| component | p0.5 | median | p99.5 | Table I range | inside |")
    print("|---|---|---|---|---|---|")
    for k, name in enumerate(names):
        if name.startswith(("contacts", "normals")) or name.endswith(("gravity_axis.z",)):
            continue
        print(f"| {name} | {p[0, k]:+.2f} | {p[1, k]:+.2f} | {p[2, k]:+.2f} | [{low[k]:+.2f}, {high[k]:+.2f}] "
              f"| {100 * inside[:, k].mean():.0f} % |")  # fmt: skip
    continuous = [k for k, n in enumerate(names) if not n.startswith("contacts")]
    all_inside = inside[:, continuous].all(axis=1)
    print(f"\nstates inside every Table I range: {100 * all_inside.mean():.1f} %")
    for condition, chunk in per_condition.items():
        ok = ((chunk >= low - 1e-9) & (chunk <= high + 1e-9))[:, continuous].all(axis=1)
        print(f"  {condition}: {100 * ok.mean():.1f} % of {len(chunk):,}")
    patterns = Counter(pattern(c) for c in from_lambda(lams).contacts)
    print("\ncontact patterns (Table I has 4 feet, 3 feet and the two diagonal pairs only):")
    for key, count in patterns.most_common(12):
        print(f"  {key}: {100 * count / len(lams):.1f} %")
    if args.json:
        record = {
            "robot": args.robot,
            "states": len(lams),
            "policies": [name for name, _ in policies],
            "conditions": list(CONDITIONS),
            "percentiles": {"p0.5": dict(zip(names, p[0].tolist(), strict=True)),
                            "median": dict(zip(names, p[1].tolist(), strict=True)),
                            "p99.5": dict(zip(names, p[2].tolist(), strict=True))},
            "inside_table_i": float(all_inside.mean()),
            "contact_patterns": {k: v / len(lams) for k, v in patterns.most_common()},
        }  # fmt: skip
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(record, indent=1) + "\n")
        print(f"\njson: {args.json}")
    if args.states:
        args.states.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(args.states, lam=lams.astype(np.float32))
        print(f"states: {args.states}")
    if args.figure:
        plot(lams, names, low, high, args.figure, args.robot)
        print(f"figure: {args.figure}")


def plot(lams: np.ndarray, names: tuple[str, ...], low: np.ndarray, high: np.ndarray, path: Path, robot: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [n for n in names if n.split(".")[0] in ("com_vel", "com_acc", "base_ang_acc", "mu")] + [
        "feet.LF.x", "feet.LF.y", "feet.LF.z"
    ]  # fmt: skip
    fig, axes = plt.subplots(3, 5, figsize=(15, 8))
    for ax, name in zip(axes.flat, shown, strict=False):
        k = names.index(name)
        values = lams[:, k]
        lo, hi = np.percentile(values, [0.1, 99.9])
        lo, hi = min(lo, low[k]), max(hi, high[k])
        ax.hist(values, bins=60, range=(lo, hi), color="tab:blue", alpha=0.8)
        ax.axvspan(low[k], high[k], color="tab:green", alpha=0.15, label="Table I")
        ax.set_title(name, fontsize=9)
        ax.set_yticks([])
    for ax in list(axes.flat)[len(shown) :]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=8)
    fig.suptitle(f"{robot}: lambda over walking-policy rollouts (blue) vs the Table I sampler (green)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=70)
    plt.close(fig)


if __name__ == "__main__":
    main()
