"""An environment's episode state in the core, at fixed addresses: the float quantities of :data:`EPISODE_STATE` as
views of one (N, 56) float64 array, the two counters of one (N, 2) int64 array. A reset writes each array in one
operation (by index on the host, by mask on a device), and a recorded graph replays on the same memory every step."""

from __future__ import annotations

from typing import Any

EPISODE_STATE: dict[str, int] = {
    # what a reset draws or reads, then what it sets to 0: the zeros in one block (one piece of the reset's write)
    "_spawn_xy": 2,  # where the episode started [m], for the curriculum's distance walked
    "command": 3,  # (v_x [m/s], v_y [m/s], yaw rate [rad/s]), base heading frame
    "_prev_com_vel": 3,  # the last step's velocities, for the finite-difference accelerations
    "_prev_ang_vel": 3,
    "_prev_joint_vel": 12,
    "_next_push": 1,  # policy steps until the next random push
    "mu": 1,  # the floor's friction coefficient
    "last_action": 12,
    "_com_acc": 3,  # the filtered accelerations [m/s^2], [rad/s^2]
    "_ang_acc": 3,
    "_air_time": 4,  # [s] per foot
    "_push_force": 3,  # the running push [N], and the force of this step (lambda's f_ext)
    "_push_applied": 3,
    "_push_torque": 3,  # always 0: with the force, the base's wrench written to the physics in one piece
}
"""The float state of an environment's episode, in the order of its columns (widths)."""

EPISODE_SPANS: dict[str, tuple[str, str]] = {
    "_prev_velocities": ("_prev_com_vel", "_prev_joint_vel"),  # differenced in one operation
    "_filtered_acc": ("_com_acc", "_ang_acc"),  # filtered in one operation
    "_push_wrench": ("_push_applied", "_push_torque"),  # written in one operation
}
"""Runs of consecutive quantities a step updates together (name -> its first and last quantity), as one view each."""

EPISODE_COUNTERS: tuple[str, ...] = ("episode_step", "_push_steps_left")
"""The int64 counters: steps since the episode started, steps left of the running push."""


def episode_views(floats: Any, counters: Any) -> dict[str, Any]:
    """Name -> its view: the columns of ``floats`` (N, 56) in :data:`EPISODE_STATE`'s order (a width of one as
    (N,)), each run of :data:`EPISODE_SPANS`, and the columns of ``counters`` (N, 2) in :data:`EPISODE_COUNTERS`'."""
    views, columns, start = {}, {}, 0
    for name, width in EPISODE_STATE.items():
        columns[name] = (start, start + width)
        view = floats[:, start : start + width]
        views[name] = view if width > 1 else view[:, 0]
        start += width
    for span, (first, last) in EPISODE_SPANS.items():
        views[span] = floats[:, columns[first][0] : columns[last][1]]
    return views | {name: counters[:, k] for k, name in enumerate(EPISODE_COUNTERS)}


def episode_columns(start: dict[str, Any], n: int, xp: Any, device: Any) -> list[Any]:
    """The pieces of ``n`` rows of the float episode state, in :data:`EPISODE_STATE`'s order, to concatenate: the
    arrays of ``start`` (name -> (n, width)), and zeros for the other columns, one array per run of them."""
    pieces: list[Any] = []
    zero_run = 0
    for name, width in EPISODE_STATE.items():
        if name not in start:
            zero_run += width
            continue
        if zero_run:
            pieces.append(xp.zeros((n, zero_run), dtype=xp.float64, device=device))
            zero_run = 0
        pieces.append(start[name])
    if zero_run:
        pieces.append(xp.zeros((n, zero_run), dtype=xp.float64, device=device))
    return pieces
