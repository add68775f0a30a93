"""Which accelerations should enter lambda? Three estimators along walking episodes, and the margin each gives.

Usage:
    python benchmarks/studies/bench_acceleration_estimates.py [--bundle anymal_b] [--episodes 4] [--steps 250] \
        [--figure docs/learned_margin/acceleration_estimates_anymal_b.png]

The bundled policies (both variants, ``--episodes`` seeds each) walk at 0.75 m/s; after every 20 ms policy
step the CoM acceleration and the base angular acceleration are estimated three ways:

* ``finite_difference`` (the environment's default): (v(t) - v(t - 20 ms)) / 20 ms of the CoM velocity
  (subtree sensor) and of the world-frame base angular velocity. With the semi-implicit integrator this is
  exactly the mean of MuJoCo's own accelerations over the four 5 ms substeps, so it *is* the substep mean;
* ``instantaneous``: MuJoCo's accelerations at the state after the step (``mj_forward`` +
  ``mj_rnePostConstraint``): the CoM acceleration from Newton's law, a_c = g + (sum of external contact
  forces + applied push) / M, from ``cfrc_ext``; the base angular acceleration R_WB qacc[3:6];
* ``ema``: the environment's optional filter, a_k = 0.5 a_(k-1) + 0.5 finite_difference_k.

For each estimator it reports the RMS, the 99th percentile and the RMS of the step-to-step change (what
impacts add) of the vertical and horizontal CoM acceleration and of the base angular acceleration, the share
of steps inside the Table I sampler's ranges, and the learned margin (the bundle's weights) and the analytic
margin computed on each estimator's lambda; the figure shows one episode (estimates, touchdowns, margins).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import mujoco
import numpy as np

import margin_rl
from margin_rl.envs.anymal import AnymalEnv
from margin_rl.envs.core import MARGIN_CLIP
from margin_rl.envs.stability_input import stability_state_from_simulation
from margin_rl.robot.mjcf_names import BASE_BODY
from margin_rl.stability import LearnedMargin, TableI, analytic_margin
from margin_rl.train.artifacts.bundle import load_bundle
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import resolve_env

ESTIMATORS = ("finite_difference", "instantaneous", "ema")
GRAVITY = np.array([0.0, 0.0, -9.81])


def instantaneous_accelerations(env: AnymalEnv) -> tuple[np.ndarray, np.ndarray]:
    """World-frame CoM acceleration [m/s^2] and base angular acceleration [rad/s^2] at the current state."""
    core = env.core
    data = core.render_data(0)  # qpos, qvel of the env
    # the servo targets and push it steps with
    data.ctrl[:], data.xfrc_applied[:] = core.physics.ctrl[0], core.physics.xfrc_applied[0]
    mujoco.mj_forward(core.model, data)
    mujoco.mj_rnePostConstraint(core.model, data)
    mass = float(np.sum(core.model.body_mass))
    external = data.cfrc_ext[:, 3:].sum(axis=0) + data.xfrc_applied[:, :3].sum(axis=0)
    com_acc = GRAVITY + external / mass
    rot = data.xmat[core.model.body(BASE_BODY).id].reshape(3, 3)
    return com_acc, rot @ data.qacc[3:6]


TABLE_I = TableI()


def in_table_i(lam: np.ndarray, ranges: TableI = TABLE_I) -> bool:
    """True if lam's CoM and base accelerations lie inside the Table I sampler's ranges (normals: within 2 std)."""
    state = margin_rl.stability.from_lambda(lam)
    com, ang = np.abs(state.com_acc), np.abs(state.base_ang_acc)
    return bool(
        np.all(com[:2] <= ranges.com_acc_xy_half_width)
        and com[2] <= ranges.com_acc_z_half_width
        and np.all(ang[:2] <= ranges.ang_acc_xy_half_width)
        and ang[2] <= 2 * ranges.ang_acc_z_std
    )


def run_episode(
    env: AnymalEnv, policy, seed: int, steps: int, learned: LearnedMargin
) -> dict[str, dict[str, np.ndarray]]:
    """Per-step estimates, lambdas and margins of one deterministic episode."""
    obs, _ = env.reset(seed=seed)
    core = env.core
    robot = core.robot
    out: dict[str, dict[str, list]] = {e: {"com_acc": [], "ang_acc": [], "lam": []} for e in ESTIMATORS}
    out["contacts"] = {"contacts": []}
    ema_com, ema_ang = np.zeros(3), np.zeros(3)
    for _ in range(steps):
        obs, _, terminated, truncated, info = env.step(policy(obs[None])[0])
        if terminated or truncated:
            break
        fd_com, fd_ang = core._com_acc[0].copy(), core._ang_acc[0].copy()
        inst_com, inst_ang = instantaneous_accelerations(env)
        ema_com, ema_ang = 0.5 * ema_com + 0.5 * fd_com, 0.5 * ema_ang + 0.5 * fd_ang
        base = margin_rl.stability.from_lambda(info["lambda"])
        s = core._read()
        for name, com_acc, ang_acc in (
            ("finite_difference", fd_com, fd_ang),
            ("instantaneous", inst_com, inst_ang),
            ("ema", ema_com, ema_ang),
        ):
            state = stability_state_from_simulation(
                s.base_rot, s.com, s.com_vel, com_acc[None], ang_acc[None],
                np.zeros((1, 3)), np.zeros((1, 3)), s.feet, core.mu, s.contacts, base.normals[None],
            )  # fmt: skip
            out[name]["com_acc"].append(state.com_acc[0])
            out[name]["ang_acc"].append(state.base_ang_acc[0])
            out[name]["lam"].append(state.to_lambda()[0])
        out["contacts"]["contacts"].append(s.contacts[0].copy())
    arrays = {k: {kk: np.array(vv) for kk, vv in v.items()} for k, v in out.items()}
    for name in ESTIMATORS:
        lams = arrays[name]["lam"]
        arrays[name]["learned"] = np.clip(learned(lams), *MARGIN_CLIP)
        analytic = np.array([analytic_margin(robot, lam).margin for lam in lams])
        arrays[name]["analytic"] = analytic  # NaN where the analytic margin is undefined
        arrays[name]["in_table_i"] = np.array([in_table_i(lam) for lam in lams])
    return arrays


def summarise(episodes: list[dict[str, dict[str, np.ndarray]]]) -> None:
    print(
        "| estimator | CoM acc z RMS / p99 [m/s²] | CoM acc xy RMS | step-to-step Δ RMS (z) | ang. acc RMS / p99 "
        "[rad/s²] | inside Table I ranges | learned margin mean | analytic margin mean (defined) | learned − "
        "analytic RMSE |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ESTIMATORS:
        com = np.concatenate([e[name]["com_acc"] for e in episodes])
        ang = np.concatenate([e[name]["ang_acc"] for e in episodes])
        dz = np.concatenate([np.diff(e[name]["com_acc"][:, 2]) for e in episodes])
        learned = np.concatenate([e[name]["learned"] for e in episodes])
        analytic = np.concatenate([e[name]["analytic"] for e in episodes])
        inside = np.concatenate([e[name]["in_table_i"] for e in episodes])
        ok = np.isfinite(analytic)
        rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
        angn = np.linalg.norm(ang, axis=1)
        print(
            f"| {name} | {rms(com[:, 2]):.2f} / {np.percentile(np.abs(com[:, 2]), 99):.1f} "
            f"| {rms(np.linalg.norm(com[:, :2], axis=1)):.2f} | {rms(dz):.2f} "
            f"| {rms(angn):.1f} / {np.percentile(angn, 99):.0f} | {100 * inside.mean():.0f} % "
            f"| {learned.mean():+.3f} | {analytic[ok].mean():+.3f} ({100 * ok.mean():.0f} %) "
            f"| {rms(learned[ok] - np.clip(analytic[ok], *MARGIN_CLIP)):.3f} |"
        )
    print(f"\n{sum(len(e['contacts']['contacts']) for e in episodes)} policy steps over {len(episodes)} episodes")


def plot(episode: dict[str, dict[str, np.ndarray]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = 0.02 * np.arange(len(episode["contacts"]["contacts"]))
    fig, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True)
    colors = {"finite_difference": "tab:blue", "instantaneous": "tab:gray", "ema": "tab:red"}
    touchdowns = np.any(np.diff(episode["contacts"]["contacts"].astype(int), axis=0) > 0, axis=1)
    for ax in axes:
        for td in t[1:][touchdowns]:
            ax.axvline(td, color="0.85", lw=0.6, zorder=0)
    for name in ESTIMATORS:
        e = episode[name]
        kw = {"color": colors[name], "lw": 1.0 if name != "instantaneous" else 0.7, "label": name}
        axes[0].plot(t, e["com_acc"][:, 2], **kw)
        axes[1].plot(t, np.linalg.norm(e["ang_acc"], axis=1), **kw)
        axes[2].plot(t, e["learned"], **kw)
        axes[3].plot(t, e["analytic"], **kw)
    axes[0].set_ylabel("CoM acc z [m/s²]")
    axes[1].set_ylabel("|base ang. acc| [rad/s²]")
    axes[1].set_yscale("symlog", linthresh=10)
    axes[2].set_ylabel("learned margin [m]")
    axes[3].set_ylabel("analytic margin [m]")
    axes[3].set_xlabel("t [s] (grey lines: touchdowns)")
    axes[0].legend(fontsize=8, ncol=3)
    axes[0].set_title(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bundle", default="anymal_b")
    parser.add_argument("--episodes", type=int, default=4, help="evaluation seeds per variant")
    parser.add_argument("--steps", type=int, default=250, help="policy steps per episode (20 ms each)")
    parser.add_argument("--figure", type=Path, default=None)
    args = parser.parse_args()
    bundle = load_bundle(args.bundle)
    # The robot of the policies' training environment (a bundle's name need not be a robot's).
    robot = resolve_env(load_policy(bundle.runs[0].policy), None, {})[1].robot
    learned = LearnedMargin.load(str(bundle.margin_weights)) if bundle.margin_weights else LearnedMargin.load(robot)
    episodes, first = [], None
    for variant, (weight, runs) in bundle.variants().items():
        train_seed, policy_file = runs[0]
        policy = load_policy(policy_file)
        env = AnymalEnv(robot=robot, margin="none", command=margin_rl.envs.config.CommandConfig())
        for seed in range(args.episodes):
            episode = run_episode(env, policy, 1000 + seed, args.steps, learned)
            episodes.append(episode)
            if first is None:
                first = (episode, f"{robot}, {variant} (w = {weight}, training seed {train_seed}), episode seed 1000")
        env.close()
    summarise(episodes)
    if args.figure is not None and first is not None:
        plot(first[0], args.figure, first[1])
        print(f"figure: {args.figure}")


if __name__ == "__main__":
    main()
