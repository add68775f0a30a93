"""Training through the command line (both backends): outputs, TensorBoard tags, checkpoints, stop and resume."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
import torch
from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

from margin_rl.train.commands import train as train_module
from margin_rl.train.runs import latest_checkpoint
from tests.conftest import require_mujoco_warp
from tests.train.conftest import tiny_args


def _scalars(path: Path) -> dict[str, list[int]]:
    """Tag -> steps of the scalar summaries in one TensorBoard event file."""
    found: dict[str, list[int]] = {}
    for event in EventFileLoader(str(path)).Load():
        for value in event.summary.value:
            found.setdefault(value.tag, []).append(int(event.step))
    return found


def _event_files(run_dir: Path) -> list[Path]:
    return sorted((run_dir / "tb").glob("events.out.tfevents.*"), key=lambda p: p.stat().st_mtime)


@pytest.mark.parametrize("backend", ["rsl", "sb3"])
def test_cli_training_writes_config_checkpoints_models_and_tags(backend: str, request: pytest.FixtureRequest) -> None:
    run_dir: Path = request.getfixturevalue(f"{backend}_run")
    config = json.loads((run_dir / "config.json").read_text())
    assert config["backend"] == backend and config["env_config"]["margin_weight"] == 0.5
    assert config["env_config"]["robot"] == "anymal_b" and config["ppo"] and config["backend_config"]
    progress = json.loads((run_dir / "progress.json").read_text())
    assert progress["finished"] and progress["env_steps"] == 384
    assert (run_dir / ("final_model.zip" if backend == "sb3" else "final_model.pt")).is_file()
    assert (run_dir / "policy_torchscript.pt").is_file()
    assert latest_checkpoint(run_dir).name == f"ckpt_000000000384.{'zip' if backend == 'sb3' else 'pt'}"
    tags = set().union(*(_scalars(p) for p in _event_files(run_dir)))
    for tag in (
        "Episode_Reward/velocity_tracking",
        "Episode_Reward/margin",
        "Episode_Metrics/margin_mean",
        "Episode_Metrics/lin_acc_rms_x",
        "Episode_Metrics/lin_acc_peak_z",
        "Episode_Metrics/ang_acc_rms_y",
        "Episode_Metrics/velocity_error_mean",
        "Episode_Metrics/stance_width_mean",
        "Episode_Termination/fell",
        "Perf/total_fps",
    ):
        assert tag in tags, f"{tag} missing from {sorted(tags)}"


def _interrupt_on_first_checkpoint(path: Path, steps: int) -> None:
    if not getattr(_interrupt_on_first_checkpoint, "sent", False):
        _interrupt_on_first_checkpoint.sent = True  # type: ignore[attr-defined]
        os.kill(os.getpid(), signal.SIGINT)


@pytest.mark.parametrize("backend", ["rsl", "sb3"])
def test_sigint_checkpoints_and_resume_continues_the_step_count(
    backend: str, tmp_path: Path, toy_weights: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    run_dir = tmp_path / "run"
    _interrupt_on_first_checkpoint.sent = False  # type: ignore[attr-defined]
    original = train_module.train
    monkeypatch.setattr(
        train_module, "train", lambda *a, **k: original(*a, **{**k, "on_checkpoint": _interrupt_on_first_checkpoint})
    )
    # 8 envs x 24 steps = 192 steps per update; a checkpoint after the first update, then SIGINT.
    code = train_module.main(tiny_args(backend, run_dir, toy_weights, total=960, every=192))
    assert code == 128 + signal.SIGINT
    stopped = json.loads((run_dir / "progress.json").read_text())
    assert stopped["stopped"] and not stopped["finished"] and stopped["stop_reason"] == "SIGINT"
    steps_at_stop = stopped["env_steps"]
    assert 0 < steps_at_stop < 960 and latest_checkpoint(run_dir).name.startswith(f"ckpt_{steps_at_stop:012d}")
    assert not (run_dir / "final_model.pt").exists() and not (run_dir / "final_model.zip").exists()
    monkeypatch.setattr(train_module, "train", original)

    with pytest.raises(SystemExit):  # the run directory is taken: only --resume may continue it
        train_module.main(tiny_args(backend, run_dir, toy_weights, total=960, every=192))
    assert train_module.main(["--resume", str(run_dir), "--no-progress"]) == 0
    done = json.loads((run_dir / "progress.json").read_text())
    assert done["finished"] and done["env_steps"] == 960

    files = _event_files(run_dir)
    assert len(files) == 2  # one per session, in the same TensorBoard folder
    first, second = _scalars(files[0]), _scalars(files[1])
    if backend == "rsl":  # x axis = iteration: the resumed session starts at the next iteration
        assert max(first["Loss/value"]) == steps_at_stop // 192 - 1
        assert min(second["Loss/value"]) == steps_at_stop // 192
        state = torch.load(latest_checkpoint(run_dir), weights_only=True)
        assert state["infos"]["completed_iterations"] == 5 and state["iter"] == 4
    else:  # x axis = environment steps
        assert min(second["time/fps"]) > steps_at_stop >= max(first["time/fps"])


def test_missing_margin_weights_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--margin-weights", str(tmp_path / "none.npz"), "--run-dir", str(tmp_path / "run"), "--no-progress"]
    with pytest.raises(SystemExit):
        train_module.main(args)
    assert "--margin none" in capsys.readouterr().err and not (tmp_path / "run").exists()


def test_a_resumed_run_keeps_the_learned_margin_it_started_with(
    tmp_path: Path, toy_weights: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The run records its weights' checksum; replacing the weights behind the same name (e.g. a new default
    network) refuses the resume with a hint, and --margin-weights to the original weights continues the run."""
    from margin_rl.stability.learned.model import LearnedMargin, save_weights
    from tests.stability.learned.test_model import random_weights

    weights = tmp_path / "weights" / "current"
    weights.parent.mkdir()
    save_weights(random_weights(0), weights, {"robot": "toy"})
    started_with = str(weights.with_suffix(".npz"))
    run_dir = tmp_path / "run"
    assert train_module.main(tiny_args("rsl", run_dir, started_with, total=192, every=192)) == 0
    recorded = json.loads((run_dir / "config.json").read_text())["learned_margin"]
    assert recorded == {"source": started_with, "sha256": LearnedMargin.load(started_with).card["sha256"]}

    original = tmp_path / "original.npz"
    original.write_bytes(weights.with_suffix(".npz").read_bytes())
    original.with_suffix(".json").write_text(weights.with_suffix(".json").read_text())
    save_weights(random_weights(1), weights, {"robot": "toy"})  # other weights under the same path
    extend = ["--resume", str(run_dir), "--total-steps", "384", "--no-progress"]
    with pytest.raises(SystemExit):
        train_module.main(extend)
    error = capsys.readouterr().err
    assert recorded["sha256"][:12] in error and "--margin-weights" in error
    assert train_module.main([*extend, "--margin-weights", str(original)]) == 0
    config = json.loads((run_dir / "config.json").read_text())
    assert config["learned_margin"] == recorded and len(config["sessions"]) == 2


