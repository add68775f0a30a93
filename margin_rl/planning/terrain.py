"""2.5-D height maps for planning: a grid of heights read as a smooth (C2) surface with exact gradients.

The grid ``heights[iy, ix]`` holds the elevation [m] at x = x0 + ix * res, y = y0 + iy * res (MuJoCo's
and :mod:`margin_rl.envs.terrain`'s convention: rows along y, columns along x). The surface is the
uniform bicubic B-spline whose control points are those heights:

    h(x, y) = sum_{i, j} H[j, i] B((x - x_i) / res) B((y - y_j) / res),
    B(t) = (4 - 6 t^2 + 3 |t|^3) / 6 for |t| < 1,  (2 - |t|)^3 / 6 for 1 <= |t| < 2,  0 beyond.

Why this surface and not bilinear interpolation: the planner's cost is the slope ||dh/dp_xy||^2 under
each foothold and the contact normals enter lambda, so IPOPT needs the gradient of the slope, i.e.
second derivatives of h; bilinear interpolation has piecewise-constant slopes (zero gradient of the
cost almost everywhere, jumps at cell borders). The B-spline is C2, never overshoots (each value is a
convex combination of 16 grid heights, so a step stays monotone, without the ringing of interpolating
splines), equals the grid exactly on planar regions, and rounds a step edge over +-2 cells (+-10 cm at
5 cm resolution), which is where the slope cost keeps footholds away from anyway.

Queries outside the grid are clamped to its border (numpy); the planner bounds footholds to the grid.
The same surface is available to CasADi (:meth:`HeightMap.casadi_function`) through
``casadi.Function.bspline`` on identical knots and coefficients; a test checks the two agree.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

# Extra control points replicated at each border: the cubic B-spline's valid domain lies 1 knot
# span inside its knot vector, so a 3-cell pad keeps the whole grid extent inside it.
_PAD = 3


@dataclass(frozen=True, eq=False)
class HeightMap:
    """A height grid [m] with origin (x0, y0) of ``heights[0, 0]`` and square cells of ``resolution`` [m]."""

    heights: np.ndarray  # (ny, nx) [m]
    origin: tuple[float, float]  # [m]
    resolution: float  # [m]
    name: str = ""

    def __post_init__(self) -> None:
        h = np.asarray(self.heights, dtype=float)
        if h.ndim != 2 or min(h.shape) < 2:
            raise ValueError(f"heights must be a 2-D grid of at least 2 x 2 cells, got shape {h.shape}")
        if not np.all(np.isfinite(h)):
            raise ValueError("heights contains NaN or infinite values; fill holes in the map before planning")
        if not (np.isfinite(self.resolution) and self.resolution > 0):
            raise ValueError(f"resolution must be a positive length in metres, got {self.resolution!r}")
        if len(self.origin) != 2 or not np.all(np.isfinite(self.origin)):
            raise ValueError(f"origin must be two finite coordinates (x0, y0) [m], got {self.origin!r}")
        h = h.copy()
        h.setflags(write=False)
        object.__setattr__(self, "heights", h)
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))
        object.__setattr__(self, "resolution", float(self.resolution))

    # ------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape  # type: ignore[return-value]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the grid [m]."""
        ny, nx = self.shape
        x0, y0 = self.origin
        return x0, x0 + (nx - 1) * self.resolution, y0, y0 + (ny - 1) * self.resolution

    @functools.cached_property
    def _control_points(self) -> np.ndarray:
        return np.pad(self.heights, _PAD, mode="edge")

    # ------------------------------------------------------------------ numpy queries
    def _local(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Control-point window and cubic basis weights (with derivatives) for points (..., 2)."""
        xy = np.asarray(xy, dtype=float)
        if xy.shape[-1:] != (2,):
            raise ValueError(f"points must have shape (..., 2) (x, y in metres), got {xy.shape}")
        x_min, x_max, y_min, y_max = self.extent
        u = (np.clip(xy[..., 0], x_min, x_max) - self.origin[0]) / self.resolution + _PAD
        v = (np.clip(xy[..., 1], y_min, y_max) - self.origin[1]) / self.resolution + _PAD
        iu, iv = np.floor(u).astype(int), np.floor(v).astype(int)
        wu, dwu, ddwu = _basis(u - iu)
        wv, dwv, ddwv = _basis(v - iv)
        offsets = np.arange(-1, 3)
        rows = iv[..., None, None] + offsets[:, None]  # (..., 4, 1)
        cols = iu[..., None, None] + offsets[None, :]  # (..., 1, 4)
        window = self._control_points[rows, cols]  # (..., 4, 4): [row (y), col (x)]
        return window, (wu, dwu, ddwu), (wv, dwv, ddwv)  # type: ignore[return-value]

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Terrain height h(x, y) [m] under points (..., 2) -> (...)."""
        window, (wu, _, _), (wv, _, _) = self._local(xy)
        return np.einsum("...r,...rc,...c->...", wv, window, wu)

    def gradient(self, xy: np.ndarray) -> np.ndarray:
        """Slope (dh/dx, dh/dy) [-] under points (..., 2) -> (..., 2)."""
        window, (wu, dwu, _), (wv, dwv, _) = self._local(xy)
        dx = np.einsum("...r,...rc,...c->...", wv, window, dwu) / self.resolution
        dy = np.einsum("...r,...rc,...c->...", dwv, window, wu) / self.resolution
        return np.stack([dx, dy], axis=-1)

    def normal(self, xy: np.ndarray) -> np.ndarray:
        """Unit surface normal (-h_x, -h_y, 1) / norm under points (..., 2) -> (..., 3), pointing up."""
        g = self.gradient(xy)
        n = np.concatenate([-g, np.ones((*g.shape[:-1], 1))], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    # ------------------------------------------------------------------ casadi
    @functools.cached_property
    def casadi_function(self):  # -> casadi.Function
        """``h(xy) -> height``: the same B-spline as a CasADi function of a (2, 1) point, with exact
        derivatives of any order (valid on the grid extent; the planner bounds footholds to it)."""
        import casadi as ca

        ny, nx = self._control_points.shape
        x0 = self.origin[0] - _PAD * self.resolution
        y0 = self.origin[1] - _PAD * self.resolution
        # Knot t_j = x0 + (j - 2) res puts the basis function of control point i around x0 + i res.
        knots_x = [x0 + (j - 2) * self.resolution for j in range(nx + 4)]
        knots_y = [y0 + (j - 2) * self.resolution for j in range(ny + 4)]
        # Flat coefficients: the first spline dimension (x, columns) fastest, i.e. C order of [row, col].
        coeffs = self._control_points.ravel().tolist()
        return ca.Function.bspline(
            f"height_{self.name or 'map'}", [knots_x, knots_y], coeffs, [3, 3], 1, {"lookup_mode": ["exact", "exact"]}
        )

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_env_terrain(cls, terrain: object, name: str = "env_rough") -> HeightMap:
        """The height field of a :class:`margin_rl.envs.terrain.Terrain` (same grid convention).

        Raises:
            ValueError: a flat environment terrain (it has no grid; use :func:`flat_map`).
        """
        heights = getattr(terrain, "heights", None)
        if heights is None:
            raise ValueError("this environment terrain is flat and has no height grid; use a flat HeightMap instead")
        return cls(np.asarray(heights, dtype=float), tuple(terrain.origin), float(terrain.resolution), name)  # type: ignore[attr-defined]

    def crop(self, x_range: tuple[float, float], y_range: tuple[float, float], name: str | None = None) -> HeightMap:
        """The part of the map inside x_range x y_range [m] (whole cells, clipped to the grid)."""
        ny, nx = self.shape
        x0, y0 = self.origin
        c0 = max(int(np.floor((x_range[0] - x0) / self.resolution)), 0)
        c1 = min(int(np.ceil((x_range[1] - x0) / self.resolution)), nx - 1)
        r0 = max(int(np.floor((y_range[0] - y0) / self.resolution)), 0)
        r1 = min(int(np.ceil((y_range[1] - y0) / self.resolution)), ny - 1)
        if c1 - c0 < 1 or r1 - r0 < 1:
            raise ValueError(f"crop {x_range} x {y_range} leaves no cells of the map with extent {self.extent}")
        return HeightMap(
            self.heights[r0 : r1 + 1, c0 : c1 + 1],
            (x0 + c0 * self.resolution, y0 + r0 * self.resolution),
            self.resolution,
            self.name if name is None else name,
        )


def _basis(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Uniform cubic B-spline weights of the 4 control points around a cell, at fraction t in [0, 1).

    Returns (weights, d/dt, d2/dt2), each (..., 4) for control points i-1, i, i+1, i+2.
    """
    t = np.asarray(t)[..., None]
    t2, t3 = t * t, t * t * t
    w = np.concatenate([(1 - t) ** 3, 3 * t3 - 6 * t2 + 4, -3 * t3 + 3 * t2 + 3 * t + 1, t3], axis=-1) / 6.0
    dw = np.concatenate([-3 * (1 - t) ** 2, 9 * t2 - 12 * t, -9 * t2 + 6 * t + 3, 3 * t2], axis=-1) / 6.0
    ddw = np.concatenate([6 * (1 - t), 18 * t - 12, -18 * t + 6, 6 * t], axis=-1) / 6.0
    return w, dw, ddw


def flat_map(x_range: tuple[float, float], y_range: tuple[float, float], resolution: float = 0.05) -> HeightMap:
    """Level ground z = 0 over x_range x y_range [m]."""
    nx = round((x_range[1] - x_range[0]) / resolution) + 1
    ny = round((y_range[1] - y_range[0]) / resolution) + 1
    return HeightMap(np.zeros((ny, nx)), (x_range[0], y_range[0]), resolution, "flat")
