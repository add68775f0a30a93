"""The core's step as a recorded graph (``envs/step_graph.py``), on Warp's CPU device where torch records no graph:

* what makes a step recordable: every step after the first dispatches the same operations with the same host
  numbers in their arguments (a graph bakes those in: a step counter of the host's, passed into an operation, would
  freeze at the recorded step), random numbers drawn from the core's generator only (the one a recording registers),
  no array made from host data;
* :class:`StepGraph`'s sequence (an eager step, a recording, replays), the actions read at one address, the outputs
  copied out of the recording's memory, a new recording where the key changes, and the checks' step numbers counted
  on the device, with a recorder that replays by running the step again into outputs at fixed addresses (what a
  CUDA graph's replay does to its outputs).

The CUDA recorder itself runs only on a GPU: ``benchmarks/speed/bench_gpu.py`` compares it with eager steps there.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten

from margin_rl.envs.core import AnymalCore
from margin_rl.envs.step_data import StepOutput
from margin_rl.envs.step_graph import StepGraph, step_graph_for
from tests.conftest import require_mujoco_warp
from tests.envs.test_sync_free_step import BUSY, WARP_CPU, N, _busy_core

require_mujoco_warp()


class ArgumentTrace(TorchDispatchMode):
    """Every aten operation dispatched, with its arguments other than tensors (a tensor by its dtype and shape, a
    generator as such)."""

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[tuple[str, tuple[Any, ...]]] = []

    def __torch_dispatch__(self, func: Any, types: Any, args: tuple = (), kwargs: dict | None = None) -> Any:
        kwargs = kwargs or {}
        flat, _ = tree_flatten((args, kwargs))
        described = tuple(
            (a.dtype, tuple(a.shape))
            if isinstance(a, torch.Tensor)
            else "generator"
            if isinstance(a, torch.Generator)
            else repr(a)
            for a in flat
        )
        self.calls.append((func.overloadpacket.__name__, described))
        return func(*args, **kwargs)


def test_every_step_dispatches_the_same_operations_with_the_same_host_numbers() -> None:
    core = _busy_core()
    actions = torch.as_tensor(np.random.default_rng(3).uniform(-1, 1, (20, N, 12)))
    traces, generators = [], []
    for a in actions:
        trace = ArgumentTrace()
        with trace:
            core.step(a)
        traces.append(trace.calls)
        generators.append(sum(1 for _, args in trace.calls if "generator" in args))
    differing = [
        (k, first, later)
        for k, trace in enumerate(traces[1:], start=1)
        for first, later in zip(traces[0], trace, strict=True)
        if first != later
    ]
    assert differing == [], differing[:3]
    random_ops = sum(1 for name, _ in traces[0] if name in {"rand", "randint", "exponential_", "normal_"})
    assert generators[0] == random_ops > 0 and len(set(generators)) == 1  # every draw from a generator passed in
    assert core.rng.generator.device == core.device


def test_a_step_makes_no_array_from_host_data(monkeypatch: pytest.MonkeyPatch) -> None:
    """A copy from the host's pageable memory cannot be recorded in a CUDA graph: after the first step (which moves
    the constants to the device once) a step converts only tensors."""
    core = _busy_core()
    calls: list[tuple[str, str]] = []
    for name in ("as_tensor", "tensor", "from_numpy", "asarray"):
        original = getattr(torch, name)

        def spy(*args: Any, _original: Any = original, _name: str = name, **kwargs: Any) -> Any:
            calls.append((_name, type(args[0]).__name__ if args else "none"))
            return _original(*args, **kwargs)

        monkeypatch.setattr(torch, name, spy)
    for _ in range(3):
        core.step(torch.zeros(N, 12))
    assert calls and all(kind == "Tensor" for _, kind in calls), sorted(set(calls))


class RerunRecorder:
    """A stand-in for a CUDA graph on the CPU: ``capture`` runs nothing, ``replay`` runs the step again and writes
    its results into the outputs of the first replay, in place (a graph's outputs keep their addresses)."""

    def __init__(self) -> None:
        self.body: Callable[[], StepOutput] | None = None
        self._outputs: StepOutput | None = None
        self.replays = 0

    def capture(self, body: Callable[[], StepOutput]) -> None:
        self.body = body

    def replay(self) -> None:
        assert self.body is not None
        result = self.body()
        self.replays += 1
        if self._outputs is None:
            self._outputs = result
            return
        for fixed, fresh in zip(_arrays(self._outputs), _arrays(result), strict=True):
            fixed.copy_(fresh)

    @property
    def outputs(self) -> StepOutput:
        assert self._outputs is not None
        return self._outputs


def _arrays(output: StepOutput) -> list[torch.Tensor]:
    """Every array of ``output``, in :meth:`StepOutput.map_arrays`'s order."""
    found: list[torch.Tensor] = []

    def keep(array: torch.Tensor) -> torch.Tensor:
        found.append(array)
        return array

    output.map_arrays(keep)
    return found


def _recorded(core: AnymalCore) -> list[RerunRecorder]:
    recorders: list[RerunRecorder] = []

    def new_recorder(generator: torch.Generator) -> RerunRecorder:
        assert generator is core.rng.generator
        recorders.append(RerunRecorder())
        return recorders[-1]

    core._step_graph = StepGraph(new_recorder)
    return recorders


def test_a_recorded_step_replays_the_eager_numbers_and_hands_out_copies() -> None:
    eager, graphed = _busy_core(), _busy_core()
    recorders = _recorded(graphed)
    actions = torch.as_tensor(np.random.default_rng(4).uniform(-1, 1, (16, N, 12)))
    kept: list[tuple[StepOutput, list[torch.Tensor]]] = []
    for a in actions:
        expected, got = eager.step(a), graphed.step(a.clone())
        for want, have in zip(_arrays(expected), _arrays(got), strict=True):
            torch.testing.assert_close(have, want, rtol=0, atol=0)
        kept.append((got, [t.clone() for t in _arrays(got)]))
    assert len(recorders) == 1 and recorders[0].replays == len(actions) - 1  # the first step eager
    for got, values in kept:  # what a step handed out is not overwritten by the steps after
        for now, then in zip(_arrays(got), values, strict=True):
            torch.testing.assert_close(now, then, rtol=0, atol=0)
    assert graphed.steps_taken == eager.steps_taken == len(actions) + 1


def test_a_new_config_generator_episode_length_or_physics_arrays_record_the_step_again() -> None:
    core = _busy_core()
    recorders = _recorded(core)
    zeros = torch.zeros(N, 12)
    for _ in range(3):
        core.step(zeros)
    assert len(recorders) == 1
    core.reconfigure(core.config.replace(action_scale=0.3))
    core.step(zeros)  # eager, under the new key
    assert len(recorders) == 1
    core.step(zeros)
    assert len(recorders) == 2
    core.reset(seed=5)  # a new generator
    core.step(zeros)
    core.step(zeros)
    core.max_episode_steps = 7
    core.step(zeros)
    core.step(zeros)
    assert len(recorders) == 4
    core.physics.set_const()  # the physics' arrays may have moved
    core.step(zeros)
    core.step(zeros)
    assert len(recorders) == 5
    core.step(zeros)
    assert len(recorders) == 5


def test_a_replayed_step_names_the_step_of_a_nan_action() -> None:
    core = AnymalCore(BUSY, 4, seed=0, **WARP_CPU)
    _recorded(core)
    core.check_every = 6
    core.reset(seed=0)
    actions = torch.zeros(4, 12)
    for _ in range(3):
        core.step(actions)  # eager, recorded, replayed
    bad = actions.clone()
    bad[1, 0] = float("inf")
    core.step(bad)  # step 3, replayed
    core.step(actions)
    with pytest.raises(ValueError, match=r"action is not finite in 1 environment\(s\) \[1\], first at step 3"):
        core.step(actions)


class FailingRecorder(RerunRecorder):
    def capture(self, body: Callable[[], StepOutput]) -> None:
        raise RuntimeError("operation not permitted when stream is capturing")


def test_a_step_that_cannot_be_recorded_warns_once_and_runs_eagerly() -> None:
    eager, graphed = _busy_core(), _busy_core()
    graphed._step_graph = StepGraph(lambda generator: FailingRecorder())
    actions = torch.as_tensor(np.random.default_rng(5).uniform(-1, 1, (6, N, 12)))
    expected, got = eager.step(actions[0]), graphed.step(actions[0])  # eager: the key's first step
    with pytest.warns(RuntimeWarning, match=r"could not be recorded.*not permitted when stream is capturing"):
        expected, got = eager.step(actions[1]), graphed.step(actions[1])
    torch.testing.assert_close(got.observation, expected.observation, rtol=0, atol=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once only
        for a in actions[2:]:
            expected, got = eager.step(a), graphed.step(a)
            torch.testing.assert_close(got.reward, expected.reward, rtol=0, atol=0)
    assert graphed._step_graph.failure is not None and graphed._step_graph.recordings == 0


def test_only_a_cuda_device_records_steps() -> None:
    assert step_graph_for(_busy_core().physics) is None  # Warp's CPU device: torch records no graph there
    assert AnymalCore(BUSY, 2, seed=0)._step_graph is None  # mujoco.batch
