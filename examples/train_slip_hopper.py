"""Train the SLIP hopper (``margin_rl/SLIPHopper-v0``) with plain Stable-Baselines3 PPO.

``margin_rl.train`` trains the batched ANYmal ids only; every other Gymnasium environment of the package is
an ordinary ``gymnasium.make`` environment that plain SB3 trains as it is. This script shows it for the
SLIP hopper of seed 001 (one apex-to-apex hop per step, an optional learned failure-margin reward term weighted
by the environment's ``margin_weight`` keyword): PPO over ``--num-envs`` hoppers, checkpoints every
``--checkpoint-every`` steps, then deterministic evaluation episodes and their mean return.

Run from the repository root (the defaults are the settings of ``docs/slip.md``; 100k hops take 10 to 20
minutes on a CPU, at 100 to 180 hops/s)::

    python examples/train_slip_hopper.py --total-steps 100000 --seed 0 --margin-weight 1 --out runs/slip_mw1
    python examples/train_slip_hopper.py --total-steps 100000 --seed 0 --margin-weight 0 --out runs/slip_mw0

Outputs in ``--out``: ``checkpoints/ckpt_<steps>.zip`` and ``final_model.zip`` (SB3 models, each written to a
temporary name and moved into place with ``os.replace``, so a killed run never leaves a truncated file); load
one with ``stable_baselines3.PPO.load``.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import gymnasium
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env

import margin_rl  # noqa: F401 - registers the margin_rl ids

ENV_ID = "margin_rl/SLIPHopper-v0"


def save_atomic(model: PPO, path: Path) -> Path:
    """``model.save`` into a temporary file next to ``path``, then ``os.replace`` it into place."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.zip")  # same folder: os.replace is atomic
    try:
        model.save(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


class Checkpoints(BaseCallback):
    """Save ``<folder>/ckpt_<steps>.zip`` (atomically) each time another ``every`` environment steps are done."""

    def __init__(self, folder: Path, every: int) -> None:
        super().__init__()
        self.folder, self.every, self.next = folder, every, every

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.next:
            save_atomic(self.model, self.folder / f"ckpt_{self.num_timesteps:09d}.zip")
            self.next = (self.num_timesteps // self.every + 1) * self.every
        return True


def evaluate(model: PPO, margin_weight: float, episodes: int, seed: int) -> list[float]:
    """Returns of deterministic episodes, episode ``i`` on a fresh hopper reset with ``seed + i``."""
    env = gymnasium.make(ENV_ID, margin_weight=margin_weight)
    returns = []
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action)
            total, done = total + float(reward), terminated or truncated
        returns.append(total)
    env.close()
    return returns


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--total-steps", type=int, default=100_000, help="environment steps (hops)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--margin-weight", type=float, default=1.0, help="weight of the margin reward (0: none)")
    parser.add_argument("--out", type=Path, default=Path("runs/slip_hopper"), help="output folder")
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument("--checkpoint-every", type=int, default=10_000, help="environment steps between checkpoints")
    parser.add_argument("--eval-episodes", type=int, default=10)
    args = parser.parse_args(argv)

    venv = make_vec_env(
        lambda: gymnasium.make(ENV_ID, margin_weight=args.margin_weight), n_envs=args.num_envs, seed=args.seed
    )
    n_steps = max(1, min(256, args.total_steps // args.num_envs))  # a tiny budget still gets whole rollouts
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=n_steps,
        batch_size=max(2, n_steps * args.num_envs // 4),
        n_epochs=5,
        learning_rate=1e-3,
        ent_coef=0.01,
        vf_coef=1.0,
        max_grad_norm=1.0,
        target_kl=0.01,
        policy_kwargs={
            "net_arch": {"pi": [128, 64, 32], "vf": [128, 64, 32]},
            "activation_fn": torch.nn.ELU,
            "log_std_init": math.log(0.5),
        },
        seed=args.seed,
        device="cpu",
    )
    model.learn(args.total_steps, callback=Checkpoints(args.out / "checkpoints", args.checkpoint_every))
    final = save_atomic(model, args.out / "final_model.zip")
    venv.close()

    returns = evaluate(model, args.margin_weight, args.eval_episodes, seed=args.seed + 1000)
    print(f"trained {model.num_timesteps} steps; wrote {final}")
    print(f"mean return over {len(returns)} episodes: {np.mean(returns):.3f} ± {np.std(returns):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