# ---------------------------------------------------------------------------------------------------------------------
# command-line defaults: the shipped experiment for the ANYmal ids
# ---------------------------------------------------------------------------------------------------------------------
def _spec(*argv: str) -> train_module.TrainSpec:
    spec, _, _ = train_module.spec_from_args(train_module.build_parser().parse_args(list(argv)))
    return spec


def test_cli_defaults_are_the_shipped_experiment() -> None:
    """No --recipe is the shipped bundles' recipe with its weight; --recipe none keeps that weight, the bare
    environment and the command's own sizes; the bundles' runs are reproduced by their recorded commands."""
    from margin_rl.train.recipes import RECIPES, SHIPPED_RECIPE

    shipped = RECIPES[SHIPPED_RECIPE]
    spec = _spec()  # margin_rl/AnymalB-v1 with the shipped recipe and --env-option reward_params.alive_bonus=0.1
    assert spec.recipe == SHIPPED_RECIPE and spec == _spec("--recipe", SHIPPED_RECIPE)
    assert spec.env_config.margin_weight == shipped.margin_weight and spec.num_envs == shipped.num_envs
    assert spec.env_config.randomization == shipped.env_options["randomization"]
    bare = _spec("--recipe", "none")
    assert bare.recipe is None and bare.env_config.margin_weight == shipped.margin_weight
    assert bare.num_envs == train_module.DEFAULT_NUM_ENVS and bare.env_config.randomization.push_interval_s is None
    config = spec.env_config
    assert config.reward_params.alive_bonus == 0.1
    argv = ("--env", "margin_rl/AnymalC-v1", "--margin-weight", "0", "--env-option", "reward_params.alive_bonus=0")
    config = _spec(*argv).env_config
    assert config.margin_weight == 0.0 and config.reward_params.alive_bonus == 0.0  # given values win
    config = _spec("--env-option", "reward_params.knee_clearance=5").env_config  # other entries keep the default
    assert config.reward_params.knee_clearance == 5 and config.reward_params.alive_bonus == 0.1
    assert _spec("--env-option", "margin_weight=0.7").env_config.margin_weight == 0.7
    # the Python API keeps EnvConfig's
    assert train_module.make_spec().env_config.margin_weight == 1.0
    helptext = train_module.build_parser().format_help()
    assert f"--recipe {SHIPPED_RECIPE}" in helptext and "reward_params.alive_bonus=0.1" in helptext
    with pytest.raises(SystemExit):  # --resume continues the run's own recipe: naming one is refused
        train_module.main(["--resume", "runs/x", "--recipe", "none"])


