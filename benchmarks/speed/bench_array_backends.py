"""Benchmark: the environment core's array arithmetic in numpy, through an array namespace, and in torch on the CPU.

Usage:
    python benchmarks/speed/bench_array_backends.py [--num-envs 128 1024 4096] [--calls 200] [--rounds 7] [--json PATH]

The question it answers: written once for both the CPU path (``mujoco.batch``, numpy arrays) and a GPU path (torch
tensors over MuJoCo Warp), what does the CPU path pay? A representative slice of one policy step of
:class:`~margin_rl.envs.core.AnymalCore` (quaternion to rotation matrix, the base-frame velocities, finite-difference
accelerations through the EMA filter, the feet in the heading frame as lambda has them, the reward's logistic kernel,
the float32 observation) is written once against the Python array API standard and run three ways, float64, one
thread, on N environments:

* ``numpy``: the namespace of numpy itself (what the core calls today);
* ``numpy via array_api_compat``: the same arrays through ``array_api_compat.array_namespace`` (its wrappers);
* ``torch (CPU)``: CPU tensors through the same namespace (what a torch-throughout core would run on the CPU).

Rounds interleave the three; the table has the medians of the per-call times.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import array_api_compat
import numpy as np
import torch

from benchmarks.harness import interleave, machine_line, parser, print_table, summarise, write_record

POLICY_DT = 0.02  # [s]
FILTER = 0.5  # EnvConfig.acceleration_filter's default


def step_slice(xp: Any, quat: Any, qvel: Any, prev_com_vel: Any, com_acc: Any, feet: Any, com: Any) -> tuple:
    """The slice of a policy step, in the array API standard's names (``xp``: numpy or an array_api_compat
    namespace). quat (N, 4) w, x, y, z; qvel (N, 18); prev_com_vel, com_acc, com (N, 3); feet (N, 4, 3)."""
    w, x, y, z = quat[:, 0], quat[:, 1], quat[:, 2], quat[:, 3]
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]  # fmt: skip
    R = xp.reshape(xp.stack(rows, axis=-1), (-1, 3, 3))
    lin_vel_base = xp.matmul(xp.matrix_transpose(R), qvel[:, :3, None])[..., 0]
    com_acc = FILTER * com_acc + (1 - FILTER) * (qvel[:, :3] - prev_com_vel) / POLICY_DT
    yaw = xp.atan2(R[:, 1, 0], R[:, 0, 0])
    c, s = xp.cos(yaw)[:, None], xp.sin(yaw)[:, None]
    relative = feet - com[:, None, :]
    feet_x = c * relative[..., 0] + s * relative[..., 1]
    feet_y = -s * relative[..., 0] + c * relative[..., 1]
    e = 8 * (0.75 - lin_vel_base[:, 0])
    reward = 1 / (xp.exp(-e) + 2 + xp.exp(e))
    observation = xp.concat([lin_vel_base, qvel[:, 3:6], -R[:, 2, :], qvel[:, 6:], feet_x, feet_y], axis=1)
    return xp.astype(observation, xp.float32), reward, com_acc


def inputs(num_envs: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(0)
    quat = rng.normal(size=(num_envs, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    return (quat, rng.normal(size=(num_envs, 18)), rng.normal(size=(num_envs, 3)), rng.normal(size=(num_envs, 3)),
            rng.normal(size=(num_envs, 4, 3)), rng.normal(size=(num_envs, 3)))  # fmt: skip


class NumpyNamespace:
    """numpy's own functions under the standard's names that differ (numpy 2 has most of them itself)."""

    def __getattr__(self, name: str) -> Any:
        return getattr(np, name)

    @staticmethod
    def concat(arrays: list[np.ndarray], axis: int = 0) -> np.ndarray:
        return np.concatenate(arrays, axis=axis)

    @staticmethod
    def astype(x: np.ndarray, dtype: Any) -> np.ndarray:
        return x.astype(dtype)


def runner(xp: Any, arrays: tuple, calls: int) -> Callable[[int], float]:
    step_slice(xp, *arrays)  # warm-up

    def run(_round: int) -> float:
        t0 = time.perf_counter()
        for _ in range(calls):
            step_slice(xp, *arrays)
        return (time.perf_counter() - t0) / calls * 1e6

    return run


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--num-envs", type=int, nargs="+", default=[128, 1024, 4096])
    args_parser.add_argument("--calls", type=int, default=200)
    args_parser.add_argument("--rounds", type=int, default=7)
    args = args_parser.parse_args()
    torch.set_num_threads(1)
    rows, results = [], {}
    for n in args.num_envs:
        arrays = inputs(n)
        tensors = tuple(torch.from_numpy(a) for a in arrays)
        runners = {
            "numpy": runner(NumpyNamespace(), arrays, args.calls),
            "numpy via array_api_compat": runner(array_api_compat.array_namespace(arrays[0]), arrays, args.calls),
            "torch (CPU)": runner(array_api_compat.array_namespace(tensors[0]), tensors, args.calls),
        }
        times = {name: summarise(values) for name, values in interleave(runners, args.rounds, alternate=True).items()}
        results[n] = times
        base = times["numpy"].median
        rows.extend((n, name, f"{t.median:,.0f}", f"{t.median / base:.2f}") for name, t in times.items())
    print(machine_line())
    print(f"{args.calls} calls per round, {args.rounds} interleaved rounds, float64, one thread (median)")
    print()
    print_table(("environments", "arrays", "µs per call", "/ numpy"), rows)
    write_record(args.json, "array_backends", args, {"us_per_call": results})


if __name__ == "__main__":
    main()
