"""Evaluation of every saved-policy kind, wrong-size policies, the SB3 unpickling warning, the video fallback."""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from margin_rl.train.artifacts.policies import PolicyMismatchError, detect_kind, load_policy
from margin_rl.train.commands.evaluate import evaluate, main
from margin_rl.train.runs import torchscript_export

QUICK = {"episodes": 2, "max_steps": 30, "warmup_s": 0.1}


@pytest.mark.parametrize(
    ("run", "name", "kind"),
    [
        ("rsl_run", "final_model.pt", "rsl"),
        ("rsl_run", "policy_torchscript.pt", "torchscript"),
        ("sb3_run", "final_model.zip", "sb3"),
        ("sb3_run", "policy_torchscript.pt", "torchscript"),
    ],
)
def test_evaluate_each_policy_kind(run: str, name: str, kind: str, request: pytest.FixtureRequest) -> None:
    run_dir: Path = request.getfixturevalue(run)
    out = run_dir / "eval" / f"{kind}_{Path(name).stem}"
    args = [str(run_dir / name), "--episodes", "2", "--max-steps", "30", "--warmup-s", "0.1", "--out", str(out)]
    assert main(args) == 0
    report = json.loads((out / "metrics.json").read_text())
    assert report["kind"] == kind and report["env_id"] == "margin_rl/AnymalB-v1" and report["episodes"] == 2
    assert report["env_config"]["command"]["forward_velocity"] == [0.75, 0.75]
    for key in ("velocity_error_mean", "lin_acc_rms_x", "lin_acc_peak_z", "stance_width_mean", "margin_mean", "fell"):
        assert key in report["summary"] and len(report["per_episode"]) == 2
    assert (out / "episode.png").stat().st_size > 10_000


def test_checkpoint_and_torchscript_act_alike(rsl_run: Path, sb3_run: Path) -> None:
    obs = np.random.default_rng(0).normal(size=(5, 48)).astype(np.float32)
    for run in (rsl_run, sb3_run):
        final = run / ("final_model.pt" if run == rsl_run else "final_model.zip")
        exported = load_policy(run / "policy_torchscript.pt")
        np.testing.assert_allclose(load_policy(final)(obs), exported(obs), atol=1e-5)


def test_sb3_zip_says_it_unpickles(sb3_run: Path, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="margin_rl.train"):
        load_policy(sb3_run / "final_model.zip")
    assert "pickle" in caplog.text and "trust" in caplog.text


def _torchscript(path: Path, inputs: int, outputs: int) -> Path:
    with torchscript_export():
        module = torch.jit.trace(torch.nn.Linear(inputs, outputs), torch.zeros(1, inputs))
        torch.jit.save(module, str(path))
    return path


@pytest.mark.parametrize(("inputs", "outputs", "message"), [(50, 12, "size 50.*gives 48"), (48, 8, "8 actions")])
def test_wrong_size_policy_is_a_clear_error(
    tmp_path: Path, inputs: int, outputs: int, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _torchscript(tmp_path / "policy.pt", inputs, outputs)
    with pytest.raises(PolicyMismatchError, match=message):
        evaluate(path, env_overrides={"margin": "none"}, out_dir=tmp_path / "out", **QUICK)
    assert main([str(path), "--margin", "none", "--out", str(tmp_path / "out")]) == 2
    assert "error:" in capsys.readouterr().err


def test_unrecognised_files(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("not a policy")
    with pytest.raises(ValueError, match="not a policy file"):
        detect_kind(tmp_path / "notes.txt")
    with pytest.raises(FileNotFoundError):
        detect_kind(tmp_path / "missing.pt")
    torch.save({"weights": torch.zeros(3)}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not an rsl-rl checkpoint"):
        load_policy(tmp_path / "other.pt")


@pytest.mark.filterwarnings("ignore::glfw.GLFWError")  # without MUJOCO_GL, GLFW finds no display: reported too
def test_video_without_imageio_gives_a_clear_message(
    rsl_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "imageio", None)  # imports of imageio now fail
    monkeypatch.setitem(sys.modules, "imageio.v2", None)
    report, _ = evaluate(
        rsl_run / "policy_torchscript.pt", out_dir=tmp_path, video=True, episodes=1, max_steps=3, warmup_s=0.0
    )
    assert report["video"] is None
    assert "imageio" in report["video_message"] or "MUJOCO_GL" in report["video_message"]


def test_metrics_that_cannot_be_computed_say_why(
    rsl_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Episodes shorter than the warm-up have no acceleration sample: "not computed" with the reason, never NaN."""
    out = tmp_path / "short"
    args = [str(rsl_run / "policy_torchscript.pt"), "--episodes", "2", "--max-steps", "5", "--out", str(out)]
    assert main(args) == 0  # 5 steps = 0.1 s, within the default 1 s warm-up
    printed = capsys.readouterr().out
    assert "nan" not in printed.lower()
    assert "lin_acc_rms: not computed (episode shorter than the RMS window" in printed
    report = json.loads((out / "metrics.json").read_text())
    assert report["summary"]["lin_acc_rms"]["mean"] is None and report["summary"]["lin_acc_rms"]["count"] == 0
    assert "shorter than the RMS window" in report["not_computed"]["ang_acc_rms"]
    assert "margin_mean" not in report["not_computed"] and report["summary"]["margin_mean"]["count"] == 2


def test_not_computed_reasons() -> None:
    from margin_rl.train.metrics import not_computed, summarize

    summary = summarize([{"lin_acc_rms": float("nan"), "margin_mean": 0.1, "speed_mean": float("nan")}])
    reasons = not_computed(summary, warmup_s=1.0)
    assert set(reasons) == {"lin_acc_rms", "speed_mean"} and "first 1 s" in reasons["lin_acc_rms"]
    assert reasons["speed_mean"] == "no episode reported a finite value"
    assert not_computed(summarize([{"lin_acc_rms": 2.0}])) == {}


def test_evaluation_condition_is_recorded_and_options_apply_on_top(rsl_run: Path) -> None:
    out = rsl_run / "eval" / "slippery"
    argv = [str(rsl_run / "final_model.pt"), "--episodes", "2", "--max-steps", "10", "--out", str(out)]
    assert main([*argv, "--condition", "friction_0.4", "--env-option", "reward_params.alive_bonus=0.3"]) == 0
    report = json.loads((out / "metrics.json").read_text())
    assert report["condition"] == "friction_0.4" and report["env_config"]["randomization"]["friction"] == [0.4, 0.4]
    assert report["env_config"]["reward_params"]["alive_bonus"] == 0.3
    report, _ = evaluate(rsl_run / "final_model.pt", out_dir=out, **QUICK)
    assert report["condition"] == "nominal" and report["env_config"]["randomization"]["friction"] is None