def test_compare_cli_defaults_are_the_shipped_experiment() -> None:
    from margin_rl.train.commands.compare import _settings_from_args, build_parser
    from margin_rl.train.commands.options import with_training_defaults

    settings = _settings_from_args(build_parser().parse_args([]))
    assert settings.recipe == "robust" and settings.margin_weight == 0.1 and settings.num_envs == 512
    bare = _settings_from_args(build_parser().parse_args(["--recipe", "none"]))
    assert bare.recipe is None and bare.margin_weight == 0.1 and bare.num_envs == 128
    robust = _settings_from_args(build_parser().parse_args(["--recipe", "robust", "--total-steps", "1000"]))
    assert robust.recipe == "robust" and robust.num_envs == 512 and robust.total_steps == 1000
    assert "reward_params.alive_bonus=0.1" in build_parser().format_help()
    options = with_training_defaults("margin_rl/AnymalB-v1", {"margin": "none"}, margin_weight=False)
    assert options == {"reward_params": {"alive_bonus": 0.1}, "margin": "none"}  # the variants set their weights


def test_thread_counts_below_one_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    for option in ("--update-threads", "--torch-threads"):
        with pytest.raises(SystemExit):
            train_module.main([option, "0"])
        assert f"{option} must be >= 1, got 0" in capsys.readouterr().err


