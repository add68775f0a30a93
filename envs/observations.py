"""The observation layout, declared once: names, sizes, scales and noise levels.

The policy observation is the concatenation of :data:`POLICY_OBSERVATIONS` in order (and, with
``EnvConfig.height_scan``, :data:`HEIGHT_SCAN` after them: :func:`policy_observations`), each multiplied by
its scale (legged_gym's normalisation) and perturbed by uniform noise of half-width
``noise * scale * RandomizationConfig.observation_noise``. Frames: velocities in the base frame,
gravity projected into the base frame, joint positions relative to the standing keyframe.
:data:`PRIVILEGED_OBSERVATIONS` is the optional critic group.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from margin_rl.arrays import constant, namespace, reshaped, rotate

if TYPE_CHECKING:
    from margin_rl.envs.step_data import SimulationState


@dataclass(frozen=True)
class ObservationTerm:
    name: str
    size: int
    scale: float
    noise: float  # uniform half-width before scaling, in the term's units
    description: str


POLICY_OBSERVATIONS: tuple[ObservationTerm, ...] = (
    ObservationTerm("base_lin_vel", 3, 2.0, 0.1, "base linear velocity, base frame [m/s]"),
    ObservationTerm("base_ang_vel", 3, 0.25, 0.2, "base angular velocity, base frame [rad/s]"),
    ObservationTerm("projected_gravity", 3, 1.0, 0.05, "unit gravity direction in the base frame"),
    ObservationTerm("command", 3, 2.0, 0.0, "command: forward, lateral velocity [m/s], yaw rate [rad/s]"),
    ObservationTerm("joint_pos", 12, 1.0, 0.01, "joint angles minus the standing keyframe [rad]"),
    ObservationTerm("joint_vel", 12, 0.05, 1.5, "joint velocities [rad/s]"),
    ObservationTerm("last_action", 12, 1.0, 0.0, "previous action"),
)

HEIGHT_SCAN_POINTS: tuple[tuple[float, float], ...] = tuple(
    (round(0.1 * i, 10), round(0.1 * j, 10)) for i in range(-8, 9) for j in range(-5, 6)
)
"""Where the actor's height scan samples the terrain: a 1.6 m x 1.0 m grid at 0.1 m (17 x 11 points, x-major) in the
heading frame (x forwards, y to the left, yaw of the base only), centred on the base: the field's grid for ANYmal
(legged_gym's, Isaac Lab's)."""

HEIGHT_SCAN_CLIP = 1.0
"""The scan's values are clipped to [-HEIGHT_SCAN_CLIP, HEIGHT_SCAN_CLIP] [m] (a cliff or a wall reads as one metre)."""

HEIGHT_SCAN = ObservationTerm(
    "height_scan",
    len(HEIGHT_SCAN_POINTS),
    5.0,
    0.1,
    "base height above the terrain at each scan point minus the standing height, clipped to +-1 m [m]",
)
"""The optional terrain-perception group of the actor (``EnvConfig.height_scan``): 0 everywhere for a robot standing
on flat ground, positive where the ground is lower than under a standing robot, negative where it is higher. Noise:
+-0.1 m (uniform, the field's default), scaled by ``RandomizationConfig.observation_noise`` like every term."""

FOOT_HEIGHT_OFFSETS: tuple[tuple[float, float], ...] = tuple(
    (dx, dy) for dx in (-0.1, 0.0, 0.1) for dy in (-0.1, 0.0, 0.1)
)
"""Horizontal offsets [m] around each foot where the privileged group samples the terrain height."""

PRIVILEGED_OBSERVATIONS: tuple[ObservationTerm, ...] = (
    ObservationTerm(
        "foot_terrain_heights",
        4 * len(FOOT_HEIGHT_OFFSETS),
        5.0,
        0.0,
        "foot height above the terrain at 3x3 points around each foot [m]",
    ),
    ObservationTerm("friction", 1, 1.0, 0.0, "terrain friction coefficient"),
    ObservationTerm("margin", 1, 10.0, 0.0, "stability margin of the current state [m]"),
)


def policy_observations(height_scan: bool = False) -> tuple[ObservationTerm, ...]:
    """The actor's observation terms in order: :data:`POLICY_OBSERVATIONS`, then :data:`HEIGHT_SCAN` when asked
    (``EnvConfig.height_scan``)."""
    return POLICY_OBSERVATIONS + ((HEIGHT_SCAN,) if height_scan else ())


def observation_structure(terms: tuple[ObservationTerm, ...] = POLICY_OBSERVATIONS) -> dict[str, int]:
    """Name -> size, in order (Gymnasium's ``observation_structure``)."""
    return {t.name: t.size for t in terms}


def observation_size(terms: tuple[ObservationTerm, ...] = POLICY_OBSERVATIONS) -> int:
    return sum(t.size for t in terms)


def assemble(values: dict[str, Any], terms: tuple[ObservationTerm, ...], noise_level: float, rng: Any) -> Any:
    """Concatenate scaled (and optionally noisy) terms: values[name] has shape (N, size) -> (N, total) float32.

    ``values``: all numpy arrays or all torch tensors (:mod:`margin_rl.arrays`); ``rng``: a generator of their kind
    (:func:`margin_rl.arrays.random_generator`)."""
    xp = namespace(*values.values())
    parts = []
    for t in terms:
        v = xp.astype(xp.asarray(values[t.name]), xp.float64, copy=False)
        v = reshaped(v, (int(v.shape[0]), t.size))  # (N, ...) flattened per environment
        if noise_level > 0 and t.noise > 0:
            v = v + rng.uniform(-1.0, 1.0, size=v.shape) * t.noise * noise_level
        parts.append(v)
    # every term scaled in one product (on a device one operation, not one per term)
    return xp.astype(xp.concat(parts, axis=1) * constant(_scales(terms), parts[0]), xp.float32)


@functools.cache
def _scales(terms: tuple[ObservationTerm, ...]) -> np.ndarray:
    """Each observation entry's scale, in the order of ``terms``."""
    return np.repeat([t.scale for t in terms], [t.size for t in terms])


def robot_state_terms(state: SimulationState, command: Any, standing_joint_pos: Any) -> dict[str, Any]:
    """The robot-state terms of the policy observation (unscaled, in the frames of :data:`POLICY_OBSERVATIONS`) from a
    world-frame state, with the environments' commands (N, 3) and the standing keyframe's joint angles (12,)."""
    R = state.base_rot
    return {
        "base_lin_vel": rotate(R, state.lin_vel_world, inverse=True),  # base frame
        "base_ang_vel": state.ang_vel_body,
        "projected_gravity": -R[:, 2, :],
        "command": command,
        "joint_pos": state.joint_pos - standing_joint_pos,
        "joint_vel": state.joint_vel,
    }
