"""The event-based foot parametrisation of one planning horizon (seed 000 §IV-B).

Each leg's footholds over a horizon [t0, t0 + T] form a sequence: its current foothold (known: where it
stands, or where it lifted off if it is in the air at t0), then one foothold per touchdown, each held
through the stance that follows. The foot-sphere centre at time t is

* in stance on foothold q_j: q_j + r n(q_j) (a sphere of radius r resting on the terrain at q_j);
* in swing from q_j to q_{j+1} (s = (t - t_liftoff) / (t_touchdown - t_liftoff) in [0, 1]):
  (1 - b) centre_j + b centre_{j+1} + 4 s (1 - s) h_swing e_z, with b = 3 s^2 - 2 s^3.

The blend is written once for numpy arrays and CasADi expressions alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from margin_rl.planning.gait import Gait, Swing, contact_flags, swings_between


@dataclass(frozen=True)
class FootholdSlot:
    """One foothold decision variable: leg i touches down at ``touchdown`` and stands until ``stance_end`` [s]."""

    leg: int
    touchdown: float
    stance_end: float


@dataclass(frozen=True)
class HorizonSchedule:
    """Node times, contact flags and the foothold slots of one horizon."""

    gait: Gait
    t0: float
    node_times: np.ndarray  # (N + 1,) [s]
    contacts: np.ndarray  # (N + 1, 4) flags at the nodes
    swings: tuple[tuple[Swing, ...], ...]  # per leg, the swings with touchdown after t0, in time order
    slots: tuple[FootholdSlot, ...]  # one per swing, leg-major: the order of the foothold variables

    @property
    def n_nodes(self) -> int:
        return len(self.node_times)

    def slot_indices(self, leg: int) -> list[int]:
        """Indices into :attr:`slots` of ``leg``'s footholds, in time order."""
        return [k for k, s in enumerate(self.slots) if s.leg == leg]

    def phase_key(self) -> tuple:
        """What fixes the problem's structure: gait, t0 modulo the period, node count."""
        return (self.gait, round(self.t0 % self.gait.period, 6), self.n_nodes)

    def swing_fraction(self, leg: int, t: float) -> float | None:
        """s in [0, 1] if ``leg`` is in swing at time t (closed interval), else None."""
        for swing in self.swings[leg]:
            if swing.liftoff <= t <= swing.touchdown:
                return (t - swing.liftoff) / (swing.touchdown - swing.liftoff)
        return None

    def foot_centre(self, leg: int, t: float, centres: list, up):
        """Foot-sphere centre of ``leg`` at time t from its foothold centres (sequence index 0 = current).

        ``centres[j]`` is the centre over foothold j (numpy (3,) or a CasADi (3, 1)); ``up`` is e_z
        in the same type. Times beyond the last touchdown keep the last foothold.
        """
        swings = self.swings[leg]
        j = 0
        for swing in swings:
            if t < swing.liftoff:
                break
            if t <= swing.touchdown:
                s = (t - swing.liftoff) / (swing.touchdown - swing.liftoff)
                blend = 3 * s**2 - 2 * s**3
                return (1 - blend) * centres[j] + blend * centres[j + 1] + 4 * s * (1 - s) * self.gait.swing_height * up
            j += 1
        return centres[j]


def horizon_schedule(gait: Gait, t0: float, horizon: float, node_dt: float) -> HorizonSchedule:
    """The schedule of [t0, t0 + horizon] with base nodes every ``node_dt`` [s].

    Raises:
        ValueError: non-positive horizon or node spacing, or a horizon that is not a whole number of nodes.
    """
    if not (np.isfinite(horizon) and horizon > 0):
        raise ValueError(f"horizon must be a positive duration in s, got {horizon!r}")
    if not (np.isfinite(node_dt) and node_dt > 0):
        raise ValueError(f"node_dt must be a positive duration in s, got {node_dt!r}")
    n = horizon / node_dt
    if abs(n - round(n)) > 1e-9 or round(n) < 2:
        raise ValueError(f"horizon {horizon} s must be a whole number (>= 2) of node spacings {node_dt} s")
    times = t0 + node_dt * np.arange(round(n) + 1)
    t_end = float(times[-1])
    per_leg: list[list[Swing]] = [[] for _ in range(4)]
    for swing in swings_between(gait, t0, t_end):
        # A swing whose touchdown is at or before t0 is over: that foot stands on its current foothold.
        if swing.touchdown > t0 + 1e-9:
            per_leg[swing.leg].append(swing)
    stance = gait.period - gait.swing_duration
    slots = tuple(
        FootholdSlot(leg, s.touchdown, s.touchdown + stance)
        for leg in range(4)
        for s in sorted(per_leg[leg], key=lambda x: x.liftoff)
    )
    return HorizonSchedule(
        gait=gait,
        t0=float(t0),
        node_times=times,
        contacts=contact_flags(gait, times),
        swings=tuple(tuple(sorted(s, key=lambda x: x.liftoff)) for s in per_leg),
        slots=slots,
    )
