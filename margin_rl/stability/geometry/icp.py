r"""Instantaneous Capture Point (eq. 5) and analytic stability margin (eqs. 6-7).

Both work on single points ``(2,)`` or batches ``(..., 2)`` and in the x-y plane of the
horizontal frame H (the frame of :class:`~margin_rl.stability.geometry.region.FeasibleRegion`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.stability.geometry.region import FeasibleRegion

__all__ = ["capture_point", "stability_margin"]


def capture_point(
    com_xy: ArrayLike, com_vel_xy: ArrayLike, com_height: ArrayLike, g: float = 9.81
) -> NDArray[np.float64]:
    r"""Instantaneous Capture Point of the Linear Inverted Pendulum, eq. (5).

    .. math:: \xi = c_{xy} + \dot c_{xy} / \omega, \qquad \omega = \sqrt{g / c_z}

    Parameters
    ----------
    com_xy : (..., 2) array_like
        Horizontal CoM position [m] (in H the current CoM is the origin, so usually zeros).
    com_vel_xy : (..., 2) array_like
        Horizontal CoM velocity [m/s].
    com_height : float or (...) array_like
        CoM height c_z above the ground [m], > 0.
    g : float
        Gravity magnitude [m/s^2], > 0.

    Returns
    -------
    (..., 2) ndarray
        The capture point [m].

    Raises
    ------
    ValueError
        If ``com_height <= 0`` or ``g <= 0``, a value is not finite, or the last axis is not 2.
    """
    c = np.asarray(com_xy, dtype=np.float64)
    v = np.asarray(com_vel_xy, dtype=np.float64)
    h = np.asarray(com_height, dtype=np.float64)
    if c.shape[-1:] != (2,):
        raise ValueError(f"com_xy must have shape (..., 2), got {c.shape}")
    if v.shape[-1:] != (2,):
        raise ValueError(f"com_vel_xy must have shape (..., 2), got {v.shape}")
    if not (np.isfinite(g) and g > 0):
        raise ValueError(f"g must be finite and > 0, got {g!r}")
    if not np.all(np.isfinite(h)) or np.any(h <= 0):
        raise ValueError("com_height must be finite and > 0")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(v))):
        raise ValueError("com_xy and com_vel_xy must be finite")
    # 1/omega = sqrt(c_z / g); the trailing axis broadcasts a per-sample height over x, y.
    return c + v * np.sqrt(h / g)[..., None]


def stability_margin(
    region: FeasibleRegion | ArrayLike, point: ArrayLike, outside: str = "lines"
) -> float | NDArray[np.float64]:
    r"""Analytic stability margin, eq. (7): :math:`m_a = \min(N [p^T\ 1]^T)`.

    Parameters
    ----------
    region : FeasibleRegion or (h, 3) array_like
        A region, or directly its half-space matrix: rows ``[n_x, n_y, a]`` with inward unit
        normals and ``n . p - a >= 0`` inside (eq. 6, with the offset stored so that it is
        subtracted: the paper's :math:`N [p; 1]` uses the rows ``[n^T, -a]``).
    point : (2,) or (..., 2) array_like
        Point(s) p [m] in the region's frame, e.g. the capture point.
    outside : ``"lines"`` or ``"euclidean"``
        ``"lines"`` (default) is eq. (7) everywhere: the minimum signed distance to the edge
        *lines*.  Inside a convex polygon that is the distance to the boundary; outside it is the
        distance to the most violated edge line, which is smaller than the Euclidean distance
        beyond a vertex and can jump when a sharp vertex is cut by one more edge (a finer
        approximation of the same region).  ``"euclidean"`` keeps eq. (7) inside and returns
        minus the Euclidean distance to the polygon outside (continuous in the region's shape);
        it needs a :class:`FeasibleRegion` (vertices).

    Returns
    -------
    float or (...) ndarray
        Margin [m]: positive inside, <= 0 on or outside the boundary.  An empty region (no
        half-spaces) gives ``-inf``: no equilibrium exists anywhere.
    """
    if outside not in ("lines", "euclidean"):
        raise ValueError(f"outside must be 'lines' or 'euclidean', got {outside!r}")
    if isinstance(region, FeasibleRegion):
        hs = region.halfspaces
    else:
        if outside == "euclidean":
            raise ValueError("outside='euclidean' needs a FeasibleRegion (its vertices), not half-spaces")
        hs = np.asarray(region, dtype=np.float64)
    if hs.ndim != 2 or hs.shape[1] != 3:
        raise ValueError(f"region half-spaces must have shape (h, 3), got {hs.shape}")
    p = np.asarray(point, dtype=np.float64)
    if p.shape[-1:] != (2,):
        raise ValueError(f"point must have shape (2,) or (..., 2), got {p.shape}")
    if hs.shape[0] == 0:
        out = np.full(p.shape[:-1], -np.inf)
    else:
        # d = n . p - a for every edge (eq. 6 sign convention: a is subtracted).
        out = (p @ hs[:, :2].T - hs[:, 2]).min(axis=-1)
        if outside == "euclidean" and isinstance(region, FeasibleRegion):
            if p.ndim == 1:  # one point: the distance to the polygon only when it is needed
                return float(out) if out > 0.0 else -float(_distance_to_polygon(region.vertices, p))
            out = np.where(out > 0.0, out, -_distance_to_polygon(region.vertices, p))
    return float(out) if p.ndim == 1 else out


def _distance_to_polygon(vertices: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Euclidean distance from points (..., 2) to the boundary of the polygon (m, 2), m >= 1."""
    a = vertices
    ab = np.empty_like(a)  # edge vectors a[i+1] - a[i] (cyclic), without np.roll's overhead
    np.subtract(a[1:], a[:-1], out=ab[:-1])
    np.subtract(a[0], a[-1], out=ab[-1])
    ap = p[..., None, :] - a  # (..., m, 2)
    len2 = np.einsum("ij,ij->i", ab, ab)
    # Clamped projection parameter (np.minimum/np.maximum: np.clip's values, less overhead).
    t = np.minimum(np.maximum(np.einsum("...ij,ij->...i", ap, ab) / np.where(len2 > 0.0, len2, 1.0), 0.0), 1.0)
    return np.linalg.norm(ap - t[..., None] * ab, axis=-1).min(axis=-1)
