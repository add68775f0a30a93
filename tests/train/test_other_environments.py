"""Environments other than the batched ANYmal ids: ``margin_rl.train`` refuses them with one clear error (commands
and factories), and ``examples/train_slip_hopper.py`` trains the SLIP hopper with plain Stable-Baselines3."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json
import shutil
from pathlib import Path
from types import ModuleType

import gymnasium
import numpy as np
import pytest
from stable_baselines3 import PPO

from margin_rl.registration import ANYMAL_ENV_IDS
from margin_rl.train.backends.rsl import make_rsl_env
from margin_rl.train.backends.sb3 import make_sb3_env
from margin_rl.train.commands import compare as compare_module
from margin_rl.train.commands import evaluate as evaluate_module
from margin_rl.train.commands import train as train_module
from margin_rl.train.environments import anymal_id

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "train_slip_hopper.py"
SLIP = "margin_rl/SLIPHopper-v0"
BUNDLED_POLICY = ROOT / "train" / "bundled" / "anymal_b" / "with_margin__s0" / "policy.pt"


def assert_refused(message: str) -> None:
    """The one error for another id: it names every ANYmal id and points at plain SB3 and the example."""
    for env_id in ANYMAL_ENV_IDS:
        assert env_id in message
    assert "Stable-Baselines3" in message and "SLIPHopper-v0" in message and "examples/train_slip_hopper.py" in message


# ---------------------------------------------------------------------------------------------------------------------
# margin_rl.train: one environment path
# ---------------------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("env_id", "kind"), [(SLIP, "is not a margin_rl ANYmal"), ("Pendulum-v1", "is not a"),
                                              ("margin_rl/NoSuchHopper-v0", "unknown environment id")])  # fmt: skip
def test_ids_and_factories_refuse_other_environments(env_id: str, kind: str) -> None:
    for build in (anymal_id, train_module.make_spec, lambda i: make_sb3_env(i, 2), lambda i: make_rsl_env(i, 2)):
        with pytest.raises(ValueError, match=kind) as info:
            build(env_id)
        assert_refused(str(info.value))
    assert anymal_id("margin_rl/AnymalB-v0") == "margin_rl/AnymalB-v1"  # a retired id is read as its -v1 id


@pytest.mark.parametrize("backend", ["rsl", "sb3"])
def test_train_command_refuses_the_slip_hopper(
    backend: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["--env", SLIP, "--backend", backend, "--run-dir", str(tmp_path / "run"), "--no-progress"]
    with pytest.raises(SystemExit):
        train_module.main(args)
    assert_refused(capsys.readouterr().err)
    assert not (tmp_path / "run").exists()


def test_resume_of_a_run_of_another_environment_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A run directory of the former generic path (``env_kwargs``, no ``env_config``) cannot be resumed."""
    config = {"env_id": SLIP, "backend": "sb3", "seed": 0, "num_envs": 2, "total_steps": 96, "checkpoint_every": 48,
              "env_kwargs": {"margin_weight": 0.5}, "ppo": {}, "backend_config": {}}  # fmt: skip
    (tmp_path / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError) as info:
        train_module.load_spec(tmp_path)
    assert_refused(str(info.value))
    with pytest.raises(SystemExit):
        train_module.main(["--resume", str(tmp_path), "--no-progress"])
    assert_refused(capsys.readouterr().err)


def test_evaluate_command_refuses_the_slip_hopper(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "eval"
    assert evaluate_module.main([str(BUNDLED_POLICY), "--env", SLIP, "--out", str(out)]) == 2
    assert_refused(capsys.readouterr().err)
    assert not out.exists()


def test_compare_command_refuses_the_slip_hopper(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "compare"
    with pytest.raises(SystemExit):
        compare_module.main(["--env", SLIP, "--seeds", "1", "--total-steps", "96", "--out", str(out), "--no-progress"])
    assert_refused(capsys.readouterr().err)
    assert not out.exists()


# ---------------------------------------------------------------------------------------------------------------------
# the SLIP hopper with plain Stable-Baselines3: examples/train_slip_hopper.py
# ---------------------------------------------------------------------------------------------------------------------
def _example() -> ModuleType:
    spec = importlib.util.spec_from_file_location("train_slip_hopper", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def slip_out(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The example's output folder after a tiny run (256 steps, checkpoints every 128), and what it printed."""
    out = tmp_path_factory.mktemp("slip") / "out"
    argv = ["--total-steps", "256", "--num-envs", "4", "--checkpoint-every", "128", "--eval-episodes", "2",
            "--seed", "3", "--margin-weight", "0.5", "--out", str(out)]  # fmt: skip
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert _example().main(argv) == 0
    return out, printed.getvalue()


def test_example_writes_its_model_and_checkpoints_atomically(slip_out: tuple[Path, str]) -> None:
    out, printed = slip_out
    assert (out / "final_model.zip").is_file()
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["ckpt_000000128.zip", "ckpt_000000256.zip"]
    assert not [p for p in out.rglob("*") if p.name.startswith(".")]  # no temporary file left behind
    assert "trained 256 steps" in printed and "mean return over 2 episodes:" in printed


def test_the_saved_model_loads_and_acts(slip_out: tuple[Path, str], tmp_path: Path) -> None:
    out, _ = slip_out
    model = PPO.load(out / "final_model.zip", device="cpu")
    assert model.num_timesteps == 256 and model.observation_space.shape == (3,) and model.action_space.shape == (2,)
    env = gymnasium.make(SLIP, margin_weight=0.5)
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action)
    env.step(action)
    returns = _example().evaluate(model, 0.5, 2, seed=11)
    assert len(returns) == 2 and np.all(np.isfinite(returns))
    assert PPO.load(out / "checkpoints" / "ckpt_000000128.zip", device="cpu").predict(obs)[0].shape == (2,)
    # margin_rl.train does not evaluate it: the SLIP hopper is not one of its environments
    shutil.copy(out / "final_model.zip", tmp_path / "final_model.zip")
    with pytest.raises(ValueError) as info:
        evaluate_module.evaluate(tmp_path / "final_model.zip", env_id=SLIP, out_dir=tmp_path / "eval")
    assert_refused(str(info.value))
