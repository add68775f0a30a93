"""Terrain of the environments: flat ground, or a rough heightfield like seed 000 Fig. 8.

The rough terrain is a square heightfield of tiles, each of one type drawn from the paper's scenes
(bricks, stairs up and down, inclines, side steps, scattered obstacles), with heights of 6-18 cm as in
Fig. 5/8, and a flat pad at every tile centre where robots spawn. MuJoCo collides with the same grid
(an ``hfield`` geom); :meth:`Terrain.height` and :meth:`Terrain.normal` query the same surface (MuJoCo's triangles),
vectorised over numpy arrays or torch tensors, for the contact normals in lambda, the terminations, the privileged
heights and spawning.

Every tile meets its neighbours at the base level on its border, and nowhere does the ground jump by more than one
step (``step_height``'s upper bound): stairs and inclines are square pyramids, rising (``*_up``) or falling
(``*_down``) from the border to the pad, so that a robot crossing tiles meets stairs, never a wall.

A **terrain curriculum** (``TerrainConfig.curriculum_levels`` = L >= 2, as in legged_gym, Isaac Lab and mjlab) lays
the tiles in L rows along y of rising difficulty instead: row l holds tiles at difficulty l / (L - 1)
(:func:`at_difficulty`: row 0 flat, the top row ``config``'s full scale), its ``size / tile`` columns of tile types
drawn without repetition where the row is long enough. Each environment spawns on the pad of a tile of its level
(:attr:`Terrain.levels`, spawn points in row-major order) and moves between rows at its episode's end
(:func:`next_levels`).

Grid convention (MuJoCo's): ``heights[r, c]`` is the elevation at x = x0 + c * res, y = y0 + r * res.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from array_api_compat import device as device_of

from margin_rl.arrays import constant, like, namespace, to_numpy, unstack

TILE_TYPES: tuple[str, ...] = (
    "flat",
    "bricks",
    "stairs_up",
    "stairs_down",
    "slope_up",
    "slope_down",
    "side_step",
    "obstacles",
)


RIM_CELLS = 2
"""Width, in grid cells, of the base-level rim around every tile."""

MIN_SLOPE_DEG = 5.0
"""Inclines are drawn from [MIN_SLOPE_DEG, max_slope_deg] (from [max_slope_deg, max_slope_deg] below it)."""


@dataclass(frozen=True)
class TerrainConfig:
    """Rough-terrain generator settings (lengths in m)."""

    size: float = 24.0  # side of the square of tiles
    # Flat ground at the base level around the tiles: a 20 s episode at 0.75 m/s walks 15 m, and a robot that walks
    # off the heightfield falls (there is no ground beyond it), however well it walks.
    border: float = 16.0
    resolution: float = 0.05  # grid spacing
    tile: float = 4.0  # side of one tile
    step_height: tuple[float, float] = (0.06, 0.18)  # bricks, stairs, side steps, obstacles (Fig. 8)
    max_slope_deg: float = 15.0
    pad: float = 1.0  # side of the flat spawn pad at each tile centre
    base_level: float = 0.5  # tiles start at this height so that stairs can go down
    max_height: float = 1.5  # vertical extent of the MuJoCo hfield
    # 0: size x size of tiles of random types at the scale above; L >= 2: a curriculum of L rows of rising
    # difficulty (the module docstring), each size long
    curriculum_levels: int = 0
    initial_max_level: int = 2  # curriculum: environments start on a level drawn from 0..initial_max_level

    @property
    def columns(self) -> int:
        """Tiles along x."""
        return round(self.size / self.tile)

    @property
    def rows(self) -> int:
        """Tiles along y: the curriculum's levels, or as many as along x."""
        return self.curriculum_levels or self.columns

    def grid_shape(self) -> tuple[int, int]:
        """(rows, columns) of the height grid, border included."""
        per_tile, border = round(self.tile / self.resolution), round(self.border / self.resolution)
        return self.rows * per_tile + 2 * border + 1, self.columns * per_tile + 2 * border + 1


