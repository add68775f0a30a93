"""The rsl-rl adapter over a device core (Warp's CPU device): its step reads nothing from the host between two
reads of its statistics, which come once per rollout (the length the runner sets), as the means of what the
episodes that ended gave; rsl-rl's own loop is measured, not changed (its logger reads the host every step)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from benchmarks.tools.host_reads import DispatchCounter
from margin_rl.envs.config import RandomizationConfig
from tests.conftest import require_mujoco_warp

require_mujoco_warp()

from margin_rl.train import make_rsl_env  # noqa: E402

WARP_CPU = {"physics": "warp", "physics_device": "cpu"}
BUSY = {"randomization": RandomizationConfig(push_interval_s=0.1), "episode_length_s": 0.3}


def test_the_adapter_reads_the_host_once_per_rollout() -> None:
    env = make_rsl_env("margin_rl/AnymalC-v1", 8, seed=0, **WARP_CPU, **BUSY)
    env.set_rollout_length(24)
    assert env.core.check_every == 24
    actions = torch.zeros(8, 12)
    env.step(actions)  # warm-up
    counter, logs = DispatchCounter(), []
    for _ in range(22):  # steps 2-23 of the first rollout
        with counter:
            extras = env.step(actions)[3]
        logs.append(extras["log"])
    assert dict(counter.host_reads) == {}
    assert all(log == {} for log in logs)  # nothing read, nothing logged inside the rollout
    _, _, _, extras = env.step(actions)  # the rollout's last step: one read of the statistics
    log = extras["log"]
    assert {"Step/margin_mean", "Episode_Termination/timed_out", "Episode_Metrics/lin_acc_rms"} <= log.keys()
    timed_out = log["Episode_Termination/timed_out"]  # a value per episode that ended in the window (15 steps long)
    assert timed_out.shape[0] >= 8 and float(timed_out.mean()) > 0
    assert isinstance(log["Step/margin_mean"], float)
    assert all(np.isfinite(np.asarray(value)).all() for value in log.values())


def test_a_bad_rollout_length_is_refused() -> None:
    env = make_rsl_env("margin_rl/AnymalC-v1", 2, seed=0, **WARP_CPU)
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match="rollout length must be a whole number of steps >= 1"):
            env.set_rollout_length(bad)
