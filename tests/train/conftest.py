"""Shared fixtures of the training tests: toy learned-margin weights and two tiny finished runs (rsl, sb3)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("GIT_PYTHON_REFRESH", "quiet")

from tests.stability.learned.test_model import random_weights

TINY_ENV = ["--env-option", "episode_length_s=0.5"]  # 25-step episodes: metrics appear within a few iterations


@pytest.fixture(scope="session")
def toy_weights(tmp_path_factory: pytest.TempPathFactory) -> str:
    """Random learned-margin weights with a valid card (the bundled ones may not exist yet)."""
    from margin_rl.stability.learned.model import save_weights

    path = tmp_path_factory.mktemp("weights") / "toy"
    save_weights(random_weights(), path, {"robot": "toy"})
    return str(path.with_suffix(".npz"))


def tiny_args(backend: str, run_dir: Path, weights: str, total: int = 384, every: int = 192) -> list[str]:
    """Command-line arguments of a tiny run: 8 environments, ``total`` steps, toy margin weights."""
    return [
        "--backend", backend, "--num-envs", "8", "--total-steps", str(total), "--checkpoint-every", str(every),
        "--margin-weights", weights, "--margin-weight", "0.5", "--seed", "3", "--run-dir", str(run_dir),
        "--no-progress", *TINY_ENV,
    ]  # fmt: skip


def _train(backend: str, root: Path, weights: str) -> Path:
    from margin_rl.train.commands.train import main

    run_dir = root / f"{backend}_run"
    assert main(tiny_args(backend, run_dir, weights)) == 0
    return run_dir


@pytest.fixture(scope="session")
def rsl_run(tmp_path_factory: pytest.TempPathFactory, toy_weights: str) -> Path:
    """A finished tiny rsl-rl run, trained through the command line."""
    return _train("rsl", tmp_path_factory.mktemp("rsl"), toy_weights)


@pytest.fixture(scope="session")
def sb3_run(tmp_path_factory: pytest.TempPathFactory, toy_weights: str) -> Path:
    """A finished tiny SB3 run, trained through the command line."""
    return _train("sb3", tmp_path_factory.mktemp("sb3"), toy_weights)
