"""Fingerprints of the package's numerical behaviour, to show that a refactor changes nothing.

Each entry is the sha256 of the exact bytes of a computation's outputs (float64 arrays as computed, no
rounding), so two fingerprint files agree only if every number is bit-identical:

* analytic margins (status, margin, region vertices, capture point) of Table I states, B and C;
* the FWP feasibility factor of Table I states;
* learned margins and their gradients (numpy) of Table I states, B and C;
* environment rollouts (observations, rewards, terminations, every info entry) of the batched env for B
  and C: flat and rough ground, pushes, friction randomisation, filtered accelerations, a privileged critic,
  the shaped reward, and a few steps with the analytic and FWP margin terms;
* the single (non-vector) environment;
* the bundled ANYmal B policies evaluated by ``compare --bundled`` (the ``make demo`` table);
* a labelled dataset shard (``dataset generate``) and a short rsl-rl and SB3 training run's final weights.

Usage (run it on both trees with the same interpreter; the two JSON files must be equal)::

    python benchmarks/tools/fingerprint.py --out /tmp/before.json        # on the old tree
    python benchmarks/tools/fingerprint.py --out /tmp/after.json         # on the new tree
    python benchmarks/tools/fingerprint.py --compare /tmp/before.json /tmp/after.json

Bit-identity holds on one machine and one set of library versions: BLAS kernels and MuJoCo's SIMD paths
may round differently on another CPU, so the files are compared, never committed as a test oracle.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def digest(*arrays: Any) -> str:
    """sha256 over the raw bytes (and shapes, dtypes) of ``arrays``."""
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a))
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def stability_fingerprints(n: int) -> dict[str, str]:
    import margin_rl
    from margin_rl.stability import LearnedMargin, analytic_margin, fwp_feasibility, sample_states

    out = {}
    for name in ("anymal_b", "anymal_c"):
        robot = margin_rl.load_robot(name)
        lams = sample_states(robot, n, seed=7)
        parts = []
        for lam in lams:
            r = analytic_margin(robot, lam)
            vertices = r.region.vertices if r.region is not None else np.zeros((0, 2))
            parts += [np.frombuffer(r.status.encode(), np.uint8), np.float64(r.margin), vertices]
            parts.append(np.zeros(2) if r.capture_point is None else r.capture_point)
        out[f"analytic/{name}"] = digest(*parts)
        fwp = [fwp_feasibility(robot, lam).s for lam in lams[: n // 4]]
        out[f"fwp/{name}"] = digest(np.array(fwp))
        model = LearnedMargin.load(name)
        values, grads = model.value_and_grad(lams)
        out[f"learned/{name}"] = digest(model(lams), values, grads, model(lams[0]))
    return out


NEW_INFO_KEY = re.compile(r"^_?(termination_|(edge_)?touchdowns$|joint_torque_sq$|torque_at_limit$)")
"""Info keys added after the first fingerprints (the ANYmal ids' v1 termination causes, the feet landing and those on
step edges, the joint torques' mean square and the flag of a joint at its torque limit): left out of the env digests,
so that every number the earlier files hold is still compared."""


NEW_METRIC = re.compile(
    r"^(termination/|edge_landing_fraction$|torque_rms$|torque_limit_fraction$|margin_reward_share$)"
)
"""Episode metrics added after the first fingerprints (the v1 termination causes, the share of landings on step
edges, the joint torques' RMS, the share of steps at a torque limit, the margin term's share of the reward), left
out of the demo's digest; the grid's termination causes were there from its first fingerprint, and leaving them out
of both files compares the same numbers."""


def _digested(info: dict[str, Any]) -> list[str]:
    return sorted(key for key in info if not NEW_INFO_KEY.match(key))


def _rollout(env, steps: int, rng: np.random.Generator) -> str:
    obs, _ = env.reset(seed=3)
    parts = [obs]
    for _ in range(steps):
        action = rng.uniform(-1.2, 1.2, size=env.action_space.shape)
        obs, reward, terminated, truncated, info = env.step(action)
        parts += [obs, np.asarray(reward), np.asarray(terminated), np.asarray(truncated)]
        for key in _digested(info):
            value = info[key]
            if isinstance(value, np.ndarray) and value.dtype == object:
                value = np.stack([v for v in value if v is not None]) if any(v is not None for v in value) else []
            if isinstance(value, dict):
                parts += [np.asarray(value[k]) for k in _digested(value)]
            else:
                parts.append(np.asarray(value))
    return digest(*parts)


def env_fingerprints(steps: int) -> dict[str, str]:
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    import margin_rl  # noqa: F401 - registers the ids
    from margin_rl.envs.config import CommandConfig, RandomizationConfig

    cases: dict[str, tuple[str, dict[str, Any], int]] = {
        "b_flat": ("margin_rl/AnymalB-v1", {}, steps),
        "c_flat_shaped": (
            "margin_rl/AnymalC-v1",
            {"reward_preset": "shaped", "reward_params": {"alive_bonus": 0.1}},
            steps,
        ),
        "b_rough_random": (
            "margin_rl/AnymalB-Rough-v1",
            {
                "randomization": RandomizationConfig(
                    friction=(0.4, 1.0), push_interval_s=0.3, observation_noise=1.0, added_base_mass=(-1.0, 2.0)
                ),
                "command": CommandConfig(forward_velocity=(0.2, 1.0), lateral_velocity=(-0.3, 0.3)),
                "acceleration_filter": 0.5,
                "privileged_observations": True,
                "seed": 5,  # the added base masses are drawn at construction
            },
            steps,
        ),
        "c_rough": ("margin_rl/AnymalC-Rough-v1", {"margin_weight": 0.2}, steps),
        "b_analytic": ("margin_rl/AnymalB-v1", {"margin": "analytic"}, 8),
        "c_fwp": ("margin_rl/AnymalC-v1", {"margin": "fwp"}, 4),
        "b_none": ("margin_rl/AnymalB-v1", {"margin": "none"}, 50),
    }
    out = {}
    for name, (env_id, kwargs, n_steps) in cases.items():
        # same-step autoreset: the mode these rollouts were first recorded with (the -v1 default is next-step)
        env = gym.make_vec(env_id, num_envs=8, autoreset_mode=AutoresetMode.SAME_STEP, **kwargs)
        out[f"env/{name}"] = _rollout(env, n_steps, np.random.default_rng(11))
        if kwargs.get("privileged_observations"):
            out[f"env/{name}/privileged"] = digest(env.unwrapped.core.privileged_observation())
        env.close()
    single = gym.make("margin_rl/AnymalC-v1")
    out["env/single_c"] = _rollout(single, steps, np.random.default_rng(12))
    single.close()
    return out


def _run(args: list[str], cwd: Path) -> None:
    subprocess.run([sys.executable, *args], cwd=cwd, check=True, stdout=subprocess.DEVNULL)


def cli_fingerprints(work: Path) -> dict[str, str]:
    out = {}
    _run(["-m", "margin_rl.train", "compare", "--bundled", "anymal_b", "--out", str(work / "demo")], work)
    report = json.loads((work / "demo" / "compare.json").read_text())
    for key in ("provenance", "wall_time_s", "command"):
        report.pop(key, None)
    # the bundle's file paths depend on where the package is installed, not on what it computes
    cells = [report, *report.get("grid", [])]
    for cell in cells:  # metrics added after the first fingerprints, left out: see NEW_METRIC
        for variant in cell.get("variants", {}).values():
            for run in variant.get("runs", []):
                run["metrics"] = {k: v for k, v in run["metrics"].items() if not NEW_METRIC.match(k)}
    # each run's evaluation folder (``eval_dir``) lies under this call's temporary folder, named by a digest of the
    # evaluation's overrides, which hold the bundle's network path: where, not what
    text = json.dumps(report, sort_keys=True).replace(str(work), "<work>")
    text = re.sub(r"/(eval(?:_grid)?)_[0-9a-f]{8}/", r"/\1_<digest>/", text)
    text = re.sub(r'"[^"]*/bundled/', '"<bundle>/', text)
    out["demo/compare.json"] = hashlib.sha256(text.encode()).hexdigest()
    out["demo/compare.md"] = file_digest(work / "demo" / "compare.md")
    from margin_rl.robot import load_robot  # noqa: F401 - fail early if the package is broken

    data = work / "data"
    module = "margin_rl.stability.learned.dataset"
    try:
        __import__(module)
    except ImportError:
        module = "margin_rl.dataset"
    _run(["-m", module, "generate", "--robot", "anymal_b", "--n", "400", "--shard-size", "200", "--workers", "1",
          "--out", str(data), "--quiet"], work)  # fmt: skip
    shards = sorted(p for p in data.iterdir() if p.suffix == ".npz")
    for shard in shards:
        with np.load(shard) as z:
            # "seconds" is each label's wall time: the only entry that may differ between identical runs
            out[f"dataset/{shard.name}"] = digest(*(z[k] for k in sorted(z.files) if k != "seconds"))
    for backend, extra in (("rsl", []), ("sb3", ["--ppo-option", "n_steps=64"])):
        run_dir = work / f"train_{backend}"
        _run(["-m", "margin_rl.train", "train", "--env", "margin_rl/AnymalB-v1", "--backend", backend, "--seed", "1",
              "--num-envs", "8", "--total-steps", "1024", "--margin-weight", "0.2",
              "--env-option", "reward_params.alive_bonus=0",
              "--run-dir", str(run_dir), "--no-progress", *extra], work)  # fmt: skip
        import torch

        policy = torch.jit.load(str(run_dir / "policy_torchscript.pt"))
        out[f"train/{backend}/policy"] = digest(*(p.detach().numpy() for p in policy.parameters()))
        obs = torch.linspace(-1, 1, 48)[None]
        out[f"train/{backend}/action"] = digest(policy(obs).detach().numpy())
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="write the fingerprints here (JSON)")
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("BEFORE", "AFTER"))
    parser.add_argument("--states", type=int, default=120, help="Table I states per robot")
    parser.add_argument("--steps", type=int, default=150, help="environment steps per rollout")
    parser.add_argument("--skip-cli", action="store_true", help="skip the CLI runs (demo, dataset, training)")
    args = parser.parse_args(argv)
    if args.compare:
        before, after = (json.loads(p.read_text()) for p in args.compare)
        differ = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
        for key in differ:
            print(f"DIFFERS {key}: {before.get(key)} vs {after.get(key)}")
        same = sum(before[k] == after[k] for k in before.keys() & after.keys())
        print(f"{same} identical, {len(differ)} differ or missing")
        return 1 if differ else 0
    if args.out is None:
        parser.error("give --out FILE or --compare BEFORE AFTER")
    prints = {**stability_fingerprints(args.states), **env_fingerprints(args.steps)}
    if not args.skip_cli:
        with tempfile.TemporaryDirectory() as tmp:
            prints.update(cli_fingerprints(Path(tmp)))
    args.out.write_text(json.dumps(prints, indent=1, sort_keys=True) + "\n")
    print(f"{len(prints)} fingerprints -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
