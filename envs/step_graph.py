"""A core's step recorded once and replayed: on a CUDA device, one policy step (the actions copied in, the torch
stages, MuJoCo Warp's launches for the decimated physics, the masked reset and the forward pass) becomes one CUDA
graph, so the ~400 operations the step dispatches from Python (docs/studies/simulation_speed.md) cost one launch.

What makes the step recordable is the core's, checked on Warp's CPU device: it reads nothing from the host, draws a
fixed count of random numbers, keeps its state at fixed addresses and bakes no step-varying number of the host's
into its operations (the checks count steps on the device). What this module adds:

* **When.** :meth:`StepGraph.step` runs the first step after a (re)recording eagerly (lazy set-up: the network's
  weights, constants moved to the device, kernels loaded), records the next one and replays it, then replays. The
  core gives a key of what a recording bakes in besides its arrays (its config object, generator, terrain, the
  physics' count of ``set_const`` calls, episode length, autoreset and truncation); a new key records again. A
  pickled core is rebuilt without its graph.
* **How, on CUDA** (:class:`CudaStepRecorder`, the pattern of Warp's own torch interop tests): a non-blocking side
  stream shared by torch and Warp (torch refuses to capture on a blocking stream, and Warp's default stream is
  one); torch's capture begun there and registered with Warp as external, so MuJoCo Warp's solver loop
  (``capture_while``) becomes a conditional node instead of reading the host every iteration, and the physics
  launches its kernels into this capture instead of replaying its own graphs
  (:meth:`~margin_rl.envs.physics_warp.WarpPhysics.recorded_by_torch`); the core's generator registered with the
  graph, so that each replay draws new numbers.
* **If recording fails** (an operation torch or the driver cannot record), :meth:`StepGraph.step` warns once with
  the reason and steps eagerly from then on: training goes on, slower, with the same numbers.
* **What a replay returns.** The step's outputs live in the graph's memory and the next replay overwrites them, so
  the caller gets copies (one per output array): a learner keeps an observation across the next step (rsl-rl's
  transition holds it until the step after).

Not yet run on a GPU (no GPU was at hand where it was written): the CUDA recorder's parity with the eager step and
the determinism of replays are measured by ``benchmarks/speed/bench_gpu.py``. Eager steps stay available with the
physics option ``graphs=False`` (debugging: every operation launched from Python, Warp's graphs off too).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any, Protocol

from margin_rl.envs.step_data import StepOutput


class StepRecorder(Protocol):
    """Records a step once and replays it (:class:`CudaStepRecorder` on a CUDA device)."""

    def capture(self, body: Callable[[], StepOutput]) -> None:
        """Record ``body`` (runs nothing on the device)."""

    def replay(self) -> None:
        """Run what was recorded; :attr:`outputs` then holds this run's results."""

    @property
    def outputs(self) -> StepOutput:
        """The recorded step's outputs, at fixed addresses (valid after a replay, until the next)."""


class StepGraph:
    """The step of one core, recorded by a recorder of ``new_recorder(generator)`` and replayed (module
    docstring)."""

    def __init__(self, new_recorder: Callable[[Any], StepRecorder]) -> None:
        self._new_recorder = new_recorder
        self._key: tuple[Any, ...] | None = None
        self._recorder: StepRecorder | None = None
        self._actions: Any = None
        self.recordings = 0
        """How many times a step was recorded (a new key records again)."""
        self.failure: str | None = None
        """Why recording failed (the exception), after which every step runs eagerly; None while it has not."""

    def step(self, body: Callable[[Any], StepOutput], actions: Any, key: Any, rng: Any) -> StepOutput:
        """One step of ``body(actions)``: eager, recorded or replayed (module docstring). ``actions``: (N, 12) float64
        on the core's device; ``key``: a tuple of what the recording bakes in (objects, held here so that they stay
        themselves, compared by identity; numbers by value); ``rng``: the core's
        :class:`~margin_rl.arrays.TorchRandom`, whose generator a recording registers."""
        if self.failure is not None or _changed(self._key, key):  # eager: recording failed, or a new key's first step
            self._key, self._recorder = key, None
            return body(actions)
        if self._recorder is None:
            self._actions = actions.clone()  # the address the recording reads the actions at
            try:  # building the recorder too: a torch without what it needs fails here
                recorder = self._new_recorder(rng.generator)
                recorder.capture(lambda: body(self._actions))
            except Exception as exc:  # a recording runs nothing on the device: the step can still run eagerly
                self.failure = f"{type(exc).__name__}: {exc}"
                warnings.warn(
                    f"the environment step could not be recorded as a CUDA graph ({self.failure}); it runs eagerly "
                    "from now on, every operation launched from Python (slower, the same numbers); "
                    "physics_options={'graphs': False} turns every graph off.",
                    RuntimeWarning,
                    stacklevel=3,
                )
                return body(actions)
            self._recorder = recorder
            self.recordings += 1
        else:
            self._actions.copy_(actions)
        self._recorder.replay()
        return self._recorder.outputs.map_arrays(lambda array: array.clone())


def _changed(old: tuple[Any, ...] | None, new: tuple[Any, ...]) -> bool:
    """Whether key ``new`` differs from ``old``: an object by identity (a config replaced by an equal one still bakes
    in the same numbers, but identity is what the core can vouch for), a number or flag by value."""
    if old is None or len(old) != len(new):
        return True
    return any(a is not b and not (isinstance(a, (int, float)) and a == b) for a, b in zip(old, new, strict=True))


class CudaStepRecorder:
    """A step recorded as one CUDA graph with torch and MuJoCo Warp on one side stream (module docstring).
    ``physics``: the core's :class:`~margin_rl.envs.physics_warp.WarpPhysics`; ``generator``: the core's CUDA
    ``torch.Generator``."""

    def __init__(self, physics: Any, generator: Any) -> None:
        import torch

        self._torch = torch
        self._physics = physics
        self._device = generator.device
        self._stream = torch.cuda.Stream(device=self._device)  # torch's streams are non-blocking
        self._graph = torch.cuda.CUDAGraph()
        self._graph.register_generator_state(generator)
        self._outputs: StepOutput | None = None

    def capture(self, body: Callable[[], StepOutput]) -> None:
        torch = self._torch
        self._stream.wait_stream(torch.cuda.current_stream(self._device))  # what was queued before, first
        physics, stream = self._physics, self._stream
        # in this order (Warp's torch interop tests): Warp on torch's stream, torch's capture, Warp told of it
        with physics.on_torch_stream(stream), torch.cuda.graph(self._graph, stream=stream), physics.recorded_by_torch():
            self._outputs = body()
        torch.cuda.current_stream(self._device).wait_stream(self._stream)

    def replay(self) -> None:
        self._graph.replay()  # on the current stream, after what was queued there (the actions' copy)

    @property
    def outputs(self) -> StepOutput:
        if self._outputs is None:
            raise RuntimeError("nothing recorded yet: capture a step first")
        return self._outputs


def step_graph_for(physics: Any) -> StepGraph | None:
    """The step graph of a core over ``physics``: for MuJoCo Warp on a CUDA device with its graphs on (the default),
    else None (eager: the host's ``mujoco.batch``, Warp's CPU device, where torch records no graphs, or
    ``graphs=False``)."""
    if not getattr(physics, "graphs", False) or not getattr(physics, "on_cuda", False):
        return None
    return StepGraph(lambda generator: CudaStepRecorder(physics, generator))
