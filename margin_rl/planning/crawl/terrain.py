"""Rough ground for the crawl: square tiles at random heights, flat on top (seed 004 §VI-C's rough terrain).

Each tile is a box whose top is level, so every contact normal is vertical and the controller's friction
pyramid (set up for horizontal ground) stays exact, while the four feet stand at different heights: the
non-coplanar contacts the FWP is made for. Heights are drawn uniformly in ``[0, max_height]`` above the
floor, with the tiles under the standing robot at zero so that it starts level.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TileTerrain:
    """Tiles of side ``tile`` [m] over ``x_range`` x ``y_range`` [m, W], tops at random heights."""

    tile: float = 0.25
    max_height: float = 0.05
    x_range: tuple[float, float] = (-1.0, 3.0)
    y_range: tuple[float, float] = (-0.75, 0.75)
    flat_radius: float = 0.6  # tiles whose centre is this close to the origin (under the standing feet) stay at zero
    seed: int = 0

    def __post_init__(self) -> None:
        if not (self.tile > 0 and self.max_height >= 0 and self.flat_radius >= 0):
            raise ValueError("TileTerrain needs tile > 0, max_height >= 0 and flat_radius >= 0")
        if not (self.x_range[0] < self.x_range[1] and self.y_range[0] < self.y_range[1]):
            raise ValueError(f"TileTerrain ranges must be increasing, got {self.x_range} and {self.y_range}")

    @cached_property
    def centres(self) -> tuple[FloatArray, FloatArray]:
        """Tile centres along x and y."""
        xs = np.arange(self.x_range[0] + self.tile / 2, self.x_range[1], self.tile)
        ys = np.arange(self.y_range[0] + self.tile / 2, self.y_range[1], self.tile)
        return xs, ys

    @cached_property
    def heights(self) -> FloatArray:
        """(ny, nx) top heights [m]."""
        xs, ys = self.centres
        rng = np.random.default_rng(self.seed)
        heights = rng.uniform(0.0, self.max_height, size=(ys.size, xs.size))
        near = np.hypot(*np.meshgrid(xs, ys)) < self.flat_radius
        heights[near] = 0.0
        return heights

    def height(self, x: float, y: float) -> float:
        """Top height [m] of the tile under (x, y); 0 outside the tiled area."""
        xs, ys = self.centres
        i = int(np.floor((y - self.y_range[0]) / self.tile))
        j = int(np.floor((x - self.x_range[0]) / self.tile))
        if 0 <= i < ys.size and 0 <= j < xs.size:
            return float(self.heights[i, j])
        return 0.0

    def add_to(self, spec, friction: float) -> None:  # spec: mujoco.MjSpec
        """Add the tiles as boxes (their tops at the heights, their bottoms 10 cm below the floor)."""
        import mujoco

        xs, ys = self.centres
        bottom = -0.1
        for i, y in enumerate(ys):
            for j, x in enumerate(xs):
                top = float(self.heights[i, j])
                spec.worldbody.add_geom(
                    name=f"tile_{i}_{j}", type=mujoco.mjtGeom.mjGEOM_BOX,
                    size=[self.tile / 2, self.tile / 2, (top - bottom) / 2], pos=[x, y, (top + bottom) / 2],
                    friction=[friction, 0.005, 0.0001], priority=1, condim=3,
                    rgba=[0.45 + 4 * top, 0.5, 0.55 - 4 * top, 1.0],
                )  # fmt: skip