def test_resume_refuses_options_that_define_the_run(tmp_path: Path) -> None:
    """--resume continues a run with its recorded settings: --seed 0 or --margin-weight 0 (falsy values too) would
    silently not apply, so they are refused by name; --total-steps, --checkpoint-every and --device apply."""
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    train_module.write_run_config(_spec("--seed", "3", "--num-envs", "8"), run_dir, None)
    parser = train_module.build_parser()
    for argv, named in (
        (["--seed", "0"], "--seed"),
        (["--margin-weight", "0", "--num-envs", "16"], "--margin-weight, --num-envs"),
        (["--env-option", "reward_params.alive_bonus=0"], "--env-option"),
        (["--recipe", "robust"], "--recipe"),
    ):
        with pytest.raises(ValueError, match=f"{named} would change the run"):
            train_module.spec_from_args(parser.parse_args(["--resume", str(run_dir), *argv]))
    argv = ["--resume", str(run_dir), "--total-steps", "4096", "--checkpoint-every", "1024", "--device", "cpu"]
    spec, resumed_dir, resume = train_module.spec_from_args(parser.parse_args(argv))
    assert resume and resumed_dir == run_dir
    assert (spec.seed, spec.num_envs, spec.total_steps, spec.checkpoint_every) == (3, 8, 4096, 1024)


def test_a_run_trained_on_warp_resumes_on_mujoco(tmp_path: Path, toy_weights: str) -> None:
    """--physics is chosen per call, like the threads: a run trained on the Warp backend (Warp's CPU device) records
    no backend in its config.json and resumes on mujoco.batch; the LP margin kinds are refused beside Warp."""
    require_mujoco_warp()
    run_dir = tmp_path / "run"
    warp = ["--physics", "warp", "--physics-device", "cpu"]
    assert train_module.main([*tiny_args("rsl", run_dir, toy_weights, total=192, every=192), *warp]) == 0
    config = json.loads((run_dir / "config.json").read_text())
    recorded = {key: value for key, value in config.items() if key not in ("command", "sessions")}
    assert "physics" not in json.dumps(recorded) and "--physics" in config["command"]  # the command line only
    assert train_module.main(["--resume", str(run_dir), "--total-steps", "384", "--no-progress"]) == 0
    assert json.loads((run_dir / "progress.json").read_text())["env_steps"] == 384
    with pytest.raises(SystemExit):
        train_module.main(["--margin", "analytic", "--run-dir", str(tmp_path / "lp"), "--no-progress", *warp])
    assert not (tmp_path / "lp").exists()


def test_a_buffer_overflow_stops_a_warp_run_and_keeps_its_last_checkpoint(tmp_path: Path, toy_weights: str) -> None:
    """--physics-option reaches the Warp backend: buffers too small for the landing robots stop the resumed run with
    PhysicsOverflowError naming the settings to raise; the checkpoint before it stays, and the run resumes from it
    with the default buffers."""
    require_mujoco_warp()
    from margin_rl.envs.physics_warp import PhysicsOverflowError

    run_dir = tmp_path / "run"
    warp = ["--physics", "warp", "--physics-device", "cpu"]
    assert train_module.main([*tiny_args("rsl", run_dir, toy_weights, total=192, every=192), *warp]) == 0
    kept = latest_checkpoint(run_dir)
    small = ["--physics-option", "nconmax=1", "--physics-option", "njmax=4"]
    with pytest.raises(PhysicsOverflowError, match=r"nconmax=1 .*njmax=4.*physics_options"):
        train_module.main(["--resume", str(run_dir), "--total-steps", "384", "--no-progress", *warp, *small])
    assert latest_checkpoint(run_dir) == kept and kept.is_file()
    assert train_module.main(["--resume", str(run_dir), "--total-steps", "384", "--no-progress", *warp]) == 0
    assert json.loads((run_dir / "progress.json").read_text())["env_steps"] == 384


# 4 curriculum rows x 2 tiles of 4 m, no border: a terrain that builds in milliseconds; every row a starting row.
SMALL_CURRICULUM = (
    'terrain_config={"size": 8.0, "tile": 4.0, "border": 0.0, "curriculum_levels": 4, "initial_max_level": 3}'
)


def _saved_levels(checkpoint: Path) -> list[int]:
    """Each environment's curriculum row saved in a checkpoint of either backend."""
    if checkpoint.suffix == ".pt":
        return torch.load(checkpoint, weights_only=True)["infos"]["curriculum_levels"].tolist()
    from margin_rl.train.backends.sb3 import ThreadedPPO

    return ThreadedPPO.load(checkpoint, device="cpu").curriculum_levels


