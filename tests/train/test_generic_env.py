"""The generic Gymnasium path of ``train`` and ``evaluate`` (SB3 only), on ``margin_rl/SLIPHopper-v0`` and Pendulum:
spec and config.json, TensorBoard tags, checkpoints, resume, evaluation of both saved kinds, and the errors."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

from margin_rl.envs.config import EnvConfig
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.backends.sb3 import make_gym_vec_env
from margin_rl.train.commands import evaluate as evaluate_module
from margin_rl.train.commands import train as train_module
from margin_rl.train.config import Sb3PPOConfig, to_dict
from margin_rl.train.environments import check_gym_env, env_kwargs_for, margin_weight_of
from margin_rl.train.metrics import InfoEpisodeStatistics
from margin_rl.train.runs import StopRequest

SLIP = "margin_rl/SLIPHopper-v0"
STEPS, EVERY, NUM_ENVS = 1920, 960, 4  # 4 envs x 24 steps = 96 steps per PPO update: 20 updates


def _slip_args(run_dir: Path) -> list[str]:
    return [
        "--env", SLIP, "--backend", "sb3", "--margin-weight", "0.5", "--num-envs", str(NUM_ENVS),
        "--total-steps", str(STEPS), "--checkpoint-every", str(EVERY), "--seed", "3", "--run-dir", str(run_dir),
        "--no-progress",
    ]  # fmt: skip


@pytest.fixture(scope="module")
def slip_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished tiny SB3 run on the SLIP hopper, trained through the command line."""
    run_dir = tmp_path_factory.mktemp("slip") / "run"
    assert train_module.main(_slip_args(run_dir)) == 0
    return run_dir


