"""Training in several processes (torchrun, rsl-rl's distributed PPO), the project's side, on the CPU: the ranks read
from torchrun's variables, what a process may be asked to run, its device and seed, and a run folder written by rank
0 alone. rsl-rl's own distributed calls (the NCCL process group, its broadcasts and reductions) are stubbed: they
need GPUs, and they are rsl-rl's."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from margin_rl.train.commands import train as train_module
from margin_rl.train.distributed import Ranks
from tests.conftest import require_mujoco_warp


@given(world=st.integers(1, 64), data=st.data())
def test_ranks_come_from_torchruns_variables(world: int, data: st.DataObject) -> None:
    rank, local = data.draw(st.integers(0, world - 1)), data.draw(st.integers(0, world - 1))
    ranks = Ranks.from_environment({"WORLD_SIZE": str(world), "RANK": str(rank), "LOCAL_RANK": str(local)})
    assert (ranks.world_size, ranks.rank, ranks.local_rank) == (world, rank, local)
    assert ranks.distributed == (world > 1) and ranks.writes == (rank == 0)
    assert ranks.device == f"cuda:{local}" and ranks.seed(7) == 7 + rank


def test_one_process_without_torchrun() -> None:
    assert Ranks.from_environment({}) == Ranks() and not Ranks().distributed and Ranks().writes


@pytest.mark.parametrize(
    ("environ", "message"),
    [
        ({"WORLD_SIZE": "two"}, "WORLD_SIZE must be a whole number"),
        ({"WORLD_SIZE": "2", "RANK": "2"}, r"RANK must lie in 0..1"),
        ({"WORLD_SIZE": "2", "LOCAL_RANK": "-1"}, r"LOCAL_RANK must lie in 0..1"),
        ({"WORLD_SIZE": "0"}, "WORLD_SIZE must be >= 1"),
    ],
)
def test_bad_ranks_are_clear_errors(environ: dict[str, str], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Ranks.from_environment(environ)


def _spec(*argv: str) -> train_module.TrainSpec:
    spec, _, _ = train_module.spec_from_args(train_module.build_parser().parse_args(["--recipe", "none", *argv]))
    return spec


def test_a_process_runs_rsl_rl_and_warp_on_its_gpu() -> None:
    ranks = Ranks(world_size=2, rank=1, local_rank=1)
    spec, physics_device = train_module.for_rank(_spec(), ranks, "warp", None)
    assert spec.device == physics_device == "cuda:1"
    with pytest.raises(ValueError, match="use --backend rsl"):
        train_module.for_rank(_spec("--backend", "sb3"), ranks, "warp", None)
    with pytest.raises(ValueError, match="use --physics warp"):
        train_module.for_rank(_spec(), ranks, "mujoco", None)
    with pytest.raises(ValueError, match=r"process 1 runs on cuda:1 \(LOCAL_RANK 1\); leave --physics-device out"):
        train_module.for_rank(_spec(), ranks, "warp", "cuda:0")


def _stub_rsl_rl_distributed(monkeypatch: pytest.MonkeyPatch, rank: int) -> list[int]:
    """torchrun's variables for a two-process world, and rsl-rl's distributed setup and collectives made local:
    the process then trains on the CPU as rank ``rank`` would. Returns the seeds the environments are built with."""
    from rsl_rl.algorithms.ppo import PPO
    from rsl_rl.runners import OnPolicyRunner

    for name, value in (("WORLD_SIZE", "2"), ("RANK", str(rank)), ("LOCAL_RANK", str(rank))):
        monkeypatch.setenv(name, value)
    monkeypatch.setattr(Ranks, "device", property(lambda self: "cpu"))  # no GPU here: Warp's CPU device

    def configure(runner: OnPolicyRunner) -> None:  # rsl-rl's, without its NCCL group and device check
        runner.gpu_world_size, runner.is_distributed = 2, True
        runner.gpu_local_rank = runner.gpu_global_rank = rank
        runner.cfg["multi_gpu"] = {"global_rank": rank, "local_rank": rank, "world_size": 2}

    monkeypatch.setattr(OnPolicyRunner, "_configure_multi_gpu", configure)
    monkeypatch.setattr(PPO, "broadcast_parameters", lambda self: None)
    monkeypatch.setattr(PPO, "reduce_parameters", lambda self: None)
    monkeypatch.setattr(torch.distributed, "all_reduce", lambda *args, **kwargs: None)
    monkeypatch.setattr(torch.distributed, "broadcast", lambda *args, **kwargs: None)
    seeds: list[int] = []
    built = train_module.rsl_vec_env

    def recording(target, num_envs, seed, *args, **kwargs):
        seeds.append(seed)
        return built(target, num_envs, seed, *args, **kwargs)

    monkeypatch.setattr(train_module, "rsl_vec_env", recording)
    return seeds


def _tiny_spec() -> train_module.TrainSpec:
    spec = _spec("--num-envs", "4", "--total-steps", "64", "--checkpoint-every", "32", "--seed", "3")
    return dataclasses.replace(spec, ppo=dataclasses.replace(spec.ppo, num_steps_per_env=8))


@pytest.mark.parametrize("rank", [0, 1])
def test_rank_zero_alone_writes_the_run_folder(rank: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    require_mujoco_warp()
    seeds = _stub_rsl_rl_distributed(monkeypatch, rank)
    run_dir = tmp_path / "run"
    result = train_module.train(_tiny_spec(), run_dir, progress=False, physics="warp")
    assert seeds == [3 + rank]  # a seed per process
    written = sorted(str(p.relative_to(run_dir)) for p in run_dir.rglob("*") if p.is_file())
    if rank == 0:
        assert result.finished and result.final_model is not None and result.final_model.is_file()
        assert {"config.json", "progress.json"} <= set(written)
        assert any(name.startswith("checkpoints/ckpt_") for name in written)
        assert any(name.startswith("tb/") for name in written)
    else:
        assert result.finished and result.final_model is None and written == []
