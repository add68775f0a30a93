r"""The aSLIP model's pieces: parameters, hop outcomes, the actuator profile and the stance vector field.

The model (nondimensional units, phases, guards, failure modes) is described in
:mod:`margin_rl.slip.dynamics`, which simulates hops with these pieces and re-exports the public names;
:mod:`margin_rl.slip.stance` integrates the stance phase.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["SlipParams", "Status", "actuator_profile", "apex_energy", "stance_rhs"]

FloatArray = NDArray[np.float64]


class Status(enum.IntEnum):
    """Outcome of one hop from apex to apex (0 means success)."""

    OK = 0
    FALL = 1
    SLIP = 2
    NO_LIFTOFF = 3
    NO_APEX = 4
    NO_TOUCHDOWN = 5


@dataclass(frozen=True)
class SlipParams:
    """Nondimensional aSLIP parameters.

    Parameters
    ----------
    stiffness : float
        Leg spring stiffness :math:`k` in :math:`[m g / l_0]` (paper: 20).
    damping_ratio : float
        :math:`\\zeta = c / (2\\sqrt{k m})` (paper: 0.1).
    friction : float
        Coulomb friction coefficient :math:`\\mu` (paper: 0.5).
    extension_time : float
        Duration :math:`T_e` of the actuator smoothstep in :math:`[\\sqrt{l_0/g}]`.  Not given
        in the paper; 0.1 is about a third of the decompression half of a stance.
    max_stance_time : float
        Stance longer than this is a ``NO_LIFTOFF`` failure (a loaded stance lasts about
        :math:`\\pi/\\sqrt{k} \\approx 0.7`).
    """

    stiffness: float = 20.0
    damping_ratio: float = 0.1
    friction: float = 0.5
    extension_time: float = 0.1
    max_stance_time: float = 3.0

    def __post_init__(self) -> None:
        checks = {
            "stiffness": self.stiffness > 0,
            "damping_ratio": self.damping_ratio >= 0,
            "friction": self.friction >= 0,
            "extension_time": self.extension_time > 0,
            "max_stance_time": self.max_stance_time > 0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (ok and np.isfinite(value)):
                raise ValueError(f"SlipParams.{name} is invalid: {value!r}")

    @property
    def damping(self) -> float:
        """Damping coefficient :math:`c = 2 \\zeta \\sqrt{k m}` with :math:`m = 1`."""
        return 2.0 * self.damping_ratio * float(np.sqrt(self.stiffness))


def actuator_profile(tau: ArrayLike, delta_l: ArrayLike, extension_time: float) -> tuple[FloatArray, FloatArray]:
    """Actuator length and rate, :math:`L_a` and :math:`\\dot L_a`, ``tau`` after max compression.

    Returns zeros for ``tau <= 0`` (before maximum compression, or ``tau = -inf``).
    """
    tau_arr = np.asarray(tau, dtype=float)
    dl = np.asarray(delta_l, dtype=float)
    sigma = np.clip(tau_arr / extension_time, 0.0, 1.0)
    length = dl * sigma * sigma * (3.0 - 2.0 * sigma)
    rate = dl * 6.0 * sigma * (1.0 - sigma) / extension_time
    return length, rate


def apex_energy(y: ArrayLike, xdot: ArrayLike) -> FloatArray:
    """Mechanical energy at an apex, :math:`E = \\dot x^2 / 2 + y` in :math:`[m g l_0]`."""
    return 0.5 * np.square(np.asarray(xdot, dtype=float)) + np.asarray(y, dtype=float)


def stance_rhs(
    t: FloatArray | float,
    z: FloatArray,
    t_mc: FloatArray | float,
    delta_l: FloatArray | float,
    p: SlipParams,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Stance vector field on ``z = [x - x_f, y, xdot, ydot, W_act, W_damp]`` (rows).

    Works on shape ``(6,)`` or ``(6, n)``.  Returns ``(dz, ldot, F)`` so that callers get the
    quantities their event functions need without recomputation.
    """
    xr, y, vx, vy = z[0], z[1], z[2], z[3]
    length = np.sqrt(xr * xr + y * y)
    ldot = (xr * vx + y * vy) / length
    la, la_dot = actuator_profile(np.asarray(t) - t_mc, delta_l, p.extension_time)
    delta_dot = la_dot - ldot
    force = p.stiffness * (1.0 + la - length) + p.damping * delta_dot
    f_over_l = force / length
    dz = np.stack([vx, vy, f_over_l * xr, f_over_l * y - 1.0, force * la_dot, p.damping * delta_dot * delta_dot])
    return dz, ldot, force