def _scalars(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    """Tag -> (step, value) of every scalar in the run's TensorBoard files."""
    from tensorboard.util import tensor_util

    found: dict[str, list[tuple[int, float]]] = {}
    for path in sorted((run_dir / "tb").glob("events.out.tfevents.*")):
        for event in EventFileLoader(str(path)).Load():
            for value in event.summary.value:
                number = (
                    value.simple_value if value.HasField("simple_value") else tensor_util.make_ndarray(value.tensor)
                )
                found.setdefault(value.tag, []).append((int(event.step), float(number)))
    return found


# ---------------------------------------------------------------------------------------------------------------------
# training, checkpoints, resume
# ---------------------------------------------------------------------------------------------------------------------
def test_slip_training_writes_config_checkpoints_models_and_tags(slip_run: Path) -> None:
    config = json.loads((slip_run / "config.json").read_text())
    assert config["env_id"] == SLIP and config["backend"] == "sb3"
    assert config["env_kwargs"] == {"margin_weight": 0.5} and "env_config" not in config
    assert config["backend_config"]["n_steps"] == 24
    progress = json.loads((slip_run / "progress.json").read_text())
    assert progress["finished"] and progress["env_steps"] == STEPS
    assert (slip_run / "final_model.zip").is_file() and (slip_run / "policy_torchscript.pt").is_file()
    assert sorted(p.name for p in (slip_run / "checkpoints").iterdir()) == [
        "ckpt_000000000960.zip",
        "ckpt_000000001920.zip",
    ]
    spec = train_module.load_spec(slip_run)
    assert not spec.is_anymal and spec.env_config is None and spec.env_kwargs == {"margin_weight": 0.5}
    scalars = _scalars(slip_run)
    for tag in (
        "Episode_Metrics/return",
        "Episode_Metrics/length",
        "Episode_Metrics/margin_mean",
        "Episode_Metrics/failed_mean",
        "Episode_Reward/tracking",
        "Episode_Reward/margin",
        "Episode_Reward/failure",
        "Episode_Termination/timed_out",
        "Perf/total_fps",
        "rollout/ep_rew_mean",
    ):
        assert tag in scalars, f"{tag} missing from {sorted(scalars)}"
    # Every episode of the hopper ends with a failure term of -1 or by its 50-hop limit: the logged means lie in
    # [-1, 0]; episode lengths in [1, 50] hops.
    assert all(-1.0 <= v <= 0.0 for _, v in scalars["Episode_Reward/failure"])
    assert all(1.0 <= v <= 50.0 for _, v in scalars["Episode_Metrics/length"])


def test_resume_extends_the_run_and_keeps_its_environment(slip_run: Path, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(slip_run, run_dir)
    before = {p.name for p in (run_dir / "checkpoints").iterdir()}
    assert train_module.main(["--resume", str(run_dir), "--total-steps", str(STEPS + EVERY), "--no-progress"]) == 0
    progress = json.loads((run_dir / "progress.json").read_text())
    assert progress["finished"] and progress["env_steps"] == STEPS + EVERY
    assert {p.name for p in (run_dir / "checkpoints").iterdir()} - before == {"ckpt_000000002880.zip"}
    config = json.loads((run_dir / "config.json").read_text())
    assert config["env_kwargs"] == {"margin_weight": 0.5} and config["total_steps"] == STEPS + EVERY
    assert len(config["sessions"]) == 2
    fps_steps = [step for step, _ in _scalars(run_dir)["time/fps"]]
    assert max(fps_steps) > STEPS  # SB3's step counter went on from the checkpoint's
    with pytest.raises(SystemExit):  # the run directory is taken: only --resume may continue it
        train_module.main(_slip_args(run_dir))


def test_stop_request_checkpoints_and_resume_finishes(tmp_path: Path) -> None:
    """A stop (as SIGINT/SIGTERM request it) after the first checkpoint: a resumable run, then finished."""
    run_dir = tmp_path / "run"
    spec = train_module.make_spec(SLIP, "sb3", {"margin_weight": 0.0}, num_envs=2, total_steps=480, checkpoint_every=96)
    stop = StopRequest()
    result = train_module.train(
        spec, run_dir, progress=False, stop=stop, on_checkpoint=lambda path, steps: stop.request()
    )
    assert result.stopped and not result.finished and result.final_model is None
    # 2 envs x 24 steps = 48 per update: the interval checkpoint at 96 steps; the stop, requested then, acts at
    # the next rollout boundary and writes its own checkpoint there.
    assert sorted(p.name for p in (run_dir / "checkpoints").iterdir()) == [
        "ckpt_000000000096.zip",
        "ckpt_000000000144.zip",
    ]
    assert result.env_steps == 144 and result.checkpoint.name == "ckpt_000000000144.zip"
    assert not (run_dir / "final_model.zip").exists()
    assert train_module.main(["--resume", str(run_dir), "--no-progress"]) == 0
    progress = json.loads((run_dir / "progress.json").read_text())
    assert progress["finished"] and progress["env_steps"] == 480 and (run_dir / "policy_torchscript.pt").is_file()
    assert json.loads((run_dir / "config.json").read_text())["env_kwargs"] == {"margin_weight": 0.0}


def test_another_gymnasium_id_trains_without_a_margin_weight(tmp_path: Path) -> None:
    """Not hard-wired to the hopper: Pendulum-v1 (no margin weight) with a constructor keyword."""
    args = ["--env", "Pendulum-v1", "--num-envs", "2", "--total-steps", "96", "--env-option", "g=9.81",
            "--env-option", "max_episode_steps=10", "--runs-root", str(tmp_path), "--no-progress"]  # fmt: skip
    assert train_module.main(args) == 0  # sb3 is the default backend of the generic path
    (run_dir,) = tmp_path.iterdir()
    assert run_dir.name.startswith("Pendulum-v1__sb3__s1__")  # no mw<weight> part
    config = json.loads((run_dir / "config.json").read_text())
    assert (
        config["env_kwargs"] == {"g": 9.81, "max_episode_steps": 10} and (run_dir / "policy_torchscript.pt").is_file()
    )
    lengths = [v for _, v in _scalars(run_dir)["Episode_Metrics/length"]]  # Pendulum only ends by its time limit
    assert lengths and all(v == 10.0 for v in lengths)
    assert all(v == 1.0 for _, v in _scalars(run_dir)["Episode_Termination/timed_out"])
    assert margin_weight_of("Pendulum-v1", {}) is None and margin_weight_of(SLIP, {}) == 1.0


# ---------------------------------------------------------------------------------------------------------------------
# evaluation
# ---------------------------------------------------------------------------------------------------------------------
def _evaluate(policy: Path, out: Path, *extra: str) -> dict:
    assert evaluate_module.main([str(policy), "--episodes", "6", "--seed", "11", "--out", str(out), *extra]) == 0
    return json.loads((out / "metrics.json").read_text())


def test_evaluate_sb3_zip_and_torchscript_alike(slip_run: Path, tmp_path: Path) -> None:
    zipped = _evaluate(slip_run / "final_model.zip", tmp_path / "zip")
    traced = _evaluate(slip_run / "policy_torchscript.pt", tmp_path / "ts")
    assert zipped["kind"] == "sb3" and traced["kind"] == "torchscript"
    assert zipped["env_id"] == SLIP and zipped["env_kwargs"] == {"margin_weight": 0.5} and zipped["episodes"] == 6
    assert (tmp_path / "zip" / "episode.png").stat().st_size > 10_000
    # Two loaders of one policy (SB3's predict, the traced actor) on the same seeds: the same episodes.
    for key in ("return", "length", "reward/margin"):
        np.testing.assert_allclose(
            [e[key] for e in zipped["per_episode"]], [e[key] for e in traced["per_episode"]], rtol=1e-9, atol=1e-12
        )
    obs = np.random.default_rng(0).uniform([0.8, -1.0, -1.0], [1.2, 1.0, 1.0], (64, 3)).astype(np.float32)
    np.testing.assert_allclose(
        load_policy(slip_run / "final_model.zip")(obs), load_policy(slip_run / "policy_torchscript.pt")(obs), atol=1e-6
    )
    for episode in zipped["per_episode"]:
        # The hopper's reward is the sum of its terms, summed independently by the evaluation.
        terms = episode["reward/tracking"] + episode["reward/margin"] + episode["reward/failure"]
        assert episode["return"] == pytest.approx(terms, abs=1e-9)
        # The margin term is margin_weight x M(s, a), summed; margin_mean averages M over the same steps.
        assert episode["reward/margin"] == pytest.approx(0.5 * episode["margin_mean"] * episode["length"], abs=1e-9)
        assert episode["terminated"] + episode["timed_out"] == 1.0


def test_evaluate_margin_weight_reaches_the_environment(slip_run: Path, tmp_path: Path) -> None:
    base = _evaluate(slip_run / "policy_torchscript.pt", tmp_path / "base")
    zero = _evaluate(slip_run / "policy_torchscript.pt", tmp_path / "zero", "--margin-weight", "0")
    assert zero["env_kwargs"] == {"margin_weight": 0.0}
    for with_margin, without in zip(base["per_episode"], zero["per_episode"], strict=True):
        assert without["reward/margin"] == 0.0  # the same hops, without the margin term
        assert without["return"] == pytest.approx(with_margin["return"] - with_margin["reward/margin"], abs=1e-9)


# ---------------------------------------------------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------------------------------------------------
def test_rsl_backend_on_a_generic_id_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match="--backend sb3"):
        train_module.make_spec(SLIP, "rsl")
    with pytest.raises(SystemExit):
        train_module.main(["--env", SLIP, "--backend", "rsl", "--run-dir", str(tmp_path / "run"), "--no-progress"])
    assert "--backend sb3" in capsys.readouterr().err and not (tmp_path / "run").exists()


def test_unknown_id_lists_the_margin_rl_ids(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match="unknown environment id") as info:
        train_module.make_spec("margin_rl/NoSuchHopper-v0", "sb3")
    assert SLIP in str(info.value) and "margin_rl/AnymalB-v1" in str(info.value)
    with pytest.raises(SystemExit):
        train_module.main(["--env", "margin_rl/NoSuchHopper-v0", "--run-dir", str(tmp_path / "run")])
    assert SLIP in capsys.readouterr().err


@pytest.mark.parametrize(
    ("env_id", "options", "message"),
    [
        (SLIP, {"no_such_option": 1}, r"unknown option.*no_such_option.*goal_velocity"),
        (SLIP, {"margin": "none"}, r"ANYmal options"),
        ("Pendulum-v1", {"margin_weight": 0.5}, r"drop --margin-weight"),
        (SLIP, {"goal_range": (-1.0, float("nan"))}, r"finite JSON"),
    ],
)
def test_wrong_environment_options_are_clear_errors(env_id: str, options: dict, message: str) -> None:
    with pytest.raises(TypeError, match=message):
        train_module.make_spec(env_id, "sb3", options)


def test_options_the_environment_rejects_fail_before_the_run_directory(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["--env", SLIP, "--env-option", "tracking_sigma=-1", "--run-dir", str(tmp_path / "run"), "--no-progress"]
    with pytest.raises(SystemExit):
        train_module.main(args)
    assert "tracking_sigma" in capsys.readouterr().err and not (tmp_path / "run").exists()
    with pytest.raises(ValueError, match="fails to reset or step"):  # a mapping where SlipParams is needed
        check_gym_env(SLIP, {"params": {}})
    with pytest.raises(ValueError, match="Box"):  # discrete actions: no Gaussian actor to export
        check_gym_env("CartPole-v1", {})


# ---------------------------------------------------------------------------------------------------------------------
# specs and episode statistics
# ---------------------------------------------------------------------------------------------------------------------
def test_spec_json_old_anymal_configs_and_no_shared_dicts(tmp_path: Path) -> None:
    options = {"margin_weight": 0.25, "goal_range": (-0.5, 0.5)}
    spec = train_module.make_spec(SLIP, "sb3", options, num_envs=2)
    options["margin_weight"] = 9.0  # the spec holds its own copy
    assert spec.env_kwargs == {"margin_weight": 0.25, "goal_range": [-0.5, 0.5]}
    assert train_module.TrainSpec.from_json(spec.to_json()) == spec and hash(spec) == hash(spec)
    # A config.json written before env_kwargs existed (ANYmal, env_config only) still loads.
    anymal = train_module.TrainSpec(backend="sb3", ppo=Sb3PPOConfig(), env_config=EnvConfig(margin_weight=0.3))
    old = {k: v for k, v in anymal.to_json().items() if k != "env_kwargs"}
    assert "env_kwargs" not in anymal.to_json() and old["env_config"] == to_dict(anymal.env_config)
    (tmp_path / "config.json").write_text(json.dumps(old))
    loaded = train_module.load_spec(tmp_path)
    assert loaded == anymal and loaded.is_anymal and loaded.env_config.margin_weight == 0.3
    with pytest.raises(ValueError, match="not both"):
        train_module.TrainSpec(env_config=EnvConfig(), env_kwargs={})


def test_info_episode_statistics_against_monitor_and_by_hand() -> None:
    stats = InfoEpisodeStatistics(2)
    info = [{"reward_a": 1.0, "flag": True, "text": "x", "vec": np.zeros(2)}, {"reward_a": 2.0}]
    assert stats.update(np.array([1.5, 2.0]), info, np.array([False, False]), np.array([False, False])) == {}
    info = [{"reward_a": 0.5, "flag": False, "TimeLimit.truncated": True}, {"reward_a": 1.0, "v": 4.0}]
    out = stats.update(np.array([0.5, 1.0]), info, np.array([False, True]), np.array([True, False]))
    assert out["env"].tolist() == [0, 1] and out["return"].tolist() == [2.0, 3.0] and out["length"].tolist() == [2, 2]
    assert out["reward/a"].tolist() == [1.5, 3.0] and out["flag_mean"][0] == 0.5 and np.isnan(out["flag_mean"][1])
    assert out["v_mean"][1] == 4.0 and "text_mean" not in out and "vec_mean" not in out
    assert out["timed_out"].tolist() == [1.0, 0.0] and out["terminated"].tolist() == [0.0, 1.0]
    assert stats.close([0])["length"].tolist() == [0]  # a fresh episode after the ending one

    # On the hopper, returns agree with SB3's Monitor (an independent sum of the same rewards).
    venv = make_gym_vec_env(SLIP, env_kwargs_for(SLIP, {"margin_weight": 0.5}), 3, seed=5)
    venv.reset()
    rng = np.random.default_rng(1)
    ended = 0
    for _ in range(30):
        _, _, dones, infos = venv.step(rng.uniform(-1, 1, (3, 2)).astype(np.float32))
        finished = venv.stats_finished
        assert finished.get("env", np.array([], dtype=int)).tolist() == np.flatnonzero(dones).tolist()
        for k, i in enumerate(finished.get("env", [])):
            assert finished["return"][k] == pytest.approx(infos[i]["episode"]["r"], abs=1e-5)  # float32 rewards
            assert finished["length"][k] == infos[i]["episode"]["l"]
            ended += 1
    assert ended > 0
    venv.close()
