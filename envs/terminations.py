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

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from margin_rl.envs.config import TerminationConfig

Arrays = dict[str, np.ndarray]
"""Per-environment inputs: ``base_contact`` (N,), ``thigh_contacts`` (N, 4), ``base_height`` (N,) above the
terrain [m], ``tilt_cos`` (N,) the cosine of the base tilt, ``diverged`` (N,), all bool or float64."""


@dataclass(frozen=True)
class TerminationCause:
    """One named reason to end an episode: ``condition(inputs, bounds)`` is (N,) bool."""

    name: str
    description: str
    condition: Callable[[Arrays, TerminationConfig], np.ndarray]

    @property
    def info_key(self) -> str:
        """Its key in the step info: ``termination_<name>``."""
        return info_key(self.name)


def info_key(cause: str) -> str:
    """The step-info key of termination cause ``cause``: ``termination_<cause>``."""
    return f"termination_{cause}"


TERMINATION_CAUSES: tuple[TerminationCause, ...] = (
    TerminationCause("base_contact", "the base touches the terrain", lambda s, b: s["base_contact"]),
    TerminationCause("thigh_contact", "a thigh touches the terrain", lambda s, b: s["thigh_contacts"].any(axis=1)),
    TerminationCause(
        "base_height", "base below min_base_height above the terrain", lambda s, b: s["base_height"] < b.min_base_height
    ),
    TerminationCause("tilt", "base tilted beyond max_tilt_rad", lambda s, b: s["tilt_cos"] < np.cos(b.max_tilt_rad)),
    TerminationCause("diverged", "the simulation diverged", lambda s, b: s["diverged"]),
)
"""The causes, in the order they are reported."""

CAUSE_NAMES: tuple[str, ...] = tuple(c.name for c in TERMINATION_CAUSES)
INFO_KEYS: tuple[str, ...] = tuple(c.info_key for c in TERMINATION_CAUSES)


def termination_causes(inputs: Arrays, bounds: TerminationConfig) -> dict[str, np.ndarray]:
    """Each cause's (N,) bool flags; a diverged environment has only ``diverged`` set (module docstring)."""
    diverged = np.asarray(inputs["diverged"], dtype=bool)
    finite_state = ~diverged
    causes = {}
    for cause in TERMINATION_CAUSES:
        holds = np.asarray(cause.condition(inputs, bounds), dtype=bool)
        causes[cause.name] = holds if cause.name == "diverged" else holds & finite_state
    return causes


def any_cause(causes: dict[str, np.ndarray]) -> np.ndarray:
    """``terminated``: (N,) True where any cause holds."""
    return np.logical_or.reduce([causes[name] for name in CAUSE_NAMES])
