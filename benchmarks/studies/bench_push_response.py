"""Study: how policies with and without the margin term respond to a lateral push, step by step.

The push-recovery benchmark counts who survives; this study measures what the margin does not see, to explain why
the margin policies of ANYmal C survive lateral pushes less often (BENCHMARKS, "Push recovery"):

(a) the stepping response: the time from the push to the first *recovery step* (a foot that lifts off and lands
    at least ``--step-threshold`` further along the push, in the heading frame at the push), the lateral length of
    the steps within ``--window-s`` after the push, and where each foot lands relative to the instantaneous
    capture point (ICP), ``sign * (y_foot - y_icp)`` in the heading frame H at touchdown (> 0: beyond the ICP in
    the push direction, where a step must land to capture the motion);
(b) whether the margin term penalises recovery steps: the margin through the push, and its change at the policy
    step a foot lifts off after the push (lifting a foot shrinks the support region);
(c) the stance width and the base height through the push.

Usage::

    python benchmarks/studies/bench_push_response.py --bundled anymal_c [--impulse 45] [--forward-velocity 0.75]
        [--episodes 32] [--out docs/comparison/push_response]
    # the bundle's baselines against margin policies trained since (finished runs), both measured with the
    # package's default learned margin (or --margin-weights):
    python benchmarks/studies/bench_push_response.py --bundled anymal_c \
        --margin-runs runs/release/anymal_c/with_margin_s*

Protocol: the push-recovery protocol (``margin_rl.train.commands.push_recovery``): the same seed, push times in
2-4 s after the reset and signs for every policy, a constant force ``impulse / 0.1 s`` across the heading, the
training environment with a fixed command. Each policy's value of a metric is its mean over its pushed episodes;
the variants are compared over training seeds (mean ± std, Welch test and bootstrap interval,
:mod:`margin_rl.train.analysis.significance`). Writes ``push_response.json`` and ``push_response.md``.

ICP: the CoM-relative capture point of the linear inverted pendulum, ``v_H / omega`` with
``omega = sqrt(g / h)`` and ``h`` the CoM height above the mean of the feet (lambda's own CoM velocity and feet, in
H, the frame the margin is computed in).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

import numpy as np

from margin_rl.envs.core import AnymalCore
from margin_rl.envs.stability_input import heading_rotation
from margin_rl.robot import mjcf_names as names
from margin_rl.robot import quat_wxyz_to_matrix
from margin_rl.stability import from_lambda
from margin_rl.train.analysis.significance import compare_seeds
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import evaluation_target
from margin_rl.train.commands.push_recovery import PushProtocol, push_forces, push_schedule
from margin_rl.train.environments import ACTION_SIZE
from margin_rl.train.runs import CONFIG_FILE, TORCHSCRIPT_FILE, read_json, torch_threads, write_json

GRAVITY = 9.81  # [m/s^2]
BEFORE_S = 0.5  # trace window before the push [s]

METRICS: dict[str, str] = {
    "survived": "survived the push (fraction of pushed episodes)",
    "first_recovery_step_s": "time from the push to the first recovery step [s]",
    "recovery_steps": "recovery steps within the window (count)",
    "lateral_step_m": "mean lateral length of the steps landed in the window, along the push [m]",
    "landing_beyond_icp_m": "mean landing point beyond the ICP, along the push, of the steps in the window [m]",
    "margin_before_m": "mean margin in the 0.5 s before the push [m]",
    "margin_after_m": "mean margin in the window after the push [m]",
    "margin_min_after_m": "minimum margin in the window after the push [m]",
    "margin_change_at_liftoff_m": "margin change at the policy step a foot lifts off after the push [m]",
    "stance_width_before_m": "stance width in the 0.5 s before the push [m]",
    "stance_width_after_m": "stance width in the window after the push [m]",
    "base_height_min_after_m": "lowest base height in the window after the push [m]",
}
"""Per-episode metrics (a policy's value: the mean over its pushed episodes; NaN where an episode had none)."""


def record(policy_path: Path, overrides: dict[str, Any], protocol: PushProtocol, impulse: float) -> dict[str, Any]:
    """Step one policy through ``protocol.episodes`` lateral pushes of ``impulse`` [N s] at the first command of the
    protocol; the per-step record of every environment (N leading, steps second)."""
    policy = load_policy(policy_path)
    target = evaluation_target(policy, None, overrides, protocol.forward_velocities[0])
    core = AnymalCore(target.config, num_envs=protocol.episodes, seed=protocol.seed, autoreset=False, truncate=False)
    policy.check(int(core.observation_size), ACTION_SIZE, target.config.robot)
    start, signs = push_schedule(protocol, core.num_envs, core.dt, np.random.default_rng(protocol.seed))
    window = round(protocol.recovery_s / core.dt)
    feet = np.array([core.physics.site_id(name) for name in core.robot.foot_names])
    core.reset()
    obs = core.observe_all()
    traces: dict[str, list[np.ndarray]] = {key: [] for key in ("contacts", "feet", "margin", "stance", "height", "lam")}
    terminated = np.zeros((core.num_envs, int(start.max()) + window), dtype=bool)
    heading = np.zeros((core.num_envs, 3, 3))
    for step in range(terminated.shape[1]):
        due = np.nonzero(start == step)[0]
        if due.size:
            rotation = quat_wxyz_to_matrix(core.physics.qpos[due][:, names.BASE_QUATERNION_QPOS])
            heading[due] = heading_rotation(rotation)
            forces = push_forces("lateral", np.full(due.size, impulse), signs[due], protocol.duration_s)
            core.push(due, forces, protocol.duration_s, frame="heading")
        out = core.step(policy(obs))
        obs = out.observation
        terminated[:, step] = out.terminated
        traces["contacts"].append(out.info["contacts"] > 0.5)
        traces["feet"].append(core.physics.site_xpos[:, feet].copy())
        traces["margin"].append(out.info["margin"])
        traces["stance"].append(out.info["stance_width"])
        traces["height"].append(out.info["base_height"])
        traces["lam"].append(out.info["lambda"])
    stacked = {key: np.stack(values, axis=1) for key, values in traces.items()}
    return {**stacked, "terminated": terminated, "start": start, "signs": signs, "heading": heading, "dt": core.dt}


def episode_metrics(rec: dict[str, Any], env: int, window_s: float, step_threshold: float) -> dict[str, float]:
    """The metrics of one pushed episode (see :data:`METRICS`); NaN for what the episode does not have."""
    dt, s0, sign = rec["dt"], int(rec["start"][env]), float(rec["signs"][env])
    horizon = rec["terminated"].shape[1]
    fell = np.nonzero(rec["terminated"][env])[0]
    end_recovery = min(horizon, s0 + round(3.0 / dt))
    survived = not np.any((fell >= s0) & (fell < end_recovery))
    w_end = min(horizon, s0 + round(window_s / dt), int(fell[0]) if fell.size else horizon)
    before = slice(max(0, s0 - round(BEFORE_S / dt)), s0)
    after = slice(s0, max(s0 + 1, w_end))
    contacts, feet_w = rec["contacts"][env], rec["feet"][env]  # (T, 4), (T, 4, 3)
    R_wh = rec["heading"][env]  # H at the push: x forwards, y to the left
    state = from_lambda(rec["lam"][env])  # the margin's own frame H (per step) for the ICP
    steps_lateral, landings, recovery_times, liftoff_changes = [], [], [], []
    for leg in range(4):
        c = contacts[:, leg]
        for t in range(max(s0, 1), w_end):
            if c[t - 1] and not c[t]:  # lift-off at policy step t
                liftoff_changes.append(rec["margin"][env, t] - rec["margin"][env, t - 1])
            if c[t] and not c[t - 1]:  # touchdown at t: the step from the last lift-off
                lifted = np.nonzero(c[:t])[0]
                if lifted.size == 0:
                    continue
                t_off = int(lifted[-1]) + 1
                displacement = R_wh.T @ (feet_w[t, leg] - feet_w[t_off - 1, leg])
                lateral = sign * displacement[1]
                steps_lateral.append(lateral)
                com_height = -float(np.mean(state.feet[t, :, 2]))
                omega = math.sqrt(GRAVITY / max(com_height, 1e-3))
                icp_y = state.com_vel[t, 1] / omega
                landings.append(sign * (state.feet[t, leg, 1] - icp_y))
                if lateral >= step_threshold:
                    recovery_times.append((t - s0) * dt)
    margin, stance, height = rec["margin"][env], rec["stance"][env], rec["height"][env]
    return {
        "survived": float(survived),
        "first_recovery_step_s": min(recovery_times) if recovery_times else math.nan,
        "recovery_steps": float(len(recovery_times)),
        "lateral_step_m": float(np.mean(steps_lateral)) if steps_lateral else math.nan,
        "landing_beyond_icp_m": float(np.mean(landings)) if landings else math.nan,
        "margin_before_m": float(np.mean(margin[before])),
        "margin_after_m": float(np.mean(margin[after])),
        "margin_min_after_m": float(np.min(margin[after])),
        "margin_change_at_liftoff_m": float(np.mean(liftoff_changes)) if liftoff_changes else math.nan,
        "stance_width_before_m": float(np.mean(stance[before])),
        "stance_width_after_m": float(np.mean(stance[after])),
        "base_height_min_after_m": float(np.min(height[after])),
    }


def aligned_trace(rec: dict[str, Any], key: str, window_s: float) -> np.ndarray:
    """``key`` of every pushed episode from 0.5 s before to ``window_s`` after its push (NaN after a fall)."""
    dt = rec["dt"]
    lo, hi = round(BEFORE_S / dt), round(window_s / dt)
    values = np.full((len(rec["start"]), lo + hi), np.nan)
    for env, s0 in enumerate(rec["start"]):
        fell = np.nonzero(rec["terminated"][env])[0]
        stop = min(rec["terminated"].shape[1], s0 + hi, int(fell[0]) + 1 if fell.size else s0 + hi)
        values[env, : stop - (s0 - lo)] = rec[key][env, s0 - lo : stop]
    return values


def survival_correlations(report: dict[str, Any]) -> dict[str, dict[str, float]]:
    """Pearson's r (and its two-sided p) between each metric and survival over every policy of both variants: which
    part of the response goes with surviving, whatever the variant."""
    from scipy import stats

    policies = [p for variant in report["variants"].values() for p in variant["policies"]]
    survival = np.array([p["survived"] for p in policies])
    result = {}
    for metric in METRICS:
        values = np.array([p[metric] for p in policies], dtype=float)
        finite = np.isfinite(values) & np.isfinite(survival)
        if metric == "survived" or finite.sum() < 3 or np.ptp(values[finite]) == 0:
            continue
        r, p_value = stats.pearsonr(values[finite], survival[finite])
        result[metric] = {"r": float(r), "p": float(p_value), "n": int(finite.sum())}
    return result


def margin_runs(run_dirs: list[Path]) -> tuple[float, list[tuple[int, Path]]]:
    """(margin weight, [(seed, TorchScript actor)]) of finished training runs of one margin weight."""
    weights, runs = set(), []
    for run in run_dirs:
        config, actor = run / CONFIG_FILE, run / TORCHSCRIPT_FILE
        if not (config.is_file() and actor.is_file()):
            raise SystemExit(f"--margin-runs {run}: not a finished run (no {CONFIG_FILE} or {TORCHSCRIPT_FILE})")
        recorded = read_json(config)
        weights.add(float(recorded["env_config"]["margin_weight"]))
        runs.append((int(recorded["seed"]), actor))
    if len(weights) != 1 or 0.0 in weights:
        raise SystemExit(f"--margin-runs: the runs must share one margin weight > 0, got {sorted(weights)}")
    return weights.pop(), sorted(runs)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bundled", default="anymal_c", help="a policy bundle (shipped name or folder)")
    parser.add_argument("--impulse", type=float, default=45.0, help="lateral push impulse [N s]")
    parser.add_argument("--forward-velocity", type=float, default=0.75, help="command [m/s]")
    parser.add_argument("--episodes", type=int, default=32, help="pushed episodes per policy")
    parser.add_argument("--window-s", type=float, default=1.0, help="the recovery window after the push [s]")
    parser.add_argument("--step-threshold", type=float, default=0.05, help="a recovery step's lateral length [m]")
    parser.add_argument("--out", type=Path, default=Path("push_response"))
    parser.add_argument(
        "--margin-runs",
        type=Path,
        nargs="+",
        default=None,
        help="finished training runs that replace the bundle's margin variant (their TorchScript actors)",
    )
    parser.add_argument(
        "--margin-weights", default=None, help="with --margin-runs: the learned margin both variants are measured with"
    )
    args = parser.parse_args(argv)
    bundle = load_bundle(args.bundled)
    variants = bundle.variants()
    env_overrides = bundle.env_overrides()
    if args.margin_runs:
        variants = {**variants, "with margin": margin_runs(args.margin_runs)}
        # One network measures both variants: the baselines' reward never used theirs (weight 0).
        env_overrides = {} if args.margin_weights is None else {"margin_weights": args.margin_weights}
    protocol = replace(
        PushProtocol(), impulses=(args.impulse,), directions=("lateral",),
        forward_velocities=(args.forward_velocity,), episodes=args.episodes,
    )  # fmt: skip
    report: dict[str, Any] = {
        "bundle": bundle.name,
        "margin_runs": [str(run) for run in args.margin_runs or []],
        "env_overrides": env_overrides,
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "protocol": {
            **vars(args),
            "out": str(args.out),
            "margin_runs": [str(r) for r in args.margin_runs or []],
            "push_seed": protocol.seed,
        },
        "metrics": METRICS,
        "variants": {},
    }
    traces: dict[str, dict[str, list[float]]] = {}
    with torch_threads(1):
        for variant, (weight, runs) in variants.items():
            policies, curves = [], {key: [] for key in ("margin", "stance", "height")}
            for seed, path in runs:
                rec = record(path, env_overrides, protocol, args.impulse)
                episodes = [
                    episode_metrics(rec, env, args.window_s, args.step_threshold)
                    for env in range(len(rec["start"]))
                    if not rec["terminated"][env, : rec["start"][env]].any()  # still walking when pushed
                ]
                means = {k: float(np.nanmean([e[k] for e in episodes])) if episodes else math.nan for k in METRICS}
                policies.append({"seed": seed, "pushed": len(episodes), **means})
                for key in curves:
                    curves[key].append(np.nanmean(aligned_trace(rec, key, args.window_s), axis=0))
                print(f"{variant} seed {seed}: " + ", ".join(f"{k} {v:.3f}" for k, v in means.items()), flush=True)
            report["variants"][variant] = {"margin_weight": weight, "policies": policies}
            traces[variant] = {key: np.mean(np.stack(v), axis=0).tolist() for key, v in curves.items()}
    (baseline, base), (other, variant) = list(report["variants"].items())[:2]
    report["statistics"] = {
        metric: asdict(compare_seeds(
            metric, [p[metric] for p in base["policies"]], [p[metric] for p in variant["policies"]],
            names=(baseline, other),
        ))
        for metric in METRICS
    }  # fmt: skip
    report["correlation_with_survival"] = survival_correlations(report)
    report["traces"] = {"dt": 0.02, "before_s": BEFORE_S, "variants": traces}
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "push_response.json", report)
    lines = [
        f"# Lateral push response: {bundle.name}, {args.impulse:g} N s at {args.forward_velocity:g} m/s",
        "",
        f"{args.episodes} episodes per policy; mean ± std over training seeds; Welch p over seeds.",
        "",
        f"| metric | {baseline} | {other} | difference | p |",
        "|---|---|---|---|---|",
    ]
    for metric, label in METRICS.items():
        a = np.array([p[metric] for p in base["policies"]], dtype=float)
        b = np.array([p[metric] for p in variant["policies"]], dtype=float)
        s = report["statistics"][metric]
        p = "–" if s["p_value"] is None else f"{s['p_value']:.3f}"
        diff = "–" if s["difference"] is None else f"{s['difference']:+.3f}"
        lines.append(
            f"| {label} | {np.nanmean(a):.3f} ± {np.nanstd(a):.3f} | {np.nanmean(b):.3f} ± {np.nanstd(b):.3f} "
            f"| {diff} | {p} |"
        )
    lines += ["", "Pearson's r with survival over every policy of both variants (p):", ""]
    lines += [
        f"- {METRICS[m]}: r = {c['r']:+.2f} (p = {c['p']:.3f})" for m, c in report["correlation_with_survival"].items()
    ]
    (args.out / "push_response.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
