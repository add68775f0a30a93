"""benchmarks/speed/bench_gpu.py --smoke: every stage of the GPU benchmark, small, on Warp's CPU device, so that the
script a GPU session runs once is known to run to its end and to write its record."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from tests.conftest import require_mujoco_warp

require_mujoco_warp()

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks

from benchmarks.speed import bench_gpu  # noqa: E402


def test_every_stage_runs_small_on_warps_cpu_device_and_writes_its_record(tmp_path: Path) -> None:
    assert bench_gpu.main(["--smoke", "--out", str(tmp_path), "--runs-root", str(tmp_path / "runs")]) == 0
    record = json.loads((tmp_path / bench_gpu.JSON_NAME).read_text())
    assert record["settings"]["smoke"] and record["settings"]["device"] == "cpu" and record["gpu"] is None
    stages = record["stages"]
    assert list(stages) == ["graph_parity", "physics_and_env", "ppo", "training"]
    parity = stages["graph_parity"]  # on Warp's CPU device both cores step eagerly: the same numbers, bit for bit
    assert not parity["recorded"] and len(parity["per_step"]) == bench_gpu.SMOKE["parity_steps"]
    assert all(value == 0 for pair in parity["max"].values() for value in pair.values()), parity["max"]
    for size in map(str, bench_gpu.SMOKE["num_envs"]):
        rates = stages["physics_and_env"][size]["env_steps_per_s"]
        assert set(rates) == {"physics", "env_learned", "env_no_margin"} and min(rates.values()) > 0
        assert stages["ppo"][size]["env_steps_per_s"] > 0
    for variant in ("margin_weight_0", "margin_weight_0.1"):
        run = stages["training"][variant]
        assert run["env_steps"] == bench_gpu.SMOKE["train_steps"] and Path(run["final_model"]).is_file()
        steps = [row["env_steps"] for row in run["checkpoints"]]
        assert steps == sorted(set(steps)) and steps[-1] == run["env_steps"]  # each checkpoint once, the last too
        assert all(0 <= row["falls"] <= 1 and row["velocity_error"] >= 0 for row in run["checkpoints"])
    assert all(stages[name]["complete"] for name in stages)
    # the modules Warp compiled in the run (none where its cache already held them) and their seconds
    assert all(isinstance(name, str) and seconds >= 0 for name, seconds in record["warp_modules_compiled"])
    assert record["warp_compile_seconds"] >= 0 and "warp_cache_path" in record


def test_a_stage_that_raises_is_recorded_with_its_traceback_and_the_next_stage_still_runs(
    tmp_path: Path, monkeypatch
) -> None:
    def broken_physics(sizes, steps, rounds, device, partial, env_id, recipe, step_graph):
        partial({"4": {"env_steps_per_s": {"physics": 1.0}}})  # one size measured before the failure
        raise RuntimeError("graph capture failed")

    monkeypatch.setattr(bench_gpu, "physics_and_env", broken_physics)
    monkeypatch.setattr(bench_gpu, "ppo", lambda *args: {"4": {"env_steps_per_s": 2.0}})
    argv = ["--smoke", "--out", str(tmp_path), "--stages", "physics_and_env", "ppo"]
    assert bench_gpu.main(argv) == 1
    stages = json.loads((tmp_path / bench_gpu.JSON_NAME).read_text())["stages"]
    failed = stages["physics_and_env"]
    assert failed["error"] == "RuntimeError: graph capture failed" and "broken_physics" in failed["traceback"]
    assert failed["4"]["env_steps_per_s"]["physics"] == 1.0 and not failed["complete"]  # what was measured is kept
    assert stages["ppo"] == {"4": {"env_steps_per_s": 2.0}, "complete": True}


def test_the_rough_recipes_environment_runs_its_stages_on_warps_cpu_device(tmp_path: Path) -> None:
    argv = ["--smoke", "--env", "margin_rl/AnymalC-Rough-v1", "--recipe", "rough", "--stages", "physics_and_env"]
    assert bench_gpu.main([*argv, "--out", str(tmp_path)]) == 0
    record = json.loads((tmp_path / bench_gpu.JSON_NAME).read_text())
    assert record["settings"]["env_id"] == "margin_rl/AnymalC-Rough-v1" and record["settings"]["recipe"] == "rough"
    assert list(record["stages"]) == ["physics_and_env"] and record["stages"]["physics_and_env"]["complete"]


def test_the_core_profile_counts_the_operations_of_a_step(capsys) -> None:
    """The profile of the device step: its operations, no host read, the same random draws every step."""
    from benchmarks.speed import profile_core_ops

    assert profile_core_ops.main(["--num-envs", "2", "--steps", "2", "--top", "3"]) == 0
    out = capsys.readouterr().out
    summary, rows = out.splitlines()[0], [line for line in out.splitlines() if line.startswith("| `")]
    assert "environments on Warp's CPU device, per step:" in summary and "0.0 host reads" in summary
    counts = re.search(r"([\d,]+) aten operations dispatched \(([\d,]+) views, ([\d,]+) kernels\)", summary)
    total, views, kernels = (int(group.replace(",", "")) for group in counts.groups())
    assert len(rows) == 3 and total > 100 and views + kernels == total and views > 0
    assert re.search(r"the kernels read and write [\d.]+ MiB per step, [\d.]+ KiB per environment", summary)
    assert "rsl-rl's loop" not in out  # only with --rsl
