"""Built-in planning scenarios: a height map, a start pose and a goal along a course of >= 5 m.

=============  ===============================================================================
flat           level ground, 6 m straight
side_step      seed 000 Fig. 7: from x = 1 m on, the ground under the left feet (y > 0) is 18 cm
               above the ground under the right feet; the robot walks 6 m along the step edge
course         seed 000 Fig. 5/8: obstacles of 6, 12 and 18 cm (60 cm deep, across the course),
               then a 10 degree incline up to a plateau; 7.5 m
env_rough      the rough-terrain height field of the environments (``margin_rl.envs.terrain``,
               default config, seed 0), a 5 m corridor from a spawn pad along +x (bricks, then a
               level tile; it stops 1 m before the 50 cm drop into the next tile)
=============  ===============================================================================

Coordinates: world x along the course, y to the left, z up [m]; every course starts at yaw 0.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from margin_rl.planning.terrain import HeightMap, flat_map

RESOLUTION = 0.05  # [m] grid spacing of the built-in maps (the environments' resolution)
SIDE_STEP_HEIGHT = 0.18  # [m] seed 000 Fig. 7


@dataclass(frozen=True, eq=False)
class Scenario:
    """A planning task: terrain, start (x, y) [m] at yaw 0, goal (x, y) [m]."""

    name: str
    height_map: HeightMap
    start_xy: tuple[float, float]
    goal_xy: tuple[float, float]
    description: str

    @property
    def course_length(self) -> float:
        return float(np.hypot(self.goal_xy[0] - self.start_xy[0], self.goal_xy[1] - self.start_xy[1]))


def _grid(x_range: tuple[float, float], y_range: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, HeightMap]:
    base = flat_map(x_range, y_range, RESOLUTION)
    ny, nx = base.shape
    x = base.origin[0] + np.arange(nx) * RESOLUTION
    y = base.origin[1] + np.arange(ny) * RESOLUTION
    X, Y = np.meshgrid(x, y)  # [row (y), col (x)]
    return X, Y, base


def flat() -> Scenario:
    return Scenario("flat", flat_map((-1.0, 7.5), (-1.5, 1.5), RESOLUTION), (0.0, 0.0), (6.0, 0.0), "level ground")


def side_step() -> Scenario:
    X, Y, base = _grid((-1.0, 7.5), (-1.5, 1.5))
    # The edge runs along x at y = 0, between the left (y > 0) and right feet; it starts at x = 1 m.
    heights = np.where((Y > 0.0) & (X >= 1.0), SIDE_STEP_HEIGHT, 0.0)
    return Scenario(
        "side_step",
        HeightMap(heights, base.origin, RESOLUTION, "side_step"),
        (0.0, 0.0),
        (6.0, 0.0),
        f"left feet {100 * SIDE_STEP_HEIGHT:.0f} cm above the right from x = 1 m (seed 000 Fig. 7)",
    )


def course() -> Scenario:
    X, _, base = _grid((-1.0, 9.0), (-1.5, 1.5))
    heights = np.zeros_like(X)
    for x0, h in ((1.5, 0.06), (2.7, 0.12), (3.9, 0.18)):  # obstacles of 6, 12, 18 cm, 60 cm deep
        heights = np.where((x0 <= X) & (x0 + 0.6 > X), h, heights)
    slope = np.tan(np.deg2rad(10.0))
    ramp = np.clip((X - 5.2) * slope, 0.0, 1.0 * slope)  # 10 degrees from x = 5.2 m to 6.2 m
    heights = np.maximum(heights, ramp)
    return Scenario(
        "course",
        HeightMap(heights, base.origin, RESOLUTION, "course"),
        (0.0, 0.0),
        (7.5, 0.0),
        "obstacles of 6, 12 and 18 cm, then a 10 degree incline to a plateau (seed 000 Fig. 5/8)",
    )


def env_rough(seed: int = 0) -> Scenario:
    from margin_rl.envs.terrain import TerrainConfig, rough_terrain

    terrain = rough_terrain(TerrainConfig(), seed)
    full = HeightMap.from_env_terrain(terrain)
    # The spawn pad nearest the map centre, then 5 m along +x; the map is cropped to that corridor.
    pads = np.asarray(terrain.spawn_points)
    sx, sy, _ = pads[np.argmin(np.hypot(pads[:, 0], pads[:, 1]))]
    cropped = full.crop((sx - 1.5, sx + 7.5), (sy - 1.5, sy + 1.5), name="env_rough")
    return Scenario(
        "env_rough",
        cropped,
        (float(sx), float(sy)),
        (float(sx) + 5.0, float(sy)),
        f"rough-terrain height field of the environments (TerrainConfig(), seed {seed}), 5 m corridor",
    )


SCENARIOS: dict[str, Callable[[], Scenario]] = {
    "flat": flat,
    "side_step": side_step,
    "course": course,
    "env_rough": env_rough,
}


def get_scenario(name: str) -> Scenario:
    """A built-in scenario by name; the error lists the known ones."""
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}; built-in scenarios: {', '.join(SCENARIOS)}")
    return SCENARIOS[name]()
