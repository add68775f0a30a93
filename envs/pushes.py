"""Pushes on the base: the random ones of :class:`~margin_rl.envs.config.RandomizationConfig` and the ones a user
asks for (:meth:`~margin_rl.envs.core.AnymalCore.push`). A push is a constant horizontal force at the base origin
for whole policy steps; it enters lambda as f_ext. The running pushes live in the core's episode state (force [N],
steps left, policy steps until the next random push), updated here in place."""

from __future__ import annotations

from typing import Any

import numpy as np

from margin_rl.arrays import namespace, to_numpy, write_where
from margin_rl.envs.config import RandomizationConfig

PUSH_FRAMES = ("world", "heading")
"""The frames a push's force may be given in: the world's, or the base heading frame (yaw only: x forwards, y to the
left, z up)."""


def push_steps(duration_s: float, dt: float) -> int:
    """Policy steps (of ``dt`` [s]) a push of ``duration_s`` [s] lasts: rounded, at least one."""
    return max(1, round(duration_s / dt))


def checked_push(ids: Any, force: Any, duration_s: float, frame: str, num_envs: int) -> tuple[np.ndarray, np.ndarray]:
    """A push request as (ids (k,) int64, force (k, 3) float64) numpy arrays.

    Raises:
        ValueError: ``ids`` outside [0, num_envs), ``force`` not finite with shape (len(ids), 3), ``duration_s``
            not > 0, or a frame not in :data:`PUSH_FRAMES`.
    """
    ids = np.atleast_1d(np.asarray(to_numpy(ids), dtype=np.int64))
    force = np.asarray(to_numpy(force), dtype=np.float64)
    if ids.size and (ids.min() < 0 or ids.max() >= num_envs):
        raise ValueError(f"push ids must lie in [0, {num_envs}), got {ids.min()}..{ids.max()}")
    if force.shape != (len(ids), 3) or not np.all(np.isfinite(force)):
        raise ValueError(f"push force must be finite with shape (len(ids), 3) = ({len(ids)}, 3), got {force.shape}")
    if not duration_s > 0:
        raise ValueError(f"push duration_s must be > 0 [s], got {duration_s}")
    if frame not in PUSH_FRAMES:
        raise ValueError(f"push frame must be one of {PUSH_FRAMES}, got {frame!r}")
    return ids, force


def start_random_pushes(
    next_push: Any, force: Any, steps_left: Any, rng: Any, randomization: RandomizationConfig, dt: float, by_mask: bool
) -> None:
    """Count every environment's wait for its next random push (``next_push``, policy steps) down by one; where it
    runs out a push starts: ``force`` (N, 3) [N] of ``randomization.push_force`` in a uniform horizontal direction,
    ``steps_left`` (N,) its length, ``next_push`` a new wait, exponential with mean ``push_interval_s / dt``. All in
    place.

    ``by_mask``: draw for every environment and keep the draws where a push starts (a device's step: the same draws
    every step and no count to read from the host); otherwise draw as many as pushes start (the host's numbers).
    """
    xp, n = namespace(force), int(force.shape[0])
    next_push -= 1
    start = next_push <= 0
    steps = push_steps(randomization.push_duration_s, dt)
    mean_wait = randomization.push_interval_s / dt

    def directions(angle: Any) -> Any:
        return randomization.push_force * xp.stack([xp.cos(angle), xp.sin(angle), xp.zeros_like(angle)], axis=1)

    if by_mask:
        angle = rng.uniform(0, 2 * np.pi, size=n)
        pushed, wait = directions(angle), rng.exponential(mean_wait, size=n)
        write_where(force, start, pushed)
        write_where(steps_left, start, steps)
        write_where(next_push, start, wait)
        return
    count = int(xp.sum(start))
    if count:
        force[start] = directions(rng.uniform(0, 2 * np.pi, size=count))
        steps_left[start] = steps
        next_push[start] = rng.exponential(mean_wait, size=count)
