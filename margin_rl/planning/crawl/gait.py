"""The statically stable crawl of seed 004 §V: base-motion and swing phases alternate, footholds by a stated rule.

One crawl *step* is a base-motion phase (four feet on the ground, the CoM moves) followed by a swing
phase (one foot in the air, the base holds still). The swing order is ANYmal's and HyQ's crawl order
LH, LF, RH, RF, so every triple stance keeps a diagonal pair and the front or hind foot of the other
side on the ground.

Foothold rule (:func:`next_foothold`): a swing foot lands one stride ahead of where it lifted off, half
a stride on its first step from the standing pose, so the feet stay centred around the body. The
footholds do not depend on the CoM planner (the paper's decoupled approach: footholds first, then
the CoM), so all planners crawl on the same footholds. Over a cycle every foot advances by one stride
and so does the CoM on average: the crawl's mean speed is ``stride / (4 (duration_bm + duration_swing))``.

Frames: world W, z up, the crawl heads along +x; positions in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LEGS: tuple[str, ...] = ("LF", "RF", "LH", "RH")
"""Leg order of every per-foot array (the package's)."""

SWING_ORDER: tuple[str, ...] = ("LH", "LF", "RH", "RF")
"""Crawl sequence: each hind foot is followed by the front foot of the same side."""


@dataclass(frozen=True)
class CrawlGait:
    """Timing and geometry of the crawl (SI units).

    Attributes:
        stride: distance [m] each foot moves forward per cycle (four steps).
        swing_duration: duration [s] of one swing phase.
        step_height: apex of the swing foot above the straight line between lift-off and touchdown [m].
        base_motion_duration: nominal duration [s] of a base-motion phase (the heuristic planner's; the
            FWP and CWC planners choose their own within ``duration_bounds``).
        duration_bounds: bounds [s] on the planned base-motion duration Delta t_bm.
        knots: N, knots of a base-motion plan (seed 004 Table III: 10).
        stability_margin: distance [m] the CoM must stay inside the next triple-stance support triangle
            at the end of a base motion (every planner).
        max_acceleration: bound [m/s^2] on each horizontal CoM acceleration component of an optimised plan
            (twice the heuristic's minimum-jerk peak for a 6 cm motion in 1.2 s).
        workspace_box: half-widths (x, y) [m] of the box around each foot's standing offset from the CoM
            that the optimised CoM keeps every foot in (the legs' range of motion; ANYmal B and C reach
            +-0.20 m along x and +-0.10 m across at standing height, so the box keeps a margin). Without it
            the FWP planner, whose polytope is linearised at one pose, pulls the CoM out of the legs' reach.
    """

    stride: float = 0.20
    swing_duration: float = 0.6
    step_height: float = 0.08
    base_motion_duration: float = 1.2
    duration_bounds: tuple[float, float] = (0.6, 3.0)
    knots: int = 10
    stability_margin: float = 0.03
    max_acceleration: float = 0.5
    workspace_box: tuple[float, float] = (0.15, 0.05)

    def __post_init__(self) -> None:
        for name in ("stride", "swing_duration", "step_height", "base_motion_duration", "stability_margin",
                     "max_acceleration"):  # fmt: skip
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"CrawlGait.{name} must be a positive number, got {value!r}")
        low, high = self.duration_bounds
        if not (0 < low <= self.base_motion_duration <= high):
            raise ValueError(
                "CrawlGait.duration_bounds must satisfy 0 < low <= base_motion_duration <= high, "
                f"got {self.duration_bounds} with base_motion_duration {self.base_motion_duration}"
            )
        if len(self.workspace_box) != 2 or not all(math.isfinite(v) and v > 0 for v in self.workspace_box):
            raise ValueError(f"CrawlGait.workspace_box must be two positive half-widths, got {self.workspace_box!r}")
        if not (isinstance(self.knots, int) and self.knots >= 2):
            raise ValueError(f"CrawlGait.knots must be an integer >= 2, got {self.knots!r}")

    @property
    def nominal_speed(self) -> float:
        """Mean forward speed [m/s] of the crawl at the nominal base-motion duration."""
        return self.stride / (len(SWING_ORDER) * (self.base_motion_duration + self.swing_duration))


