"""margin_rl.train.metrics on a device's tensors: the episode sums kept where the environment's arrays are give the
metrics the host's numpy sums give (the hand-checked cases are in tests/train/backends/test_backends.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.envs.terminations import CAUSE_NAMES
from margin_rl.train.metrics import (
    METRIC_LABELS,
    SUMMARY_METRICS,
    TERRAIN_METRICS,
    EpisodeStatistics,
    comparison_metrics,
    step_tags,
    table_metrics,
)

N = 6


def step_info(rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {
        "reward_velocity_tracking": rng.uniform(0, 1, N),
        "reward_margin": rng.normal(0, 0.1, N),
        "margin": rng.normal(0, 0.1, N),
        "base_lin_acc": rng.normal(0, 5, (N, 3)),
        "base_ang_acc": rng.normal(0, 20, (N, 3)),
        "base_lin_vel": rng.normal(0.5, 0.2, (N, 3)),
        "velocity_error": rng.uniform(0, 0.5, N),
        "stance_width": rng.uniform(0.3, 0.5, N),
        "base_height": rng.uniform(0.4, 0.6, N),
        "touchdowns": rng.integers(0, 3, N).astype(float),
        "edge_touchdowns": rng.integers(0, 2, N).astype(float),
        "joint_torque_sq": rng.uniform(0, 900, N),
        "torque_at_limit": (rng.random(N) < 0.05).astype(float),
        "fell": (rng.random(N) < 0.1).astype(float),
        "diverged": np.zeros(N),
        "termination_base_contact": (rng.random(N) < 0.1).astype(float),
    }


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), warmup=st.integers(0, 3))
def test_episode_statistics_on_tensors_equal_numpys(seed: int, warmup: int) -> None:
    rng = np.random.default_rng(seed)
    host = EpisodeStatistics(N, 0.02, warmup_steps=warmup)
    device = EpisodeStatistics(N, 0.02, warmup_steps=warmup, reference=torch.zeros(1))
    ended = 0
    for _ in range(25):
        info, reward = step_info(rng), rng.normal(size=N)
        terminated, truncated = rng.random(N) < 0.1, rng.random(N) < 0.05
        expected = host.update(reward, info, terminated, truncated)
        got = device.update(
            torch.from_numpy(reward),
            {k: torch.from_numpy(v) for k, v in info.items()},
            torch.from_numpy(terminated),
            torch.from_numpy(truncated),
        )
        assert sorted(got) == sorted(expected)
        for key, values in expected.items():
            assert isinstance(got[key], np.ndarray)  # finished episodes come back to the host
            np.testing.assert_allclose(got[key], values, rtol=1e-12, atol=1e-12, err_msg=key)
        ended += len(expected.get("env", []))
        tags, tags_t = step_tags(info), step_tags({k: torch.from_numpy(v) for k, v in info.items()})
        assert tags_t.keys() == tags.keys() and all(abs(tags_t[k] - v) < 1e-12 for k, v in tags.items())
    info, reward, running = step_info(rng), rng.normal(size=N), np.zeros(N, dtype=bool)  # every episode >= 1 step
    host.update(reward, info, running, running)
    on_device = {k: torch.from_numpy(v) for k, v in info.items()}
    device.update(torch.from_numpy(reward), on_device, torch.from_numpy(running), torch.from_numpy(running))
    closed = host.close(np.arange(N), info)
    closed_t = device.close(torch.arange(N), {k: torch.from_numpy(v) for k, v in info.items()})
    for key, values in closed.items():
        np.testing.assert_allclose(closed_t[key], values, rtol=1e-12, atol=1e-12, err_msg=key)
    assert ended > 0  # the comparison met finished episodes, not only running sums


def test_the_comparison_columns_add_the_fall_causes_and_edge_landings_off_flat_ground() -> None:
    assert comparison_metrics("flat") == SUMMARY_METRICS
    assert comparison_metrics("rough") == METRIC_LABELS == {**SUMMARY_METRICS, **TERRAIN_METRICS}
    causes = {key.removeprefix("termination/") for key in TERRAIN_METRICS if key.startswith("termination/")}
    assert causes == set(CAUSE_NAMES) - {"diverged"}  # every fall cause, from the terminations' own list
    # a report's columns are the labelled metrics it has a mean of, in table order; unknown keys are not columns
    variants = {"a": {"mean": {"fell": 0.1, "edge_landing_fraction": 0.2, "return": 3.0, "lin_acc_rms": 1.0}}}
    assert list(table_metrics(variants)) == ["lin_acc_rms", "fell", "edge_landing_fraction"]


def test_margin_reward_share_is_the_margin_terms_part_of_the_episodes_reward() -> None:
    """Two steps of a margin term of -0.1 and +0.3 (sum 0.2) beside a tracking term of 0.4 per step (sum 0.8) and a
    penalty of -0.5 per step (sum -1.0): |0.2| / (0.2 + 0.8 + 1.0) = 0.1, whatever the signs."""
    stats = EpisodeStatistics(num_envs=1, dt=0.02)
    base = step_info(np.random.default_rng(0))
    for k, margin_term in enumerate((-0.1, 0.3)):
        info = {key: value[:1] for key, value in base.items() if not key.startswith("reward_")}
        info |= {
            "reward_velocity_tracking": np.array([0.4]),
            "reward_margin": np.array([margin_term]),
            "reward_torques": np.array([-0.5]),
        }
        out = stats.update(np.array([0.0]), info, np.array([k == 1]), np.array([False]))
    assert out["margin_reward_share"][0] == pytest.approx(0.1)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), warmup=st.integers(0, 3))
def test_accumulated_windows_are_the_means_over_the_episodes_that_ended(seed: int, warmup: int) -> None:
    """accumulate() on a device's tensors, with no host read, then one drain() per window: each metric's mean over
    the episodes that ended in the window, where finite; the same as update()'s per-episode values averaged."""
    from benchmarks.tools.host_reads import DispatchCounter

    rng = np.random.default_rng(seed)
    host = EpisodeStatistics(N, 0.02, warmup_steps=warmup)
    device = EpisodeStatistics(N, 0.02, warmup_steps=warmup, reference=torch.zeros(1))
    for _ in range(3):  # windows
        ended: dict[str, list[float]] = {}
        counter = DispatchCounter()
        for _ in range(9):
            info, reward = step_info(rng), rng.normal(size=N)
            terminated, truncated = rng.random(N) < 0.15, rng.random(N) < 0.05
            for key, values in host.update(reward, info, terminated, truncated).items():
                ended.setdefault(key, []).extend(values[np.isfinite(values)])
            on_device = {k: torch.from_numpy(v) for k, v in info.items()}
            with counter:
                device.accumulate(
                    torch.from_numpy(reward), on_device, torch.from_numpy(terminated), torch.from_numpy(truncated)
                )
        assert dict(counter.host_reads) == {}
        drained = device.drain()
        expected = {key: values for key, values in ended.items() if key != "env" and values}
        assert drained.keys() == expected.keys()
        for key, values in expected.items():
            mean, count = drained[key]
            assert count == len(values) and mean == pytest.approx(np.mean(values), rel=1e-12, abs=1e-12), key
    assert device.drain() == {}  # nothing ended since
