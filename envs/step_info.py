"""The per-environment info of a step of :class:`~margin_rl.envs.core.AnymalCore` (``info`` of every adapter): every
weighted reward term, the margin and lambda, the base accelerations, the gait, the torques, the termination flags.
Float64 arrays (N, ...) of the core's kind; flags as 0/1."""

from __future__ import annotations

from typing import Any

from margin_rl.arrays import namespace, rotate, unstack
from margin_rl.envs.stability_input import stance_width
from margin_rl.envs.step_data import Accelerations, SimulationState
from margin_rl.envs.terminations import info_key
from margin_rl.stability.analytic.lambda_state import StabilityState


def step_info(
    state: SimulationState,
    acc: Accelerations,
    values: dict[str, Any],
    terms: dict[str, Any],
    margin: Any,
    lam: Any,
    stability: StabilityState,
    diverged: Any,
    causes: dict[str, Any],
    command: Any,
    torque_at_limit: Any,
    terrain_level: Any = None,
) -> dict[str, Any]:
    """The step's info from its state, accelerations, reward ``values`` and weighted ``terms``, the clipped margin
    and lambda, the divergence and termination flags, the commands (N, 3), each joint's torque threshold of "at the
    limit" (12,) [N m], and the terrain curriculum's rows (None: no curriculum)."""
    xp, R = namespace(lam), state.base_rot
    # The flags as float64, one conversion for all: fell, diverged, each cause (and the curriculum row).
    flags = {"fell": values["fell"], "diverged": diverged, **{info_key(name): f for name, f in causes.items()}}
    as_float = xp.astype(xp.stack(list(flags.values()), axis=1), xp.float64)
    # Unfiltered: the robot's accelerations, the comparison's metrics (lambda has the filtered ones); base frame.
    measured = xp.stack([acc.com_measured, acc.base_angular_measured], axis=1)
    lin_acc, ang_acc = unstack(rotate(R, measured, inverse=True))
    torques = values["torques"]
    contacts, touchdowns, edge_touchdowns = unstack(
        xp.astype(xp.stack([state.contacts, values["touchdown"], values["edge_touchdown"]], axis=1), xp.float64)
    )
    return {
        **{f"reward_{k}": v for k, v in terms.items()},
        "margin": margin,
        "base_lin_acc": lin_acc,  # CoM acceleration
        "base_ang_acc": ang_acc,
        "base_lin_vel": values["base_lin_vel"],
        "velocity_error": xp.abs(command[:, 0] - values["base_lin_vel"][:, 0]),
        "contacts": contacts,
        "stance_width": stance_width(stability.feet),  # feet in H, as they entered lambda
        "touchdowns": xp.sum(touchdowns, axis=1),  # feet landing this step
        "edge_touchdowns": xp.sum(edge_touchdowns, axis=1),  # of them, on a step edge
        "base_height": values["base_height"],  # base origin above the terrain under it [m]
        # mean over the joints of tau^2 [(N m)^2], and 1 where a joint's actuator is at its force limit (the last
        # physics step's actuator forces)
        "joint_torque_sq": xp.mean(torques**2, axis=1),
        "torque_at_limit": xp.astype(xp.any(xp.abs(torques) >= torque_at_limit, axis=1), xp.float64),
        "lambda": lam,  # (N, 47), the margin's input (names: stability.lambda_names())
        **dict(zip(flags, unstack(as_float), strict=True)),
        # the curriculum row of the episode (the level it moves to is set at its reset)
        **({} if terrain_level is None else {"terrain_level": xp.astype(terrain_level, xp.float64)}),
    }
