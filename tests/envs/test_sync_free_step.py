"""The device step reads nothing from the host (Warp's CPU device, where every host read is dispatched as on a GPU):
no synchronising operation in a window of steps with pushes starting and environments resetting, the same work and
the same random draws every step, the state at fixed addresses, and the checks it defers (a NaN action, a non-finite
output) raised at the next read, naming the step and the environment. On the host the same code, asked to step as a
device does (``sync_free``), gives the default path's numbers where both draw nothing."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from benchmarks.tools.host_reads import DispatchCounter
from margin_rl.envs.config import EnvConfig, RandomizationConfig
from margin_rl.envs.core import AnymalCore
from tests.conftest import require_mujoco_warp

require_mujoco_warp()

WARP_CPU = {"physics": "warp", "physics_device": "cpu"}
N = 16
BUSY = EnvConfig(
    robot="anymal_c",
    randomization=RandomizationConfig(friction=(0.4, 1.0), push_interval_s=0.1),
    episode_length_s=0.3,
)
"""Pushes starting every few steps and episodes of 15 steps: a window of 30 steps sees both, in most steps."""


def _busy_core(**options: object) -> AnymalCore:
    core = AnymalCore(BUSY, N, seed=0, **WARP_CPU, **options)
    core.check_every = 10_000  # no read inside the window
    core.reset(seed=0)
    core.step(torch.zeros(N, 12))  # warm-up: kernels loaded, first pushes drawn
    return core


def test_a_device_step_reads_nothing_from_the_host() -> None:
    core = _busy_core()
    actions = torch.as_tensor(np.random.default_rng(0).uniform(-1, 1, (N, 12)))
    counter, per_step, draws, done, pushed = DispatchCounter(), [], [], [], []
    for _ in range(30):
        ops, numbers = counter.total, counter.random_numbers
        with counter:
            out = core.step(actions)
        per_step.append(counter.total - ops)
        draws.append(counter.random_numbers - numbers)
        done.append(out.terminated | out.truncated)  # read after the window
        pushed.append(core._push_steps_left > 0)
    assert dict(counter.host_reads) == {}
    assert len(set(per_step)) == 1, per_step  # the same operations whether or not anything resets or is pushed
    assert len(set(draws)) == 1 and draws[0] > 0, draws
    assert int(torch.stack(done).sum()) > 0 and int(torch.stack(pushed).sum()) > 0  # the window covered both


def test_the_device_state_keeps_its_addresses() -> None:
    """Every state tensor and the physics' live arrays are updated in place (what a recorded graph replays)."""
    core = _busy_core()
    tensors = {name: getattr(core, name) for name in AnymalCore._STATE if isinstance(getattr(core, name), torch.Tensor)}
    tensors |= {name: getattr(core.physics, name) for name in ("qpos", "qvel", "ctrl", "xfrc_applied", "time")}
    addresses = {name: t.data_ptr() for name, t in tensors.items()}
    for _ in range(20):
        core.step(torch.zeros(N, 12))
    now = {name: getattr(core, name) for name in AnymalCore._STATE if name in tensors}
    now |= {name: getattr(core.physics, name) for name in ("qpos", "qvel", "ctrl", "xfrc_applied", "time")}
    assert [name for name, t in now.items() if t.data_ptr() != addresses[name]] == []
    assert int(core.steps_taken) == 21


def test_a_nan_action_between_two_reads_is_raised_at_the_next_naming_step_and_environment() -> None:
    core = AnymalCore(BUSY, 4, seed=0, **WARP_CPU)
    core.check_every = 5
    core.reset(seed=0)
    actions = torch.zeros(4, 12)
    core.step(actions)
    core.step(actions)
    bad = actions.clone()
    bad[3, 7] = float("nan")
    core.step(bad)  # step 2: recorded on the device, the physics stepped with 0 in its place
    assert torch.isfinite(core.physics.qpos).all()
    core.step(actions)
    with pytest.raises(ValueError, match=r"action is not finite in 1 environment\(s\) \[3\], first at step 2"):
        core.step(actions)  # the fifth step reads the flags


