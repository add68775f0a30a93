"""The 47-D stability input lambda of seed 000 eq. (4), declared once.

    lambda = ( e_g | c_dot, c_ddot, w_dot, f_ext, tau_ext, p_1..p_4 | mu, c_1..c_4, n_1..n_4 )  in R^47

Frames
------
* ``gravity_axis``: e_g, the third row of the base orientation matrix R (base in a gravity-aligned
  frame), i.e. the world up axis expressed in the base frame B (unit vector; (0, 0, 1) when level).
* Every other vector is expressed in the *horizontal frame* H: origin at the robot's CoM, z against
  gravity, x along the heading (the base x axis projected on the horizontal plane), so H differs from
  the world by position and yaw and from B by roll and pitch. Feet are therefore positions relative
  to the CoM, which is how lambda encodes where the CoM is.
* ``feet`` are the foot-sphere centres (the ``<leg>_FOOT`` sites); the contact point of foot i is
  p_i - r n_i for a sphere of radius r touching a surface of normal n_i.
* ``contacts`` are 0/1 flags, ``normals`` unit surface normals pointing out of the terrain.

Leg order is LF, RF, LH, RH everywhere. :data:`LAMBDA_FIELDS` is the only place the layout is
written; slices, names and converters are derived from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from margin_rl.arrays import namespace

N_FEET = 4


@dataclass(frozen=True)
class LambdaField:
    """One named block of lambda."""

    name: str
    shape: tuple[int, ...]
    frame: str  # "B" base, "H" horizontal, "-" frame-free
    unit: str
    description: str
    # How the field transforms under the sagittal mirror (y -> -y): "polar" vectors flip their y
    # component, "axial" vectors (angular quantities, torques) flip x and z, "even" entries keep their
    # sign. Per-foot fields (leading dimension N_FEET) also swap left and right legs.
    parity: str = "even"

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))


LAMBDA_FIELDS: tuple[LambdaField, ...] = (
    LambdaField("gravity_axis", (3,), "B", "-", "e_g: world up axis in the base frame (3rd row of R)", "polar"),
    LambdaField("com_vel", (3,), "H", "m/s", "CoM linear velocity c_dot", "polar"),
    LambdaField("com_acc", (3,), "H", "m/s^2", "CoM linear acceleration c_ddot", "polar"),
    LambdaField("base_ang_acc", (3,), "H", "rad/s^2", "base angular acceleration w_dot", "axial"),
    LambdaField("ext_force", (3,), "H", "N", "external force on the robot, applied at the CoM", "polar"),
    LambdaField("ext_torque", (3,), "H", "N m", "external torque on the robot", "axial"),
    LambdaField("feet", (N_FEET, 3), "H", "m", "foot-sphere centres relative to the CoM, LF RF LH RH", "polar"),
    LambdaField("mu", (1,), "-", "-", "terrain friction coefficient"),
    LambdaField("contacts", (N_FEET,), "-", "-", "contact flags c_i in {0, 1}"),
    LambdaField("normals", (N_FEET, 3), "H", "-", "terrain normals at the feet (unit, out of the terrain)", "polar"),
)

LAMBDA_DIM: int = sum(f.size for f in LAMBDA_FIELDS)


def _slices() -> dict[str, slice]:
    out, start = {}, 0
    for f in LAMBDA_FIELDS:
        out[f.name] = slice(start, start + f.size)
        start += f.size
    return out


LAMBDA_SLICES: dict[str, slice] = _slices()
"""Slice of each field in the flat 47-vector."""

_AXES = ("x", "y", "z")

MIRROR_LEGS: tuple[int, ...] = (1, 0, 3, 2)
"""Mirror partner of each leg (LF <-> RF, LH <-> RH) under the sagittal mirror y -> -y."""

_FLIPPED_AXES = {"polar": (1,), "axial": (0, 2), "even": ()}


def _mirror_map() -> tuple[np.ndarray, np.ndarray]:
    """The sagittal mirror as a signed permutation of lambda: mirror(lam)[k] = sign[k] * lam[source[k]]."""
    source, sign = np.arange(LAMBDA_DIM), np.ones(LAMBDA_DIM)
    for f in LAMBDA_FIELDS:
        start = LAMBDA_SLICES[f.name].start
        per_foot = f.shape[0] == N_FEET
        block = np.arange(f.size).reshape((N_FEET, -1) if per_foot else (1, -1))
        if per_foot:
            block = block[list(MIRROR_LEGS)]
        source[start : start + f.size] = start + block.ravel()
        flip = np.ones(block.shape[1])
        if block.shape[1] == 3:
            flip[list(_FLIPPED_AXES[f.parity])] = -1.0
        elif f.parity != "even":
            raise ValueError(f"lambda field {f.name!r}: parity {f.parity!r} needs 3 components")
        sign[start : start + f.size] = np.tile(flip, block.shape[0])
    return source, sign


MIRROR_SOURCE, MIRROR_SIGN = _mirror_map()
"""Index map and signs of :func:`mirror_lambda` (an involution: applying it twice is the identity)."""


def float_array_with_last_dim(values: np.ndarray, size: int, name: str) -> np.ndarray:
    """``values`` as a float array of shape (..., size), else a ValueError naming ``name`` and the shape."""
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 0 or arr.shape[-1] != size:
        raise ValueError(f"{name} must have last dimension {size}, got shape {arr.shape}")
    return arr


def _lambda_array(lam: np.ndarray) -> np.ndarray:
    """``lam`` as a float array of shape (..., 47); shape only (NaN is :func:`check_lambda`'s business)."""
    return float_array_with_last_dim(lam, LAMBDA_DIM, "lambda")


def mirror_lambda(lam: np.ndarray) -> np.ndarray:
    """lambda of the sagittally mirrored state (reflection y -> -y of the world and the robot): (..., 47).

    Polar vectors (e_g, CoM velocity and acceleration, external force, feet, normals) flip their y
    component, axial vectors (base angular acceleration, external torque) flip x and z, and the per-foot
    fields swap left and right legs (LF <-> RF, LH <-> RH). For a robot whose model is symmetric about
    its sagittal plane (ANYmal B and C) the stability margin is invariant: m(mirror(lam)) = m(lam).
    Returns a new array; the input is not modified.
    """
    return _lambda_array(lam)[..., MIRROR_SOURCE] * MIRROR_SIGN


def lambda_names() -> tuple[str, ...]:
    """One readable name per lambda entry, e.g. ``com_acc.x``, ``feet.LF.z``, ``contacts.RH``."""
    legs = ("LF", "RF", "LH", "RH")
    names: list[str] = []
    for f in LAMBDA_FIELDS:
        if f.shape == (1,):
            names.append(f.name)
        elif f.shape == (3,):
            names.extend(f"{f.name}.{a}" for a in _AXES)
        elif f.shape == (N_FEET,):
            names.extend(f"{f.name}.{leg}" for leg in legs)
        else:
            names.extend(f"{f.name}.{leg}.{a}" for leg in legs for a in _AXES)
    return tuple(names)


@dataclass(frozen=True)
class StabilityState:
    """lambda as named arrays (see the module docstring for frames and units).

    Every field may carry leading batch dimensions: ``com_vel`` has shape (..., 3), ``feet`` (..., 4, 3),
    ``mu`` (...,), ``contacts`` (..., 4) and so on.
    """

    gravity_axis: np.ndarray
    com_vel: np.ndarray
    com_acc: np.ndarray
    base_ang_acc: np.ndarray
    ext_force: np.ndarray
    ext_torque: np.ndarray
    feet: np.ndarray
    mu: np.ndarray
    contacts: np.ndarray
    normals: np.ndarray

    def to_lambda(self) -> Any:
        """Flatten to (..., 47) in the order of :data:`LAMBDA_FIELDS`, float64, as a numpy array or, when the
        fields are torch tensors, a tensor on their device (:func:`margin_rl.arrays.namespace`)."""
        values = [getattr(self, f.name) for f in LAMBDA_FIELDS]
        xp = namespace(*values)
        batch = tuple(xp.asarray(self.mu).shape)
        parts = []
        for f, raw in zip(LAMBDA_FIELDS, values, strict=True):
            value = xp.asarray(raw, dtype=xp.float64)
            expected = batch + (() if f.shape == (1,) else f.shape)
            if tuple(value.shape) != expected:
                raise ValueError(f"StabilityState.{f.name} has shape {tuple(value.shape)}, expected {expected}")
            flat = (*batch, f.size)
            parts.append(value if tuple(value.shape) == flat else xp.reshape(value, flat))
        return xp.concat(parts, axis=-1)


assert [f.name for f in fields(StabilityState)] == [f.name for f in LAMBDA_FIELDS]  # one layout


def check_lambda(lam: np.ndarray, name: str = "lam") -> np.ndarray:
    """Validate the shape and finiteness of lambda; returns it as a float array.

    Raises:
        ValueError: wrong last dimension, or a NaN/inf entry (the message names the lambda field).
    """
    arr = np.asarray(lam, dtype=float)
    if arr.ndim == 0 or arr.shape[-1] != LAMBDA_DIM:
        raise ValueError(f"{name} must have shape ({LAMBDA_DIM},) or (N, {LAMBDA_DIM}), got {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        names = lambda_names()
        columns = sorted(set(np.nonzero(bad.reshape(-1, LAMBDA_DIM))[1].tolist()))
        raise ValueError(f"{name} has NaN or infinite entries in {', '.join(names[c] for c in columns)}")
    return arr


def from_lambda(lam: np.ndarray) -> StabilityState:
    """Split (..., 47) into a :class:`StabilityState` (views, no copies)."""
    arr = _lambda_array(lam)
    batch = arr.shape[:-1]
    values = {}
    for f in LAMBDA_FIELDS:
        block = arr[..., LAMBDA_SLICES[f.name]]
        values[f.name] = block[..., 0] if f.shape == (1,) else block.reshape(*batch, *f.shape)
    return StabilityState(**values)


def gravity_axis_from_roll_pitch(roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """e_g for base roll and pitch angles [rad] (Z-Y-X Euler, yaw irrelevant): (..., 3)."""
    roll, pitch = np.asarray(roll, dtype=float), np.asarray(pitch, dtype=float)
    return np.stack([-np.sin(pitch), np.cos(pitch) * np.sin(roll), np.cos(pitch) * np.cos(roll)], axis=-1)


def base_rotation_from_gravity_axis(gravity_axis: np.ndarray) -> np.ndarray:
    """Orientation R_HB of the base in the horizontal frame, from e_g: (..., 3) -> (..., 3, 3).

    With Z-Y-X Euler angles R = Rz(yaw) Ry(pitch) Rx(roll), the third row of R is
    (-sin pitch, cos pitch sin roll, cos pitch cos roll) whatever the yaw, so pitch = -asin(e_x) and
    roll = atan2(e_y, e_z). H has zero yaw by definition, hence R_HB = Ry(pitch) Rx(roll).

    Raises:
        ValueError: if a gravity axis is not a unit vector (to 1e-3).
    """
    e = np.asarray(gravity_axis, dtype=float)
    if e.shape == (3,):
        return _base_rotation_single(e)
    norm = np.linalg.norm(e, axis=-1, keepdims=True)
    if not np.all(np.abs(norm - 1.0) <= 1e-3):
        raise ValueError(f"gravity_axis must be a unit vector, got norms {np.unique(norm.round(4)).tolist()[:5]}")
    e = e / norm
    pitch = -np.arcsin(np.clip(e[..., 0], -1.0, 1.0))
    roll = np.arctan2(e[..., 1], e[..., 2])
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    zero = np.zeros_like(cr)
    return np.stack(
        [np.stack([cp, sp * sr, sp * cr], -1), np.stack([zero, cr, -sr], -1), np.stack([-sp, cp * sr, cp * cr], -1)],
        axis=-2,
    )


def _base_rotation_single(e: np.ndarray) -> np.ndarray:
    """:func:`base_rotation_from_gravity_axis` of one (3,) axis, in Python floats, bit-identical to it.

    The same operations in the same order (numpy's arcsin, arctan2, cos and sin, not the math
    module's, which round differently in the last bit); for one state the batched code spends ~40 us
    in numpy's per-call overhead.
    """
    ex, ey, ez = e.tolist()
    norm = math.sqrt(ex * ex + ey * ey + ez * ez)  # np.linalg.norm sums the squares in this order
    if not abs(norm - 1.0) <= 1e-3:
        raise ValueError(f"gravity_axis must be a unit vector, got norms {[round(norm, 4)]}")
    ex, ey, ez = ex / norm, ey / norm, ez / norm
    pitch = -float(np.arcsin(min(max(ex, -1.0), 1.0)))
    roll = float(np.arctan2(ey, ez))
    cr, sr, cp, sp = float(np.cos(roll)), float(np.sin(roll)), float(np.cos(pitch)), float(np.sin(pitch))
    return np.array([[cp, sp * sr, sp * cr], [0.0, cr, -sr], [-sp, cp * sr, cp * cr]])
