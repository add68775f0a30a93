"""Reward terms: small pure functions of named per-environment arrays, weighted by the presets.

Sign convention: every term returns a non-negative magnitude except ``margin`` (signed, [m]); penalties get
negative weights in :data:`margin_rl.envs.config.REWARD_PRESETS`. The reward is the weighted sum, per
policy step, and every weighted term is reported in ``info`` as ``reward_<name>``.

Each term is written once, in the array API standard's names, for numpy arrays (``mujoco.batch``) and torch tensors
(a device-resident step) alike: the namespace comes from the arrays (:func:`margin_rl.arrays.namespace`); on
numpy it calls numpy's own functions, so the numbers are numpy's.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from margin_rl.arrays import constant, namespace, unstack

Arrays = dict[str, Any]
"""Per-environment arrays by name, all numpy or all torch (float64, bool for flags)."""


def logistic_kernel(x: Any) -> Any:
    """L(x) = (e^-x + 2 + e^x)^-1, in (0, 1/4], peak at x = 0 (seed 000 §V-C)."""
    xp = namespace(x)
    x = xp.clip(x, -50.0, 50.0)
    return 1.0 / (xp.exp(-x) + 2.0 + xp.exp(x))


def velocity_tracking(s: Arrays, gain: float) -> Any:
    """L(gain (v_cmd - x_dot)), x_dot the heading velocity in the base frame."""
    return logistic_kernel(gain * (s["command"][:, 0] - s["base_lin_vel"][:, 0]))


def yaw_tracking(s: Arrays, gain: float) -> Any:
    """L(gain (omega_cmd - omega_z)): the same kernel on the yaw rate [rad/s] about the base z axis, the gain read
    in s/rad (RewardParams.yaw_tracking). The paper's reward tracks the heading velocity alone, so nothing keeps a
    policy from turning under a zero yaw command: on rough ground its episodes then end near where they began."""
    return logistic_kernel(gain * (s["command"][:, 2] - s["base_ang_vel"][:, 2]))


def _row_sum(x: Any) -> Any:
    """Sum over the second axis (N, k) -> (N,)."""
    return namespace(x).sum(x, axis=1)


FIELD_TRACKING_VARIANCE = 0.25
"""sigma^2 [(m/s)^2, (rad/s)^2] of the field's exponential tracking kernels exp(-e^2 / sigma^2): legged_gym's
``tracking_sigma`` and Isaac Lab's ``std = sqrt(0.25)`` of its flat and rough velocity tasks."""


def exponential_kernel(squared_error: Any) -> Any:
    """exp(-e^2 / sigma^2), in (0, 1], 1 at e = 0 (sigma^2 = :data:`FIELD_TRACKING_VARIANCE`)."""
    return namespace(squared_error).exp(-squared_error / FIELD_TRACKING_VARIANCE)


def tracking_lin_vel_xy(s: Arrays, gain: float) -> Any:
    """exp(-|v_cmd,xy - v_xy|^2 / sigma^2): the field's linear-velocity tracking kernel on the commanded heading and
    lateral velocity [m/s] in the base frame (legged_gym ``tracking_lin_vel``, Isaac Lab ``track_lin_vel_xy_exp``)."""
    return exponential_kernel(_row_sum((s["command"][:, :2] - s["base_lin_vel"][:, :2]) ** 2))


def tracking_ang_vel_z(s: Arrays, gain: float) -> Any:
    """exp(-(omega_cmd - omega_z)^2 / sigma^2): the field's yaw-rate tracking kernel [rad/s] about the base z axis
    (legged_gym ``tracking_ang_vel``, Isaac Lab ``track_ang_vel_z_exp``)."""
    return exponential_kernel((s["command"][:, 2] - s["base_ang_vel"][:, 2]) ** 2)


def margin(s: Arrays, gain: float) -> Any:
    """The stability margin m(lambda) [m] (learned, analytic or zero)."""
    return s["margin"]


def alive(s: Arrays, gain: float) -> Any:
    """1 per policy step. A constant survival reward: with a margin term that is negative on most steps of a
    dynamic gait, L + w m < 0 per step makes falling at once the best PPO can do; the bonus removes that
    incentive and changes nothing else (see EnvConfig.alive_bonus)."""
    xp = namespace(s["margin"])
    return xp.ones_like(s["margin"], dtype=xp.float64)


def lateral_velocity(s: Arrays, gain: float) -> Any:
    return (s["base_lin_vel"][:, 1] - s["command"][:, 1]) ** 2