@dataclass(frozen=True)
class Terrain:
    """A height grid with vectorised height/normal queries; ``flat`` terrains are the plane z = 0.

    The queries take numpy arrays or torch tensors (:mod:`margin_rl.arrays`) and answer in the same kind, on the
    same device: the grid and the spawn points are copied to a device once, on its first query there.
    """

    heights: np.ndarray | None  # (rows, columns) [m], None for flat ground
    origin: tuple[float, float]  # (x0, y0) of heights[0, 0]
    resolution: float
    spawn_points: np.ndarray  # (k, 3) flat places to put a robot: x, y, ground height
    levels: int = 0  # curriculum: the spawn points are levels rows of k / levels, row-major; 0: no curriculum
    _on_device: dict[Any, tuple[Any, Any]] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_on_device"] = {}  # device copies are rebuilt where they are used
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.__dict__.setdefault("_on_device", {})

    @property
    def is_flat(self) -> bool:
        return self.heights is None

    def _arrays_like(self, reference: Any) -> tuple[Any, Any]:
        """(heights, spawn points) as arrays of ``reference``'s kind and device (numpy: the fields themselves)."""
        if namespace(reference) is np:
            return self.heights, self.spawn_points
        key = str(reference.device)
        if key not in self._on_device:
            heights = None if self.heights is None else like(self.heights, reference)
            self._on_device[key] = (heights, like(self.spawn_points, reference))
        return self._on_device[key]

    def spawn_points_like(self, reference: Any) -> Any:
        """:attr:`spawn_points` (k, 3) as an array of ``reference``'s kind and device."""
        return self._arrays_like(reference)[1]

    def height(self, xy: Any) -> Any:
        """Ground height [m] under points (..., 2) (0 for flat ground): the surface MuJoCo collides with, linear on
        the two triangles each grid cell is split into along its (r, c)-(r+1, c+1) diagonal (tested against
        ``mj_ray`` on the heightfield geom)."""
        xp = namespace(xy)
        xy = xp.astype(xp.asarray(xy), xp.float64, copy=False)
        if self.heights is None:
            return xp.zeros(xy.shape[:-1], dtype=xp.float64, device=device_of(xy))
        h, _ = self._arrays_like(xy)
        rows, columns = self.heights.shape
        # (u, v): the points in grid units (columns, rows), kept inside the grid; (c0, r0) the cell, (fu, fv) the
        # fractions in it; the cell's four corners gathered from the flat grid at once: 00, 01 (next column),
        # 10 (next row), 11.
        first, last = constant(np.zeros(2), xy), constant(np.array([columns - 1.000001, rows - 1.000001]), xy)
        uv = xp.clip((xy - constant(np.array(self.origin), xy)) / self.resolution, first, last)
        cell = xp.astype(xp.floor(uv), xp.int64)
        fraction = uv - cell
        fu, fv = unstack(fraction, axis=-1)
        cell_column, cell_row = unstack(cell, axis=-1)
        corner = cell_row * columns + cell_column
        corners = xp.reshape(h, (-1,))[corner[..., None] + constant(np.array([0, 1, columns, columns + 1]), corner)]
        h00, h01, h10, h11 = unstack(corners, axis=-1)
        # Triangle (00, 01, 11) where fu >= fv: h00 + fu (h01 - h00) + fv (h11 - h01); triangle (00, 10, 11) elsewhere:
        # h00 + fv (h10 - h00) + fu (h11 - h10). One formula over the triangle's middle corner and its fractions.
        upper = fu >= fv
        middle, along, across = xp.where(upper, h01, h10), xp.where(upper, fu, fv), xp.where(upper, fv, fu)
        return h00 + along * (middle - h00) + across * (h11 - middle)

    def normal(self, xy: Any) -> Any:
        """Unit terrain normals (..., 3) under points (..., 2), from central differences of the height."""
        xp = namespace(xy)
        xy = xp.astype(xp.asarray(xy), xp.float64, copy=False)
        if self.heights is None:
            return vertical_normals(xy)
        return self.normal_from_heights(self.height(self.normal_stencil(xy)))

    def normal_stencil(self, xy: Any) -> Any:
        """The points (..., 4, 2) around points (..., 2) whose heights give the normal there: +-one grid cell along x,
        then along y (:meth:`normal_from_heights`)."""
        d = self.resolution
        offsets = np.array([[d, 0.0], [-d, 0.0], [0.0, d], [0.0, -d]])
        return xy[..., None, :] + constant(offsets, xy)

    def normal_from_heights(self, heights: Any) -> Any:
        """Unit normals (..., 3) from the heights (..., 4) at :meth:`normal_stencil`'s points (central differences)."""
        xp, d = namespace(heights), self.resolution
        dx = (heights[..., 0] - heights[..., 1]) / (2 * d)
        dy = (heights[..., 2] - heights[..., 3]) / (2 * d)
        n = xp.stack([-dx, -dy, xp.ones_like(dx)], axis=-1)
        return n / xp.linalg.vector_norm(n, axis=-1, keepdims=True)

    def height_spread(self, xy: Any, radius: float, points: int = 8) -> Any:
        """How uneven the ground is under discs of ``radius`` [m] centred on points (..., 2): the highest minus the
        lowest ground height [m] over each centre and ``points`` points on its rim (0 on flat ground)."""
        xp = namespace(xy)
        xy = xp.astype(xp.asarray(xy), xp.float64, copy=False)
        if self.heights is None:
            return xp.zeros(xy.shape[:-1], dtype=xp.float64, device=device_of(xy))
        return spread_of_heights(self.height(spread_stencil(xy, radius, points)))


