"""Warm starts (``--init-from``): a new run begins with a trained model's networks, fresh otherwise; bad files fail
before anything is written, naming what is wrong."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest
import torch
from stable_baselines3 import PPO

from margin_rl.provenance import sha256_file
from margin_rl.train.backends.rsl import CheckpointingRunner, rsl_vec_env
from margin_rl.train.backends.sb3 import make_model, sb3_vec_env, warm_start
from margin_rl.train.commands import train as train_module
from margin_rl.train.runs import RunHooks
from tests.train.conftest import tiny_args

QUIET_HOOKS = RunHooks(lambda: False, lambda steps, mean_return: None, lambda path, steps: None)


def _rsl_runner(run_dir: Path, tmp_path: Path) -> CheckpointingRunner:
    """A fresh (randomly initialised) runner with the settings of ``run_dir``'s run, on another seed."""
    spec = train_module.load_spec(run_dir)
    torch.manual_seed(99)
    env = rsl_vec_env(spec.target, 8, seed=99)
    return CheckpointingRunner(env, spec.backend_config(), tmp_path, "cpu", QUIET_HOOKS)


def _state_dicts_equal(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_rsl_warm_start_copies_actor_critic_and_normalisers(rsl_run: Path, tmp_path: Path) -> None:
    source = torch.load(rsl_run / "final_model.pt", map_location="cpu", weights_only=True)
    runner = _rsl_runner(rsl_run, tmp_path)
    assert not _state_dicts_equal(runner.alg.save()["actor_state_dict"], source["actor_state_dict"])
    optimizer_before = runner.alg.optimizer.state_dict()
    runner.warm_start(rsl_run / "final_model.pt")
    saved = runner.alg.save()
    assert _state_dicts_equal(saved["actor_state_dict"], source["actor_state_dict"])
    assert _state_dicts_equal(saved["critic_state_dict"], source["critic_state_dict"])
    assert runner.alg.optimizer.state_dict()["state"] == optimizer_before["state"] == {}  # fresh Adam moments
    assert runner.completed_iterations == 0  # a new run: its own step count


def test_sb3_warm_start_copies_the_policy_only(sb3_run: Path) -> None:
    spec = train_module.load_spec(sb3_run)
    model = make_model(sb3_vec_env(spec.target, 8, seed=99), spec.ppo, seed=99, device="cpu")
    trained = PPO.load(sb3_run / "final_model.zip", device="cpu")
    assert not _state_dicts_equal(model.policy.state_dict(), trained.policy.state_dict())
    warm_start(model, sb3_run / "final_model.zip")
    assert _state_dicts_equal(model.policy.state_dict(), trained.policy.state_dict())
    assert model.num_timesteps == 0


@pytest.mark.parametrize("backend", ["rsl", "sb3"])
def test_cli_warm_start_records_the_source_and_counts_steps_afresh(
    backend: str, tmp_path: Path, toy_weights: str, request: pytest.FixtureRequest
) -> None:
    source_run: Path = request.getfixturevalue(f"{backend}_run")
    source = source_run / ("final_model.pt" if backend == "rsl" else "final_model.zip")
    run_dir = tmp_path / "warm"
    args = [*tiny_args(backend, run_dir, toy_weights, total=192, every=192), "--init-from", str(source)]
    assert train_module.main(args) == 0
    config = json.loads((run_dir / "config.json").read_text())
    assert config["init_from"] == str(source) and config["init_from_sha256"] == sha256_file(source)
    assert json.loads((run_dir / "progress.json").read_text())["env_steps"] == 192
    assert train_module.load_spec(run_dir).init_from == str(source)
    # --resume --total-steps continues from the run's own checkpoint; the warm start is not applied again
    assert train_module.main(["--resume", str(run_dir), "--total-steps", "384", "--no-progress"]) == 0
    resumed = json.loads((run_dir / "config.json").read_text())
    assert resumed["init_from_sha256"] == config["init_from_sha256"] and len(resumed["sessions"]) == 2


def test_spec_without_init_from_reads_old_configs(rsl_run: Path) -> None:
    data = json.loads((rsl_run / "config.json").read_text())
    data.pop("init_from", None)  # config.json of a run recorded before warm starts existed
    assert train_module.TrainSpec.from_json(data).init_from is None


def _cli_error(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit):
        train_module.main(args)
    return capsys.readouterr().err


@pytest.mark.parametrize(
    ("backend", "make_source", "message"),
    [
        ("rsl", lambda runs: runs["rsl"] / "missing.pt", "no such file"),
        ("rsl", lambda runs: runs["sb3"] / "final_model.zip", "a rsl run starts from a rsl model"),
        ("sb3", lambda runs: runs["rsl"] / "final_model.pt", "a sb3 run starts from a sb3 model"),
        ("rsl", lambda runs: runs["rsl"] / "policy_torchscript.pt", "not 'policy_torchscript.pt'"),
    ],
)
def test_bad_init_from_fails_before_the_run_directory_exists(
    backend, make_source, message, rsl_run: Path, sb3_run: Path, tmp_path: Path, toy_weights: str, capsys
) -> None:
    source = make_source({"rsl": rsl_run, "sb3": sb3_run})
    run_dir = tmp_path / "run"
    err = _cli_error([*tiny_args(backend, run_dir, toy_weights), "--init-from", str(source)], capsys)
    assert message in err and not run_dir.exists()


def test_init_from_with_resume_is_refused(rsl_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = _cli_error(["--resume", str(rsl_run), "--init-from", str(rsl_run / "final_model.pt")], capsys)
    assert "--init-from starts a new run" in err


def test_rsl_warm_start_names_a_size_or_shape_mismatch(rsl_run: Path, tmp_path: Path) -> None:
    state = torch.load(rsl_run / "final_model.pt", map_location="cpu", weights_only=True)
    other_obs = dict(state, infos={**state["infos"], "obs_dim": state["infos"]["obs_dim"] + 3})
    torch.save(other_obs, tmp_path / "other_obs.pt")
    runner = _rsl_runner(rsl_run, tmp_path / "a")
    with pytest.raises(ValueError, match="observation of size"):
        runner.warm_start(tmp_path / "other_obs.pt")

    actor = dict(state["actor_state_dict"])
    name = next(k for k, v in actor.items() if v.ndim == 2)  # a weight matrix: widen its first layer
    actor[name] = torch.zeros(actor[name].shape[0] + 1, actor[name].shape[1])
    torch.save(dict(state, actor_state_dict=actor), tmp_path / "other_net.pt")
    with pytest.raises(ValueError, match="networks differ"):
        runner.warm_start(tmp_path / "other_net.pt")

    torch.save({"actor_state_dict": {}}, tmp_path / "foreign.pt")
    with pytest.raises(ValueError, match="not a margin_rl rsl-rl model"):
        runner.warm_start(tmp_path / "foreign.pt")


def test_sb3_warm_start_names_a_network_mismatch(sb3_run: Path, tmp_path: Path) -> None:
    spec = train_module.load_spec(sb3_run)
    narrow = dataclasses.replace(spec.ppo, net_arch=(16, 16))
    model = make_model(sb3_vec_env(spec.target, 8, seed=1), narrow, seed=1, device="cpu")
    copy = tmp_path / "model.zip"
    shutil.copy(sb3_run / "final_model.zip", copy)
    with pytest.raises(ValueError, match="networks differ"):
        warm_start(model, copy)