def test_a_non_finite_output_is_raised_at_the_next_read_with_what_to_change() -> None:
    noise = RandomizationConfig(observation_noise=1e41)  # float32 observations overflow to inf
    core = AnymalCore(EnvConfig(robot="anymal_c", randomization=noise), 2, seed=0, **WARP_CPU)
    core.check_every = 3
    core.reset(seed=0)
    core.step(torch.zeros(2, 12))
    core.step(torch.zeros(2, 12))
    expected = r"observation is not finite in 2 environment\(s\) \[0, 1\], first at step 0.*observation_noise=1e"
    with pytest.raises(FloatingPointError, match=expected):
        core.step(torch.zeros(2, 12))


def test_the_host_stepping_as_a_device_gives_the_default_numbers_where_nothing_is_drawn() -> None:
    """mujoco.batch with ``sync_free`` (masked resets, a draw per environment) against its default step, no pushes
    and no episode ending: the same numbers bit for bit (the default path keeps its random stream elsewhere)."""
    config = EnvConfig(robot="anymal_c")
    default, masked = AnymalCore(config, 4, seed=1), AnymalCore(config, 4, seed=1)
    masked.sync_free = True
    for core in (default, masked):
        core.reset(seed=1)
    actions = np.random.default_rng(1).uniform(-0.5, 0.5, (12, 4, 12))
    for a in actions:
        expected, got = default.step(a), masked.step(a)
        np.testing.assert_array_equal(got.observation, expected.observation)
        np.testing.assert_array_equal(got.reward, expected.reward)
        for key, value in expected.info.items():
            np.testing.assert_array_equal(got.info[key], value, err_msg=key)


def test_the_recorded_graphs_replay_what_eager_launches() -> None:
    """The physics' three graphs (decimated step, masked reset, forward), recorded on Warp's CPU device and replayed,
    against every call launched eagerly (``graphs=False``): the same numbers bit for bit, over steps with pushes,
    autoresets and a reset asked for by ids."""
    replayed, eager = _busy_core(), _busy_core(physics_options={"graphs": False})
    assert set(replayed.physics._graphs) == {("step", 4), "reset", "forward"} and not eager.physics._graphs
    actions = torch.as_tensor(np.random.default_rng(2).uniform(-1, 1, (25, N, 12)))
    for k, a in enumerate(actions):
        if k == 12:
            for core in (replayed, eager):
                core.reset(np.array([2, 9]))
        expected, got = eager.step(a), replayed.step(a)
        torch.testing.assert_close(got.observation, expected.observation, rtol=0, atol=0)
        torch.testing.assert_close(got.reward, expected.reward, rtol=0, atol=0)
    for name in ("qpos", "qvel", "time", "sensordata"):
        torch.testing.assert_close(getattr(replayed.physics, name), getattr(eager.physics, name), rtol=0, atol=0)


@pytest.mark.parametrize("terrain", ["flat", "rough"])
def test_the_critic_of_a_device_step_sees_the_state_after_its_resets(terrain: str) -> None:
    """A device step looks the scan's and the critic's ground up in one lookup after its masked reset, from that
    reset's read: its critic observation equals the one read afresh after the step, bit for bit, on steps where
    episodes end (mujoco.batch stepping as a device does)."""
    config = EnvConfig(
        robot="anymal_c", terrain=terrain, height_scan=True, privileged_observations=True, episode_length_s=0.1
    )
    core = AnymalCore(config, 4, seed=3)
    core.sync_free = True
    core.reset(seed=3)
    ended = 0
    for a in np.random.default_rng(3).uniform(-1, 1, (12, 4, 12)):
        out = core.step(a)
        done = out.truncated | out.terminated
        np.testing.assert_array_equal(out.privileged, core.privileged_observation())
        np.testing.assert_array_equal(out.observation[done], core.observe_all()[done])  # the scan, looked up with it
        ended += int(np.sum(done))
    assert ended > 0