def yaw_rate(s: Arrays, gain: float) -> Any:
    return (s["base_ang_vel"][:, 2] - s["command"][:, 2]) ** 2


def vertical_velocity(s: Arrays, gain: float) -> Any:
    return s["base_lin_vel"][:, 2] ** 2


def roll_pitch_rate(s: Arrays, gain: float) -> Any:
    return _row_sum(s["base_ang_vel"][:, :2] ** 2)


def orientation(s: Arrays, gain: float) -> Any:
    return _row_sum(s["projected_gravity"][:, :2] ** 2)


def torques(s: Arrays, gain: float) -> Any:
    return _row_sum(s["torques"] ** 2)


def action_rate(s: Arrays, gain: float) -> Any:
    return _row_sum((s["action"] - s["last_action"]) ** 2)


def joint_acceleration(s: Arrays, gain: float) -> Any:
    return _row_sum(s["joint_acc"] ** 2)


def feet_air_time(s: Arrays, gain: float) -> Any:
    """Sum over feet touching down this step of (air time - 0.5 s); zero for a near-zero command."""
    xp = namespace(s["command"])
    moving = xp.linalg.vector_norm(s["command"][:, :2], axis=1) > 0.1
    return _row_sum((s["air_time_at_touchdown"] - 0.5) * s["touchdown"]) * moving


def base_acceleration(s: Arrays, gain: float) -> Any:
    """|a|^2 [(m/s^2)^2]: the squared norm of the base (CoM) linear acceleration over the policy step, unfiltered,
    the quantity the comparison's ``lin_acc_rms`` averages (a plain smoothness penalty, the margin's control)."""
    return _row_sum(s["base_lin_acc"] ** 2)


def collisions(s: Arrays, gain: float) -> Any:
    """Number of thigh contacts with the terrain."""
    xp = namespace(s["thigh_contacts"])
    return _row_sum(xp.astype(s["thigh_contacts"], xp.float64))


def knee_clearance(s: Arrays, gain: float) -> Any:
    """Sum over the legs of how far each knee (KFE joint) is below the clearance height above the terrain [m]:
    sum_i max(0, h_c - h_knee,i), zero while every knee is at least h_c high (EnvConfig.knee_clearance)."""
    deficit = s["knee_clearance_height"][:, None] - s["knee_heights"]
    return _row_sum(namespace(deficit).clip(deficit, min=0.0))


def base_height(s: Arrays, gain: float) -> Any:
    """How far the base origin is below its target height above the terrain under it [m]:
    max(0, h_target - h_base), zero at or above the target (target: RewardParams.base_height_fraction times
    the MJCF standing keyframe's base height)."""
    below = s["base_height_target"] - s["base_height"]
    return namespace(below).clip(below, min=0.0)


def termination(s: Arrays, gain: float) -> Any:
    """1 on the step an episode ends in a fall (any termination cause but a diverged simulation), else 0
    (RewardParams.termination_penalty)."""
    xp = namespace(s["fell"])
    return xp.astype(s["fell"], xp.float64)


REWARD_TERMS: dict[str, Callable[[Arrays, float], Any]] = {
    f.__name__: f
    for f in (
        velocity_tracking,
        yaw_tracking,
        tracking_lin_vel_xy,
        tracking_ang_vel_z,
        margin,
        alive,
        lateral_velocity,
        yaw_rate,
        vertical_velocity,
        roll_pitch_rate,
        orientation,
        torques,
        action_rate,
        joint_acceleration,
        base_acceleration,
        feet_air_time,
        collisions,
        knee_clearance,
        base_height,
        termination,
    )
}


def compute_rewards(weights: dict[str, float], s: Arrays, gain: float) -> tuple[Any, dict[str, Any]]:
    """Weighted terms and their sum: (reward (N,), {name: weighted term (N,)}), arrays of the inputs' kind."""
    unknown = set(weights) - set(REWARD_TERMS)
    if unknown:
        raise ValueError(f"unknown reward terms {sorted(unknown)}; known: {sorted(REWARD_TERMS)}")
    xp = namespace(s["margin"])
    if not weights:
        return xp.zeros_like(s["margin"], dtype=xp.float64), {}
    # every term weighted in one product and summed in one reduction (term by term, in the weights' order)
    unweighted = xp.stack([REWARD_TERMS[name](s, gain) for name in weights])  # (terms, N), float64
    weighted = unweighted * constant(np.array(list(weights.values()), dtype=np.float64)[:, None], unweighted)
    return xp.sum(weighted, axis=0), dict(zip(weights, unstack(weighted, axis=0), strict=True))
