"""Warp kernels compiled ahead of time (envs.warp_kernels): the launches recorded with the block sizes a GPU would
use, a cache compiled for Warp's CPU device that a fresh process then loads without compiling anything, and an
sm_90 cache (cubin and PTX) compiled on this machine, which has no GPU."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import require_mujoco_warp

require_mujoco_warp()

import warp as wp  # noqa: E402 -- after the check that Warp is installed

from margin_rl.envs.warp_kernels import (  # noqa: E402
    CUDA_DEFAULT_BLOCK_DIM,
    compile_ahead,
    record_launches,
    write_report,
)

ROOT = Path(__file__).resolve().parents[2]


@wp.kernel
def _scale(x: wp.array(dtype=float), factor: float):
    i = wp.tid()
    x[i] = x[i] * factor


@wp.kernel
def _first_lane_adds(x: wp.array(dtype=float)):
    i, lane = wp.tid()
    if lane == 0:
        x[i] = x[i] + 1.0


def launch_both() -> None:
    """One plain launch (no block size asked) and one tiled launch (64 threads per block), on Warp's CPU device."""
    x = wp.ones(8, dtype=float, device="cpu")
    wp.launch(_scale, dim=8, inputs=[x, 2.0], device="cpu")
    wp.launch_tiled(_first_lane_adds, dim=[8], inputs=[x], block_dim=64, device="cpu")
    assert x.numpy().tolist() == [3.0] * 8


def test_launches_are_recorded_with_the_block_size_a_gpu_would_use() -> None:
    launch, launch_tiled = wp.launch, wp.launch_tiled
    variants = record_launches(launch_both)
    assert {v.block_dim for v in variants} == {CUDA_DEFAULT_BLOCK_DIM, 64}  # not the CPU's 1
    assert {v.module.name for v in variants} == {_scale.module.name}
    assert (wp.launch, wp.launch_tiled) == (launch, launch_tiled)  # restored


def test_a_cache_compiled_ahead_for_the_cpu_loads_in_a_fresh_process_without_compiling(tmp_path: Path) -> None:
    report = compile_ahead(record_launches(launch_both), tmp_path, arch=None)
    assert len(report.modules) == 1 and report.failed == () and report.modules[0].files
    assert all(f.endswith(".o") for f in report.modules[0].files)
    path = write_report(report, "tiny")
    assert json.loads(path.read_text())["failed"] == 0
    script = (
        "from margin_rl.envs.warp_kernels import counting_compiles\n"
        "from tests.envs.test_warp_kernels import launch_both\n"
        "with counting_compiles() as compiled:\n"
        "    launch_both()\n"
        "print('compiled', len(compiled))\n"
    )

    def compiled_in_a_fresh_process(cache: Path) -> str:
        env = {**os.environ, "WARP_CACHE_PATH": str(cache), "CUDA_VISIBLE_DEVICES": ""}
        run = subprocess.run(
            [sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300
        )
        assert run.returncode == 0, run.stderr[-2000:]
        return run.stdout.strip().splitlines()[-1]

    assert compiled_in_a_fresh_process(tmp_path) == "compiled 0"
    assert compiled_in_a_fresh_process(tmp_path / "empty") == "compiled 1"  # the same module, no cache: compiled


def test_an_sm90_cache_holds_cubin_and_ptx_compiled_without_a_gpu(tmp_path: Path) -> None:
    report = compile_ahead(record_launches(launch_both), tmp_path, arch=90)
    assert report.failed == () and len(report.modules) == 2  # one module, at 256 and at 64 threads per block
    for module in report.modules:
        assert sorted(Path(f).name.removeprefix(module.identifier) for f in module.files) == [
            ".sm90.cubin",
            ".sm90.ptx",
        ]
        assert all((tmp_path / wp.config.version / f).stat().st_size > 0 for f in module.files)
    assert report.size_mib > 0


def test_an_unknown_format_is_refused() -> None:
    with pytest.raises(ValueError, match="formats must be some of"):
        compile_ahead([], "unused", arch=90, formats=("sass",))