def spread_stencil(xy: Any, radius: float, points: int = 8) -> Any:
    """The centre and ``points`` points on the rim of discs of ``radius`` [m] centred on points (..., 2): (..., 1 +
    points, 2), whose heights :func:`spread_of_heights` turns into the ground's spread under each disc."""
    angles = 2 * math.pi * np.arange(points) / points
    ring = np.concatenate([np.zeros((1, 2)), radius * np.column_stack([np.cos(angles), np.sin(angles)])])
    return xy[..., None, :] + constant(ring, xy)


def spread_of_heights(heights: Any) -> Any:
    """The highest minus the lowest of the heights (..., k) [m] (at :func:`spread_stencil`'s points)."""
    xp = namespace(heights)
    return xp.max(heights, axis=-1) - xp.min(heights, axis=-1)


def vertical_normals(xy: Any) -> Any:
    """The world's vertical (0, 0, 1) under every point (..., 2): flat ground's normals, float64 (..., 3) in the kind
    and on the device of ``xy``."""
    xp = namespace(xy)
    normals = xp.zeros((*xy.shape[:-1], 3), dtype=xp.float64, device=device_of(xy))
    normals[..., 2] = 1.0  # a fill on the device, no array from the host
    return normals


STEP_EDGE_RISE = 0.02
"""[m] A foot lands on a step edge when the ground under its sole, a disc of the foot sphere's radius, rises by more
than this (:meth:`Terrain.height_spread`). Inclines stay below it (15 degrees across ANYmal's 6 cm soles: 1.6 cm), the
Fig. 8 tiles' risers exceed it from difficulty 1/3 (steps of 6 cm and more at full scale)."""


CURRICULUM_TERRAIN = TerrainConfig(size=32.0, curriculum_levels=9)
"""The terrain curriculum the rough recipe trains on: 9 rows of 8 tiles (each of the 8 tile types once per row),
difficulties 0, 1/8, ..., 1 of Fig. 8's scale, environments starting on levels 0-2. Level 2k is difficulty k/4, the
scale of the fixed-difficulty evaluation terrains (:func:`at_difficulty` of the default config)."""


def at_difficulty(config: TerrainConfig, difficulty: float) -> TerrainConfig:
    """``config`` with its tiles at ``difficulty`` in [0, 1] of their full scale: the step heights and the incline
    (up to ``max_slope_deg``) scaled by it. 0 gives flat tiles, 1 ``config`` itself (by default seed 000's Fig. 8
    scale: steps and bricks of 6-18 cm, inclines to 15 degrees). The rows of the terrain curriculum and the
    fixed-level evaluation terrains are made with it."""
    if not (isinstance(difficulty, (int, float)) and 0.0 <= difficulty <= 1.0):
        raise ValueError(f"difficulty must be a number in [0, 1] (a share of the full tile scale), got {difficulty!r}")
    low, high = config.step_height
    return replace(
        config, step_height=(low * difficulty, high * difficulty), max_slope_deg=config.max_slope_deg * difficulty
    )


