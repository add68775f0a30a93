"""The per-step records of :class:`~margin_rl.envs.core.AnymalCore`: the simulator state it reads, the
accelerations it estimates, and what a step returns (N environments leading every array), with the check
that no non-finite output leaves a step."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from margin_rl.arrays import Array, namespace, split_columns, to_numpy
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.stability_input import heading_rotation


@dataclass(frozen=True)
class SimulationState:
    """World-frame state of some environments, read from the batch's arrays (N leading; numpy arrays, or torch
    tensors on the physics' device)."""

    base_pos: Array  # (N, 3) [m]
    base_rot: Array  # (N, 3, 3) R_WB
    lin_vel_world: Array  # (N, 3) base linear velocity [m/s]
    ang_vel_body: Array  # (N, 3) base angular velocity, base frame [rad/s]
    ang_vel_world: Array  # (N, 3) [rad/s]
    joint_pos: Array  # (N, 12) [rad]
    joint_vel: Array  # (N, 12) [rad/s]
    com: Array  # (N, 3) whole-body CoM [m]
    com_vel: Array  # (N, 3) [m/s]
    feet: Array  # (N, 4, 3) foot-sphere centres [m]
    contacts: Array  # (N, 4) bool, foot-terrain contact
    base_contact: Array  # (N,) bool
    thigh_contacts: Array  # (N, 4) bool
    knees: Array  # (N, 4, 3) knee (KFE joint) positions [m]

    @functools.cached_property
    def heading_rot(self) -> Array:
        """(N, 3, 3) R_WH, the horizontal frame in the world (the base's yaw: :func:`~margin_rl.envs.stability_input.
        heading_rotation`), computed once for everything a step turns into it (lambda, the height scan)."""
        return heading_rotation(self.base_rot)


@dataclass(frozen=True)
class Accelerations:
    """Finite-difference accelerations over the policy step (world frame).

    ``com`` and ``base_angular`` are the filtered estimates lambda is built from; ``com_measured`` and
    ``base_angular_measured`` the unfiltered differences the info reports (what the comparison's base
    acceleration metrics measure, whatever the filter).
    """

    com: Array  # (N, 3) [m/s^2], EMA-filtered (EnvConfig.acceleration_filter)
    base_angular: Array  # (N, 3) [rad/s^2], EMA-filtered
    joints: Array  # (N, 12) [rad/s^2], unfiltered
    com_measured: Array  # (N, 3) [m/s^2], unfiltered
    base_angular_measured: Array  # (N, 3) [rad/s^2], unfiltered


def estimate_accelerations(
    velocities: Array, previous: Array, filtered: Array, alpha: float, dt: float
) -> tuple[Accelerations, Array]:
    """The accelerations over a policy step of ``dt`` [s] from ``velocities`` (N, 18) = [CoM velocity (3) [m/s] |
    base angular velocity, world frame (3) [rad/s] | joint velocities (12) [rad/s]] and the previous step's
    ``previous`` (N, 18): the finite differences a_fd = (v - v_prev) / dt, the first six also filtered by the EMA
    a = alpha a_prev + (1 - alpha) a_fd over the previous step's filtered ones ``filtered`` (N, 6). Returns the
    :class:`Accelerations` and the new filtered (N, 6) to keep; one operation per stage for all the columns."""
    differences = (velocities - previous) / dt
    new_filtered = alpha * filtered + (1 - alpha) * differences[:, :6]
    com_acc, ang_acc, joint_acc = split_columns(differences, (3, 3, 12))
    com_filtered, ang_filtered = split_columns(new_filtered, (3, 3))
    return Accelerations(com_filtered, ang_filtered, joint_acc, com_acc, ang_acc), new_filtered


@dataclass(frozen=True)
class StepOutput:
    """Result of :meth:`AnymalCore.step` for all environments."""

    observation: Array  # (N, obs) float32, after autoreset for finished environments
    reward: Array  # (N,) float64
    terminated: Array  # (N,) bool
    truncated: Array  # (N,) bool
    info: dict[str, Array]  # per-environment arrays (reward_<term>, margin, accelerations, ...)
    final_observation: Array  # (N, obs): the observation before autoreset (valid where done)
    privileged: Array | None  # (N, priv) critic observation, after autoreset

    def to_numpy(self) -> StepOutput:
        """This output with every array on the host as numpy (itself where it is already: the Gymnasium and SB3
        edges of a core that computes on a device)."""
        if namespace(self.reward) is np:
            return self
        return self.map_arrays(to_numpy)

    def map_arrays(self, fn: Callable[[Array], Array]) -> StepOutput:
        """This output with ``fn`` applied to every array (the info's included)."""
        return StepOutput(
            fn(self.observation),
            fn(self.reward),
            fn(self.terminated),
            fn(self.truncated),
            {key: fn(value) for key, value in self.info.items()},
            fn(self.final_observation),
            None if self.privileged is None else fn(self.privileged),
        )


def check_finite_outputs(config: EnvConfig, reward: Array | float, *observations: Array) -> None:
    """FloatingPointError if a reward or an observation is NaN or inf.

    The core keeps diverged simulations finite (and flags them in ``info["diverged"]``); what is left is a
    setting so large that float arithmetic overflows, which no agent should train on. Checked in the core, so
    every adapter (Gymnasium, SB3, rsl-rl) gets the same error.
    """
    xp = namespace(*observations)
    bad_observation = not all(bool(xp.all(xp.isfinite(o))) for o in observations)
    if not bad_observation and bool(xp.all(xp.isfinite(xp.asarray(reward)))):
        return
    raise FloatingPointError(
        f"the {'observation' if bad_observation else 'reward'} is not finite: {finite_output_hint(config)}"
    )


def finite_output_hint(config: EnvConfig) -> str:
    """What makes an output non-finite, and what to change: the settings that scale the outputs."""
    rnd = config.randomization
    return (
        f"an EnvConfig value is too large for float arithmetic (margin_weight={config.margin_weight}, "
        f"reward_params.alive_bonus={config.reward_params.alive_bonus}, "
        f"randomization.observation_noise={rnd.observation_noise}, reset_velocity_noise={rnd.reset_velocity_noise}); "
        "use values of the order of the defaults"
    )
