"""Run directories: names, atomic file writes, checkpoints, progress records and graceful interruption.

Layout of a run directory::

    <run>/config.json          environment (``env_config``), PPO and run settings (read by --resume)
    <run>/progress.json        steps and iterations done, finished/interrupted, latest checkpoint
    <run>/checkpoints/ckpt_<steps>.pt|.zip   full training state every --checkpoint-every steps and on stop
    <run>/tb/                  TensorBoard events (a resumed run appends to the same folder)
    <run>/final_model.pt|.zip  the final checkpoint (rsl-rl / SB3), <run>/policy_torchscript.pt its actor

Every file is written to a temporary name in the same folder and moved into place with ``os.replace``, so a
run killed at any moment leaves either the old or the new file, never a truncated one.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import re
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from types import FrameType
from typing import Any

import torch

from margin_rl.atomic import atomic_write

CONFIG_FILE = "config.json"
PROGRESS_FILE = "progress.json"
CHECKPOINT_DIR = "checkpoints"
TENSORBOARD_DIR = "tb"
TORCHSCRIPT_FILE = "policy_torchscript.pt"
_CKPT = re.compile(r"^ckpt_(\d+)\.(pt|zip)$")


def run_name(env_id: str, backend: str, margin_weight: float, seed: int, when: float | None = None) -> str:
    """``<env>__<backend>__mw<weight>__s<seed>__<YYYYmmdd-HHMMSS>`` (the id's namespace dropped)."""
    env = env_id.split("/")[-1].replace(":", "_")
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(when if when is not None else time.time()))
    return f"{env}__{backend}__mw{margin_weight:g}__s{seed}__{stamp}"


def final_model_name(backend: str) -> str:
    """File name of the final model in a run directory: ``final_model.pt`` (rsl) or ``final_model.zip`` (sb3)."""
    return "final_model.zip" if backend == "sb3" else "final_model.pt"


def write_json(path: str | Path, data: Any) -> Path:
    """Atomically write ``data`` as indented JSON (non-finite floats as null)."""
    text = json.dumps(_finite(data), indent=2, sort_keys=False) + "\n"
    return atomic_write(path, lambda f: f.write(text.encode()))