@pytest.mark.parametrize("backend", ["rsl", "sb3"])
def test_a_resumed_run_keeps_each_environments_curriculum_row(
    backend: str, tmp_path: Path, toy_weights: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The curriculum's rows travel in the checkpoint: the resumed environments start on the rows the run had
    reached, not again on the starting rows (which the same seed would draw again)."""
    from margin_rl.envs.core import AnymalCore

    run_dir = tmp_path / "run"
    rough = ["--env", "margin_rl/AnymalC-Rough-v1", "--env-option", SMALL_CURRICULUM]
    # 8 envs x 48 steps: every 25-step episode has ended once, so the rows have moved from where they started.
    assert train_module.main([*tiny_args(backend, run_dir, toy_weights, total=384, every=384), *rough]) == 0
    reached = _saved_levels(latest_checkpoint(run_dir))
    assert len(reached) == 8 and set(reached) <= {0, 1, 2, 3}
    started = _started_levels(run_dir)
    assert reached != started, "the curriculum did not move: the test cannot tell a restore from a fresh start"

    given: list[list[int]] = []
    original = AnymalCore.restart_on_levels

    def record(core: AnymalCore, levels: object) -> None:
        given.append([int(level) for level in levels])  # type: ignore[attr-defined]
        original(core, levels)
        assert core.terrain_level.tolist() == given[-1]

    monkeypatch.setattr(AnymalCore, "restart_on_levels", record)
    assert train_module.main(["--resume", str(run_dir), "--total-steps", "576", "--no-progress"]) == 0
    assert given == [reached]
    assert len(_saved_levels(latest_checkpoint(run_dir))) == 8


def _started_levels(run_dir: Path) -> list[int]:
    """The rows a run's environments start on: its environment built again with its config and seed."""
    from margin_rl.train.environments import make_core
    from margin_rl.train.runs import read_json

    spec = train_module.TrainSpec.from_json(read_json(run_dir / "config.json"))
    return make_core(spec.env_config, spec.num_envs, spec.seed).terrain_level.tolist()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--physics", "warp", "--physics-device", "cuda:7"], "physics_device must be one of Warp's devices"),
        (["--physics", "warp", "--physics-device", "cpu", "--physics-option", "foo=1"], "not settings of"),
        (["--physics-device", "cuda:0"], "physics='mujoco' runs on the CPU"),
    ],
)
def test_a_bad_physics_choice_is_one_line_before_the_run_folder_is_written(
    options: list[str], message: str, tmp_path: Path, toy_weights: str, capsys: pytest.CaptureFixture[str]
) -> None:
    if "warp" in options:
        require_mujoco_warp()
    run_dir = tmp_path / "run"
    with pytest.raises(SystemExit):
        train_module.main([*tiny_args("rsl", run_dir, toy_weights, total=192, every=192), *options])
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not run_dir.exists()


def test_the_environments_generator_state_is_saved_by_its_name_and_the_older_name_still_resumes(
    tmp_path: Path, toy_weights: str
) -> None:
    run_dir = tmp_path / "run"
    assert train_module.main(tiny_args("rsl", run_dir, toy_weights, total=192, every=192)) == 0
    checkpoint = latest_checkpoint(run_dir)
    saved = torch.load(checkpoint, weights_only=True)
    assert "env_rng_state" in saved["infos"] and "numpy_rng_state" not in saved["infos"]
    saved["infos"]["numpy_rng_state"] = saved["infos"].pop("env_rng_state")  # as written before the rename
    torch.save(saved, checkpoint)
    assert train_module.main(["--resume", str(run_dir), "--total-steps", "384", "--no-progress"]) == 0
    assert json.loads((run_dir / "progress.json").read_text())["env_steps"] == 384
