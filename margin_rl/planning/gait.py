"""Predefined gaits and their contact schedule: which foot is in stance when, and its touchdowns.

A gait is periodic with period T_g [s]; leg i lifts off at phase phi_i T_g (mod T_g) and touches down
``swing_duration`` later. Time is absolute (the planner's clock), so consecutive receding-horizon
plans share one schedule. Legs are LF, RF, LH, RH (margin_rl's order).

Conventions (why): a swing interval is *closed*, [lift-off, touchdown], so at an event instant the
foot counts as lifted (the conservative choice for a stability constraint evaluated at that instant).
The event-based foothold parametrisation of seed 000 §IV-B follows from the schedule: one foothold per
touchdown, held through the stance that follows it.

m_min (seed 000 §IV-B: "gait dependent"):

* walk: m_min = 0.0 m. A walk always keeps three feet down, so the capture point can stay inside a
  support triangle; zero demands that it never leaves it.
* trot: m_min = -0.05 m (the paper's value). With two diagonal contacts the feasible region is a
  segment and the largest achievable margin is zero; -0.05 bounds how far the capture point may
  drift from the support diagonal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LEGS: tuple[str, ...] = ("LF", "RF", "LH", "RH")


@dataclass(frozen=True)
class Gait:
    """A periodic gait (times in s, lengths in m, speeds in m/s)."""

    name: str
    period: float  # T_g
    swing_duration: float
    liftoff_phase: tuple[float, float, float, float]  # phi_i in [0, 1) for LF, RF, LH, RH
    min_margin: float  # m_min [m] of the minimum-stability-margin constraint
    speed: float  # nominal forward speed of the course
    swing_height: float  # apex of the swing foot above the line between footholds

    def __post_init__(self) -> None:
        if not (np.isfinite(self.period) and self.period > 0):
            raise ValueError(f"gait {self.name!r}: period must be a positive duration in s, got {self.period!r}")
        if not (0 < self.swing_duration < self.period):
            raise ValueError(
                f"gait {self.name!r}: swing_duration must lie in (0, period={self.period}) s, "
                f"got {self.swing_duration!r}"
            )
        if len(self.liftoff_phase) != len(LEGS) or not all(0 <= p < 1 for p in self.liftoff_phase):
            raise ValueError(f"gait {self.name!r}: liftoff_phase needs 4 phases in [0, 1), got {self.liftoff_phase!r}")
        if not (np.isfinite(self.speed) and self.speed >= 0):
            raise ValueError(f"gait {self.name!r}: speed must be >= 0 m/s, got {self.speed!r}")
        if not self.swing_height >= 0:
            raise ValueError(f"gait {self.name!r}: swing_height must be >= 0 m, got {self.swing_height!r}")


WALK = Gait(
    name="walk",
    period=2.0,
    swing_duration=0.3,
    # Lateral-sequence walk LH, LF, RH, RF in 0.5 s slots: 0.2 s of four-foot stance (in which the CoM
    # crosses to the next support triangle), then 0.3 s of swing. LH lifts off at 0.2 s.
    liftoff_phase=(0.35, 0.85, 0.1, 0.6),
    min_margin=0.0,
    speed=0.15,
    swing_height=0.1,
)

TROT = Gait(
    name="trot",
    period=0.8,
    swing_duration=0.35,  # 0.05 s of four-foot stance at each switch of diagonals
    liftoff_phase=(0.0, 0.5, 0.5, 0.0),
    min_margin=-0.05,
    speed=0.3,
    swing_height=0.1,
)

GAITS: dict[str, Gait] = {g.name: g for g in (WALK, TROT)}


def get_gait(name: str) -> Gait:
    """A built-in gait by name; the error lists the known ones."""
    if name not in GAITS:
        raise ValueError(f"unknown gait {name!r}; built-in gaits: {', '.join(GAITS)}")
    return GAITS[name]


@dataclass(frozen=True)
class Swing:
    """One swing of one leg: lift-off and touchdown times [s]."""

    leg: int
    liftoff: float
    touchdown: float


def swings_between(gait: Gait, t_start: float, t_end: float) -> list[Swing]:
    """Every swing of every leg that overlaps [t_start, t_end], sorted by leg then time."""
    if not t_end >= t_start:
        raise ValueError(f"need t_end >= t_start, got [{t_start}, {t_end}]")
    out = []
    for leg, phase in enumerate(gait.liftoff_phase):
        k0 = int(np.floor((t_start - gait.swing_duration) / gait.period - phase)) - 1
        k = k0
        while True:
            lo = (k + phase) * gait.period
            td = lo + gait.swing_duration
            k += 1
            if td < t_start - 1e-12:
                continue
            if lo > t_end + 1e-12:
                break
            out.append(Swing(leg, round(lo, 9), round(td, 9)))
    return out


def contact_flags(gait: Gait, t: np.ndarray) -> np.ndarray:
    """Contact flags (..., 4) in {0, 1} at times t (...) [s]; a foot at an event instant counts as lifted."""
    t = np.asarray(t, dtype=float)
    phase = (t[..., None] / gait.period - np.asarray(gait.liftoff_phase)) % 1.0
    in_swing = phase * gait.period <= gait.swing_duration + 1e-9
    # Touchdown exactly at the period boundary reads phase ~ 1 - eps: also an event instant.
    in_swing |= (1.0 - phase) * gait.period <= 1e-9
    return (~in_swing).astype(float)