def leg_index(leg: str) -> int:
    """Index of ``leg`` in :data:`LEGS`; a clear error for anything else."""
    if leg not in LEGS:
        raise ValueError(f"unknown leg {leg!r}; legs are {', '.join(LEGS)}")
    return LEGS.index(leg)


def swing_leg(step: int) -> str:
    """The leg that swings in crawl step ``step`` (0, 1, ...)."""
    if step < 0:
        raise ValueError(f"step must be >= 0, got {step}")
    return SWING_ORDER[step % len(SWING_ORDER)]


def next_foothold(lift_off: np.ndarray, stride: float, first_step: bool, ground_height: float) -> np.ndarray:
    """Touchdown position (3,) [m, W] of a swing foot: ``lift_off`` moved ``stride`` ahead along x (half of it
    on the foot's first step), its height ``ground_height`` (the foot-sphere centre on the ground there)."""
    p = np.asarray(lift_off, dtype=float)
    return np.array([p[0] + (0.5 if first_step else 1.0) * stride, p[1], float(ground_height)])


def workspace_bounds(
    feet_xy: np.ndarray, nominal_offsets: np.ndarray, half_widths: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Box (lower (2,), upper (2,)) [m] of CoM positions that keep every foot within ``half_widths`` of its
    standing offset from the CoM: ``p_i - c`` in ``n_i +- half_widths`` for all feet (k, 2).

    Where the feet are spread wider than the box allows (a touchdown a few millimetres long, when the
    stride fills the box), that coordinate's interval collapses to the midpoint of its bounds, the CoM
    position that violates them least.
    """
    anchor = np.asarray(feet_xy, dtype=float) - np.asarray(nominal_offsets, dtype=float)
    width = np.asarray(half_widths, dtype=float)
    lower, upper = anchor.max(axis=0) - width, anchor.min(axis=0) + width
    crossed = lower > upper
    middle = 0.5 * (lower + upper)
    return np.where(crossed, middle, lower), np.where(crossed, middle, upper)


def cross2(a: np.ndarray, b: np.ndarray) -> float:
    """z component of the cross product of two planar vectors."""
    return float(a[0] * b[1] - a[1] * b[0])


def support_triangle(feet_xy: np.ndarray, swing: str) -> np.ndarray:
    """The three stance feet (3, 2) of the triple stance in which ``swing`` is in the air, counter-clockwise."""
    feet_xy = np.asarray(feet_xy, dtype=float)
    if feet_xy.shape != (len(LEGS), 2):
        raise ValueError(f"feet_xy must have shape ({len(LEGS)}, 2), got {feet_xy.shape}")
    tri = np.delete(feet_xy, leg_index(swing), axis=0)
    return tri if cross2(tri[1] - tri[0], tri[2] - tri[0]) > 0 else tri[[0, 2, 1]]


def triangle_halfplanes(triangle: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Half-planes ``A c <= b`` (3 x 2, 3) of the counter-clockwise ``triangle`` shrunk by ``margin`` [m].

    A point satisfies them iff it lies inside the triangle at least ``margin`` from every edge.
    """
    tri = np.asarray(triangle, dtype=float)
    a_rows, b_rows = [], []
    for k in range(3):
        p, q = tri[k], tri[(k + 1) % 3]
        edge = q - p
        outward = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)  # right of a CCW edge is outside
        a_rows.append(outward)
        b_rows.append(outward @ p - margin)
    return np.array(a_rows), np.array(b_rows)


def inradius(triangle: np.ndarray) -> float:
    """Radius [m] of the circle inscribed in ``triangle`` (3, 2): the largest usable stability margin."""
    tri = np.asarray(triangle, dtype=float)
    sides = [np.linalg.norm(tri[(k + 1) % 3] - tri[k]) for k in range(3)]
    area = 0.5 * abs(cross2(tri[1] - tri[0], tri[2] - tri[0]))
    return float(2.0 * area / sum(sides))
