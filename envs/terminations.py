"""Termination causes: named conditions, declared once, each computed on its own and OR'ed into ``terminated``.

Every step reports each cause per environment as ``info["termination_<cause>"]`` (float64, 1 where it holds);
``margin_rl.train.metrics`` turns them into the fraction of episodes each cause ended. Several causes can
hold on the same step (a fall often brings base contact, low height and tilt together). A diverged
simulation reports ``diverged`` only: its state was zeroed for the bookkeeping, and the physical conditions
read off zeros would mean nothing.

=================  ===================================================================================
``base_contact``   the base touches the terrain
``thigh_contact``  a thigh touches the terrain
``base_height``    the base is lower than ``TerminationConfig.min_base_height`` above the terrain under it
``tilt``           the base z axis is more than ``TerminationConfig.max_tilt_rad`` from the vertical
``diverged``       the simulation diverged (non-finite or runaway state, or MuJoCo reset it)
=================  ===================================================================================
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from margin_rl.arrays import namespace
from margin_rl.envs.config import TerminationConfig

Arrays = dict[str, Any]
"""Per-environment inputs: ``base_contact`` (N,), ``thigh_contacts`` (N, 4), ``base_height`` (N,) above the
terrain [m], ``tilt_cos`` (N,) the cosine of the base tilt, ``diverged`` (N,), all bool or float64; all numpy
arrays or all torch tensors (each condition is written once, in the array API standard's names)."""


@dataclass(frozen=True)
class TerminationCause:
    """One named reason to end an episode: ``condition(inputs, bounds)`` is (N,) bool."""

    name: str
    description: str
    condition: Callable[[Arrays, TerminationConfig], Any]

    @property
    def info_key(self) -> str:
        """Its key in the step info: ``termination_<name>``."""
        return info_key(self.name)


def info_key(cause: str) -> str:
    """The step-info key of termination cause ``cause``: ``termination_<cause>``."""
    return f"termination_{cause}"


def _any_leg(s: Arrays, bounds: TerminationConfig) -> Any:
    return namespace(s["thigh_contacts"]).any(s["thigh_contacts"], axis=1)


TERMINATION_CAUSES: tuple[TerminationCause, ...] = (
    TerminationCause("base_contact", "the base touches the terrain", lambda s, b: s["base_contact"]),
    TerminationCause("thigh_contact", "a thigh touches the terrain", _any_leg),
    TerminationCause(
        "base_height", "base below min_base_height above the terrain", lambda s, b: s["base_height"] < b.min_base_height
    ),
    TerminationCause("tilt", "base tilted beyond max_tilt_rad", lambda s, b: s["tilt_cos"] < math.cos(b.max_tilt_rad)),
    TerminationCause("diverged", "the simulation diverged", lambda s, b: s["diverged"]),
)
"""The causes, in the order they are reported."""

CAUSE_NAMES: tuple[str, ...] = tuple(c.name for c in TERMINATION_CAUSES)
INFO_KEYS: tuple[str, ...] = tuple(c.info_key for c in TERMINATION_CAUSES)


def termination_causes(inputs: Arrays, bounds: TerminationConfig) -> dict[str, Any]:
    """Each cause's (N,) bool flags; a diverged environment has only ``diverged`` set (module docstring)."""
    xp = namespace(inputs["diverged"])
    finite_state = ~xp.astype(inputs["diverged"], xp.bool, copy=False)
    causes = {}
    for cause in TERMINATION_CAUSES:
        holds = xp.astype(cause.condition(inputs, bounds), xp.bool, copy=False)
        causes[cause.name] = holds if cause.name == "diverged" else holds & finite_state
    return causes


def any_cause(causes: dict[str, Any]) -> Any:
    """``terminated``: (N,) True where any cause holds."""
    flags = [causes[name] for name in CAUSE_NAMES]
    xp = namespace(*flags)
    return xp.any(xp.stack(flags, axis=1), axis=1)  # one reduction, not an OR per cause
