r"""State-action box, sampling, labelling and the k-d-tree failure margin (paper §II-B, §III-B).

The state-action space is :math:`z = [y, \dot x, \alpha, \Delta L]` (eq. 12) restricted to the
box of eq. (13):

.. math::
    0.8 \le y \le 1.2,\quad -1 \le \dot x \le 1,\quad -0.6 \le \alpha \le 0.6,\quad
    -0.05 \le \Delta L \le 0.15.

Distances use the weighted 2-norm :math:`\|z\|_W = \sqrt{z^\top W z}` with
:math:`W = \mathrm{diag}(6.25, 0.250, 0.309, 2.50)` as printed in the paper (§V-A).

The failure margin is the oriented distance (eq. 4-5)

.. math:: b_{V^c}(z) = d_{V^c}(z) - d_V(z), \qquad d_A(z) = \inf_{w \in A} \|z - w\|_W,

positive on valid pairs and negative on invalid ones.  :math:`V` and :math:`V^c` are
represented by finite point clouds of simulated samples held in two
:class:`scipy.spatial.cKDTree`\ s built in the scaled coordinates :math:`W^{1/2} z`, where the
weighted norm becomes the Euclidean one.  For a labelled point, the distance to its own set
is zero by definition, so only the other tree is queried (as in the paper).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from margin_rl.slip.dynamics import BatchResult, SlipParams, simulate_batch

__all__ = [
    "BOX_HIGH",
    "BOX_LOW",
    "MARGIN_WEIGHTS",
    "PREDICTION_WEIGHTS",
    "FailureMargin",
    "brute_force_oriented_distance",
    "label_samples",
    "sample_box",
    "weighted_norm",
]

FloatArray = NDArray[np.float64]

#: Lower corner of the state-action box of eq. (13): ``[y, xdot, alpha, delta_L]``.
BOX_LOW: FloatArray = np.array([0.8, -1.0, -0.6, -0.05])
#: Upper corner of the state-action box of eq. (13).
BOX_HIGH: FloatArray = np.array([1.2, 1.0, 0.6, 0.15])
#: Diagonal of the state-action distance weighting matrix (paper §V-A).
MARGIN_WEIGHTS: FloatArray = np.array([6.25, 0.250, 0.309, 2.50])
#: Diagonal of the return-map prediction-error weighting on ``[dx, y1, xdot1]`` (paper §V-A).
PREDICTION_WEIGHTS: FloatArray = np.array([0.250, 6.25, 0.250])


def _check_points(name: str, points: ArrayLike, dim: int = 4) -> FloatArray:
    arr = np.asarray(points, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{name} must have shape (n, {dim}); got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite values")
    return arr


def _check_weights(weights: ArrayLike) -> FloatArray:
    w = np.asarray(weights, dtype=float)
    if w.ndim != 1 or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ValueError(f"weights must be a 1-d array of positive numbers; got {w!r}")
    return w


def sample_box(n: int, rng: np.random.Generator, low: ArrayLike = BOX_LOW, high: ArrayLike = BOX_HIGH) -> FloatArray:
    """Draw ``n`` state-action points uniformly from the box ``[low, high]`` (eq. 13)."""
    if n < 0:
        raise ValueError(f"n must be non-negative; got {n}")
    lo, hi = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    if lo.shape != hi.shape or np.any(hi < lo):
        raise ValueError("low/high must have equal shapes with high >= low")
    return lo + (hi - lo) * rng.random((n, lo.size))


def label_samples(z: ArrayLike, params: SlipParams | None = None, *, dt: float = 0.01) -> BatchResult:
    """Simulate each state-action row ``[y, xdot, alpha, delta_L]`` for one hop.

    ``result.valid`` is the label (True: the pair is in :math:`V`); ``result.next_apex`` holds
    the return map targets ``[dx, y1, xdot1]``.
    """
    pts = _check_points("z", z)
    return simulate_batch(pts[:, :2], pts[:, 2:], params, dt=dt)


def weighted_norm(diff: ArrayLike, weights: ArrayLike = MARGIN_WEIGHTS) -> FloatArray:
    """:math:`\\sqrt{d^\\top W d}` along the last axis, ``W = diag(weights)``."""
    d = np.asarray(diff, dtype=float)
    w = _check_weights(weights)
    return np.sqrt(np.sum(w * d * d, axis=-1))


@dataclass(frozen=True)
class FailureMargin:
    """Two k-d trees (valid / invalid samples) evaluating the oriented distance :math:`b`.

    Build with :meth:`from_samples`.  Distances are in the weighted norm of ``weights``.
    """

    valid_tree: cKDTree
    invalid_tree: cKDTree
    weights: FloatArray

    @classmethod
    def from_samples(cls, z: ArrayLike, valid: ArrayLike, weights: ArrayLike = MARGIN_WEIGHTS) -> FailureMargin:
        """Build the trees from labelled samples ``z`` (n, 4) and boolean ``valid`` (n,)."""
        pts = _check_points("z", z)
        lab = np.asarray(valid)
        if lab.shape != (pts.shape[0],) or lab.dtype != np.bool_:
            raise ValueError(f"valid must be a boolean array of shape ({pts.shape[0]},); got {lab.dtype} {lab.shape}")
        w = _check_weights(weights)
        if w.size != pts.shape[1]:
            raise ValueError(f"weights has {w.size} entries but points have {pts.shape[1]} coordinates")
        if not lab.any() or lab.all():
            raise ValueError("both the valid and the invalid set need at least one sample")
        scale = np.sqrt(w)
        # balanced_tree=False builds much faster on large uniform clouds at no query cost.
        return cls(
            valid_tree=cKDTree(pts[lab] * scale, balanced_tree=False),
            invalid_tree=cKDTree(pts[~lab] * scale, balanced_tree=False),
            weights=w,
        )

    @property
    def n_valid(self) -> int:
        return int(self.valid_tree.n)

    @property
    def n_invalid(self) -> int:
        return int(self.invalid_tree.n)

    def _query(self, tree: cKDTree, z: ArrayLike, workers: int) -> FloatArray:
        pts = _check_points("z", z, dim=self.weights.size)
        dist, _ = tree.query(pts * np.sqrt(self.weights), k=1, workers=workers)
        return np.asarray(dist, dtype=float)

    def distance_to_valid(self, z: ArrayLike, *, workers: int = 1) -> FloatArray:
        """:math:`d_V(z)`: weighted distance to the nearest valid sample."""
        return self._query(self.valid_tree, z, workers)

    def distance_to_invalid(self, z: ArrayLike, *, workers: int = 1) -> FloatArray:
        """:math:`d_{V^c}(z)`: weighted distance to the nearest invalid sample."""
        return self._query(self.invalid_tree, z, workers)

    def oriented_distance(self, z: ArrayLike, valid: ArrayLike, *, workers: int = 1) -> FloatArray:
        """Failure margin :math:`b` of labelled points (eq. 5).

        A valid point has :math:`d_V = 0`, so :math:`b = d_{V^c}`; an invalid one has
        :math:`d_{V^c} = 0`, so :math:`b = -d_V`.  The label must come from simulating the
        point itself (a fresh sample, or one of the tree samples: its own tree is never
        queried, so including it there changes nothing).
        """
        pts = _check_points("z", z, dim=self.weights.size)
        lab = np.asarray(valid)
        if lab.shape != (pts.shape[0],) or lab.dtype != np.bool_:
            raise ValueError(f"valid must be a boolean array of shape ({pts.shape[0]},)")
        out = np.empty(pts.shape[0])
        if lab.any():
            out[lab] = self.distance_to_invalid(pts[lab], workers=workers)
        if (~lab).any():
            out[~lab] = -self.distance_to_valid(pts[~lab], workers=workers)
        return out

    def oriented_distance_unlabelled(self, z: ArrayLike, *, workers: int = 1) -> FloatArray:
        """Point-cloud estimate :math:`d_{V^c}(z) - d_V(z)` for points that were not simulated."""
        return self.distance_to_invalid(z, workers=workers) - self.distance_to_valid(z, workers=workers)


def brute_force_oriented_distance(
    z: ArrayLike,
    valid: ArrayLike,
    valid_points: ArrayLike,
    invalid_points: ArrayLike,
    weights: ArrayLike = MARGIN_WEIGHTS,
) -> FloatArray:
    """Eq. (5) by exhaustive search, for testing: each query ``z[i]`` labelled ``valid[i]``.

    Each query is treated as a fresh sample: the valid set is ``valid_points`` plus the query
    itself when it is valid (so its own-set distance is zero), likewise for the invalid set.
    """
    pts = _check_points("z", z)
    lab = np.asarray(valid, dtype=bool)
    w = _check_weights(weights)
    vset = _check_points("valid_points", valid_points)
    iset = _check_points("invalid_points", invalid_points)
    d_v = weighted_norm(pts[:, None, :] - vset[None, :, :], w).min(axis=1, initial=np.inf)
    d_i = weighted_norm(pts[:, None, :] - iset[None, :, :], w).min(axis=1, initial=np.inf)
    d_v = np.where(lab, 0.0, d_v)
    d_i = np.where(lab, d_i, 0.0)
    return d_i - d_v
