"""Reward terms: small pure functions of named per-environment arrays, weighted by the presets.

Sign convention: every term returns a non-negative magnitude except ``margin`` (signed, [m]); penalties get
negative weights in :data:`margin_rl.envs.config.REWARD_PRESETS`. The reward is the weighted sum, per
policy step, and every weighted term is reported in ``info`` as ``reward_<name>``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Arrays = dict[str, np.ndarray]


def logistic_kernel(x: np.ndarray) -> np.ndarray:
    """L(x) = (e^-x + 2 + e^x)^-1, in (0, 1/4], peak at x = 0 (seed 000 §V-C)."""
    x = np.clip(x, -50.0, 50.0)
    return 1.0 / (np.exp(-x) + 2.0 + np.exp(x))


def velocity_tracking(s: Arrays, gain: float) -> np.ndarray:
    """L(gain (v_cmd - x_dot)), x_dot the heading velocity in the base frame."""
    return logistic_kernel(gain * (s["command"][:, 0] - s["base_lin_vel"][:, 0]))


def margin(s: Arrays, gain: float) -> np.ndarray:
    """The stability margin m(lambda) [m] (learned, analytic or zero)."""
    return s["margin"]


def alive(s: Arrays, gain: float) -> np.ndarray:
    """1 per policy step. A constant survival reward: with a margin term that is negative on most steps of a
    dynamic gait, L + w m < 0 per step makes falling at once the best PPO can do; the bonus removes that
    incentive and changes nothing else (see EnvConfig.alive_bonus)."""
    return np.ones_like(s["margin"], dtype=float)


def lateral_velocity(s: Arrays, gain: float) -> np.ndarray:
    return (s["base_lin_vel"][:, 1] - s["command"][:, 1]) ** 2


def yaw_rate(s: Arrays, gain: float) -> np.ndarray:
    return (s["base_ang_vel"][:, 2] - s["command"][:, 2]) ** 2


def vertical_velocity(s: Arrays, gain: float) -> np.ndarray:
    return s["base_lin_vel"][:, 2] ** 2


def roll_pitch_rate(s: Arrays, gain: float) -> np.ndarray:
    return np.sum(s["base_ang_vel"][:, :2] ** 2, axis=1)


def orientation(s: Arrays, gain: float) -> np.ndarray:
    return np.sum(s["projected_gravity"][:, :2] ** 2, axis=1)


def torques(s: Arrays, gain: float) -> np.ndarray:
    return np.sum(s["torques"] ** 2, axis=1)


def action_rate(s: Arrays, gain: float) -> np.ndarray:
    return np.sum((s["action"] - s["last_action"]) ** 2, axis=1)


def joint_acceleration(s: Arrays, gain: float) -> np.ndarray:
    return np.sum(s["joint_acc"] ** 2, axis=1)


def feet_air_time(s: Arrays, gain: float) -> np.ndarray:
    """Sum over feet touching down this step of (air time - 0.5 s); zero for a near-zero command."""
    moving = np.linalg.norm(s["command"][:, :2], axis=1) > 0.1
    return np.sum((s["air_time_at_touchdown"] - 0.5) * s["touchdown"], axis=1) * moving


def collisions(s: Arrays, gain: float) -> np.ndarray:
    """Number of thigh contacts with the terrain."""
    return np.sum(s["thigh_contacts"], axis=1).astype(float)


def knee_clearance(s: Arrays, gain: float) -> np.ndarray:
    """Sum over the legs of how far each knee (KFE joint) is below the clearance height above the terrain [m]:
    sum_i max(0, h_c - h_knee,i), zero while every knee is at least h_c high (EnvConfig.knee_clearance)."""
    deficit = s["knee_clearance_height"][:, None] - s["knee_heights"]
    return np.sum(np.maximum(deficit, 0.0), axis=1)


def base_height(s: Arrays, gain: float) -> np.ndarray:
    """How far the base origin is below its target height above the terrain under it [m]:
    max(0, h_target - h_base), zero at or above the target (target: RewardParams.base_height_fraction times
    the MJCF standing keyframe's base height)."""
    return np.maximum(s["base_height_target"] - s["base_height"], 0.0)


REWARD_TERMS: dict[str, Callable[[Arrays, float], np.ndarray]] = {
    f.__name__: f
    for f in (
        velocity_tracking,
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
        feet_air_time,
        collisions,
        knee_clearance,
        base_height,
    )
}


def compute_rewards(weights: dict[str, float], s: Arrays, gain: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Weighted terms and their sum: (reward (N,), {name: weighted term (N,)})."""
    unknown = set(weights) - set(REWARD_TERMS)
    if unknown:
        raise ValueError(f"unknown reward terms {sorted(unknown)}; known: {sorted(REWARD_TERMS)}")
    terms = {name: w * REWARD_TERMS[name](s, gain) for name, w in weights.items()}
    total = np.sum(np.stack(list(terms.values())), axis=0) if terms else np.zeros(len(s["margin"]))
    return total, terms