def flat_terrain() -> Terrain:
    return Terrain(heights=None, origin=(0.0, 0.0), resolution=1.0, spawn_points=np.zeros((1, 3)))


def rough_terrain(config: TerrainConfig, seed: int) -> Terrain:
    """Generate a rough terrain (a curriculum where ``config.curriculum_levels`` >= 2); the same (config, seed) gives
    the same grid."""
    rng = np.random.default_rng(seed)
    res = config.resolution
    margin = round(config.border / res)  # grid cells of flat border on each side
    rows, columns, per_tile = config.rows, config.columns, round(config.tile / res)
    heights = np.full(config.grid_shape(), config.base_level)
    origin = (-(config.size / 2 + margin * res), -(rows * config.tile / 2 + margin * res))
    levels = config.curriculum_levels
    if levels:
        row_configs = [at_difficulty(config, level / (levels - 1)) for level in range(levels)]
        types = np.concatenate([rng.permutation(np.resize(np.arange(len(TILE_TYPES)), columns)) for _ in range(rows)])
    else:
        row_configs = [config] * rows
        types = rng.permutation(np.resize(np.arange(len(TILE_TYPES)), rows * columns))
    spawns, centres = [], []
    for ti in range(rows):
        for tj in range(columns):
            r0, c0 = margin + ti * per_tile, margin + tj * per_tile
            block = _tile(TILE_TYPES[types[ti * columns + tj]], per_tile + 1, res, row_configs[ti], rng)
            heights[r0 : r0 + per_tile + 1, c0 : c0 + per_tile + 1] = config.base_level + block
            centres.append((r0 + per_tile // 2, c0 + per_tile // 2))
            spawns.append((origin[0] + (c0 + per_tile / 2) * res, origin[1] + (r0 + per_tile / 2) * res))
    # Clipping is monotone, so it never makes a neighbour difference larger; a clipped pit gets a flat floor.
    heights = np.clip(heights, 0.0, config.max_height)
    pad_heights = [heights[r, c] for r, c in centres]  # the pad is flat: its centre node is its height
    spawn_points = np.column_stack([np.array(spawns), pad_heights])
    return Terrain(heights=heights, origin=origin, resolution=res, spawn_points=spawn_points, levels=levels)


PROMOTION_TILE_FRACTION = 0.5
"""Curriculum: an episode that ends farther than this share of a tile from its spawn point moves up a level."""

DEMOTION_COMMAND_FRACTION = 0.5
"""Curriculum: an episode that ends nearer than this share of its commanded distance moves down a level."""


def next_levels(
    levels: Any,
    walked: Any,
    commanded: Any,
    tile: float,
    top: int,
    random_level: Any,
) -> Any:
    """The curriculum's level of each environment for its next episode (legged_gym's rule).

    ``walked`` [m]: horizontal distance from the episode's spawn point to where it ended; ``commanded`` [m]: the
    commanded speed times the episode's duration. Promoted (+1) where ``walked`` > :data:`PROMOTION_TILE_FRACTION`
    x ``tile``; otherwise demoted (-1, not below 0) where ``walked`` < :data:`DEMOTION_COMMAND_FRACTION` x
    ``commanded``. An environment promoted beyond ``top`` (the last level) takes ``random_level`` instead (drawn by
    the caller from 0..top), so that the top rows keep being walked without everyone piling up there. Arrays (N,)
    of one kind (numpy or torch); levels are integers.
    """
    xp = namespace(levels)
    promoted = walked > PROMOTION_TILE_FRACTION * tile
    demoted = ~promoted & (walked < DEMOTION_COMMAND_FRACTION * commanded)
    moved = levels + xp.astype(promoted, levels.dtype) - xp.astype(demoted, levels.dtype)
    moved = xp.where(moved > top, random_level, moved)
    return xp.clip(moved, min=0)


def _tile(kind: str, m: int, res: float, config: TerrainConfig, rng: np.random.Generator) -> np.ndarray:
    """Height offsets (m, m) of one tile relative to the base level, with a flat pad at the centre.

    Stairs and inclines are square pyramids in the Chebyshev distance from the tile centre: 0 on the rim, the pad
    at the top (``*_up``) or the bottom (``*_down``); one stair is ``width`` deep and one ``step`` high.
    """
    lo, hi = config.step_height
    x = (np.arange(m) - (m - 1) / 2) * res  # tile-local coordinate along the grid columns
    X, Y = np.meshgrid(x, x)  # X varies along columns (world x), Y along rows (world y)
    pad = (np.abs(X) <= config.pad / 2) & (np.abs(Y) <= config.pad / 2)
    half = (m - 1) * res / 2
    from_pad = np.maximum(np.maximum(np.abs(X), np.abs(Y)) - config.pad / 2, 0.0)  # 0 on the pad [m]
    to_border = half - RIM_CELLS * res - config.pad / 2  # from the pad's edge to the rim [m]
    out = np.zeros((m, m))
    pad_offset = 0.0
    if kind == "bricks":
        brick = 0.4
        cells = np.floor((X + 10) / brick).astype(int) * 1000 + np.floor((Y + 10) / brick).astype(int)
        values = rng.uniform(0, rng.uniform(lo, hi), size=cells.max() + 1)
        out = values[cells]
    elif kind in ("stairs_up", "stairs_down"):
        step, width = rng.uniform(lo, hi), 0.3
        stairs = math.ceil(to_border / width)  # the last (possibly narrower) stair ends at the rim
        below_pad = np.minimum(np.ceil(from_pad / width), stairs)  # stairs between a node and the pad
        out = (stairs - below_pad) * step * (1 if kind == "stairs_up" else -1)
        pad_offset = stairs * step * (1 if kind == "stairs_up" else -1)
    elif kind in ("slope_up", "slope_down"):
        slope = np.tan(np.deg2rad(rng.uniform(min(MIN_SLOPE_DEG, config.max_slope_deg), config.max_slope_deg)))
        out = np.maximum(to_border - from_pad, 0.0) * slope * (1 if kind == "slope_up" else -1)
        pad_offset = to_border * slope * (1 if kind == "slope_up" else -1)
    elif kind == "side_step":
        out = np.where(config.pad / 2 < Y, rng.uniform(lo, hi), 0.0)  # left half raised
    elif kind == "obstacles":
        for _ in range(12):
            cx, cy = rng.uniform(-(m - 1) * res / 2, (m - 1) * res / 2, size=2)
            w, d = rng.uniform(0.2, 0.8, size=2)
            box = (np.abs(X - cx) <= w / 2) & (np.abs(Y - cy) <= d / 2)
            out = np.where(box, np.maximum(out, rng.uniform(lo, hi)), out)
    out = np.where(pad, pad_offset, out)
    # Every tile is at the base level on its rim: neighbours meet there whatever their types. (The pyramids reach 0
    # at the rim's inner edge; bricks, side steps and obstacles step down to it by at most one step height.)
    rim = RIM_CELLS
    out[:rim, :], out[-rim:, :], out[:, :rim], out[:, -rim:] = 0.0, 0.0, 0.0, 0.0
    return out


def checked_levels(levels: Any, rows: int, num_envs: int, terrain: str) -> np.ndarray:
    """``levels`` (a list, numpy or a tensor on any device) as numpy integers: one curriculum row per environment.

    Raises:
        ValueError: no curriculum (``rows`` 0), not ``num_envs`` integers, or a row outside 0 .. ``rows`` - 1.
    """
    if not rows:
        raise ValueError(
            "restart_on_levels needs a terrain curriculum (TerrainConfig.curriculum_levels >= 2); this "
            f"environment's terrain is {terrain!r} without one"
        )
    given = to_numpy(levels)
    if given.shape != (num_envs,) or not np.issubdtype(given.dtype, np.integer):
        raise ValueError(
            f"levels: expected {num_envs} integers (one per environment), got shape {given.shape} of "
            f"{given.dtype}; resume with the --num-envs the run was trained with"
        )
    if given.size and (given.min() < 0 or given.max() >= rows):
        raise ValueError(
            f"levels: rows must lie in 0..{rows - 1} (this curriculum's), got {given.min()}..{given.max()}"
        )
    return given