def _finite(data: Any) -> Any:
    if isinstance(data, float):
        return data if data == data and abs(data) != float("inf") else None
    if isinstance(data, dict):
        return {str(k): _finite(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [_finite(v) for v in data]
    return data


def read_json(path: str | Path) -> Any:
    """JSON file contents, with a clear error when missing or malformed."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: malformed JSON ({exc})") from exc


def checkpoint_path(run_dir: str | Path, steps: int, backend: str) -> Path:
    """``<run>/checkpoints/ckpt_<steps, 12 digits>.pt|.zip``."""
    suffix = "zip" if backend == "sb3" else "pt"
    return Path(run_dir) / CHECKPOINT_DIR / f"ckpt_{int(steps):012d}.{suffix}"


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The checkpoint with the most environment steps in a run directory, or None."""
    folder = Path(run_dir) / CHECKPOINT_DIR
    if not folder.is_dir():
        return None
    found = [(int(m.group(1)), p) for p in folder.iterdir() if (m := _CKPT.match(p.name))]
    return max(found)[1] if found else None


def checkpoint_steps(path: str | Path) -> int:
    """Environment steps encoded in a checkpoint's file name."""
    match = _CKPT.match(Path(path).name)
    if not match:
        raise ValueError(f"{path} is not a checkpoint file name (ckpt_<steps>.pt|.zip)")
    return int(match.group(1))


def find_run_config(path: str | Path, levels: int = 3) -> Path | None:
    """``config.json`` of the run a file belongs to: the file's folder or up to ``levels`` parents."""
    folder = Path(path).resolve()
    folder = folder if folder.is_dir() else folder.parent
    for candidate in [folder, *list(folder.parents)[:levels]]:
        if (candidate / CONFIG_FILE).is_file():
            return candidate / CONFIG_FILE
    return None


def versions() -> dict[str, str]:
    """Versions of the packages that shape a run (for the config dump)."""
    result = {"python": sys.version.split()[0]}
    for name in ("margin_rl", "torch", "stable-baselines3", "rsl-rl-lib", "gymnasium", "mujoco", "numpy"):
        try:
            result[name] = version(name)
        except PackageNotFoundError:
            result[name] = "not installed"
    return result


@dataclass
class RunHooks:
    """Callbacks from a learner to the training driver."""

    stop_requested: Callable[[], bool]
    progress: Callable[[int, float | None], None]  # (environment steps done, mean episode return or None)
    checkpointed: Callable[[Path, int], None]  # (checkpoint path, environment steps)
    verbose: bool = False


class StopRequest:
    """Set by SIGINT/SIGTERM (see :func:`graceful_stop`); learners poll it at safe points and checkpoint."""

    def __init__(self) -> None:
        self.requested = False
        self.signal_name = ""

    def request(self, reason: str = "request") -> None:
        self.requested = True
        self.signal_name = self.signal_name or reason


@contextlib.contextmanager
def graceful_stop(stop: StopRequest, verbose: bool = True) -> Iterator[StopRequest]:
    """Install SIGINT/SIGTERM handlers that set ``stop`` (the learner checkpoints at the next safe point
    and returns); a second signal raises KeyboardInterrupt. Handlers are restored on exit. Outside the main
    thread signals cannot be caught, and ``stop`` is only set programmatically."""
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        if stop.requested:
            raise KeyboardInterrupt(f"second {signal.Signals(signum).name}: aborting without a checkpoint")
        stop.request(signal.Signals(signum).name)
        if verbose:
            print(
                f"\n{signal.Signals(signum).name} received: stopping at the next safe point and writing a "
                "checkpoint (send it again to abort at once)",
                file=sys.stderr,
                flush=True,
            )

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


@contextlib.contextmanager
def torch_threads(count: int | None) -> Iterator[None]:
    """Run with ``count`` torch intra-op threads (restored afterwards; None leaves torch's choice).

    One thread is the right default here: the simulation steps on MuJoCo's own thread pool, and torch's OpenMP
    workers, which keep spinning after each small policy evaluation, take the cores from it (measured on 2 cores:
    environment stepping between policy evaluations fell from 12.5k to 1.6k steps/s with torch's default).
    """
    if count is None:
        yield
        return
    previous = torch.get_num_threads()
    torch.set_num_threads(int(count))
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def with_torch_threads(function: Callable[..., Any], count: int | None) -> Callable[..., Any]:
    """``function``, run with ``count`` torch intra-op threads each call (:func:`torch_threads`).

    The learners wrap their PPO update with it: the update's matrix products use every core while the simulation
    waits, and collection stays on one torch thread. Measured on the 2-core VM with 512 environments
    (``benchmarks/speed/bench_train_split.py``): the update 0.62 -> 0.49 s per iteration, the environment's stepping
    unchanged (1.17 vs 1.16 s); ``OMP_WAIT_POLICY=PASSIVE`` did not help (0.57 s).
    """

    @functools.wraps(function)
    def call(*args: Any, **kwargs: Any) -> Any:
        with torch_threads(count):
            return function(*args, **kwargs)

    return call


@contextlib.contextmanager
def torchscript_export() -> Iterator[None]:
    """Silence torch's DeprecationWarning for ``torch.jit`` (TorchScript stays the exported format here: rsl-rl's
    ``export_policy_to_jit`` writes it and C++ deployments load it)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*torch\.jit.*deprecated", category=DeprecationWarning)
        yield


@contextlib.contextmanager
def quiet_stdout(enabled: bool) -> Iterator[None]:
    """Send stdout to nowhere while ``enabled`` (rsl-rl prints a long block every iteration)."""
    if not enabled:
        yield
        return
    with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink):
        yield
