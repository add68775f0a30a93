r"""Cheap physics features of lambda for the physics-informed learned margin (numpy, exact Jacobians, torch).

The analytic margin m_a is the signed distance of the capture point to a Feasible Region whose shape comes
from a conic program. Most of what that region *is* follows from rigid-body statics that cost a few dozen
flops: the support polygon of the stance feet, shifted by the gravito-inertial load, and the capture point
itself. These features hand that structure to the network so it only has to learn what the statics miss
(torque limits, friction on tilted terrain, the angular-momentum rate). Everything is in the horizontal
frame H of :mod:`~margin_rl.stability.analytic.lambda_state` (origin at the CoM, z up), lengths in metres:

* contact points   P_i = p_i - r n_i (foot-sphere centre minus radius along the normal), as the analytic
  margin takes them; their x-y parts span the support polygon.
* CoM height       h = -sum_i w_i P_i,z with w_i = (c_i + d) / (sum_j c_j + 4 d), d = 1e-6: the mean over
  the stance feet (the analytic margin's LIP height) for binary contact flags, and still defined (the
  mean of all four feet) with none; then floored smoothly at about 1 cm, floor(x) = (x + sqrt(x^2 + s^2)) / 2.
* capture point    xi = c_dot_xy sqrt(h / g)   (eq. 5 with the CoM at the origin of H, as the analytic margin).
* load shift       s = ((h F_x - tau_y) / F_z, (h F_y + tau_x) / F_z), with the force the contacts must
  produce F = m (c_ddot + g e_z) - f_ext and F_z floored smoothly at 0.02 m g. The centre of pressure of a
  rigid body on feet at depth h below the CoM lies at c_xy - s, so with unilateral point contacts on flat
  ground the CoM is feasible exactly where c_xy - s lies in the support polygon: the Feasible Region is the
  support polygon translated by s. The angular-momentum rate I w_dot would add to tau; it needs the
  inertia, is small on Table I (|w_dot| <= 1 rad/s^2), and is left to the network.
* shifted ICP      q = xi - s: the capture point moved into the frame where the region is the polygon.
* q - P_i,xy       per foot (x, y): where the capture point sits relative to each foot.
* friction usage   |F_xy| / (mu F_z): tangential over available force for flat ground (> 1: slides); mu
  floored smoothly at about 1e-3 so that the feature stays finite for any finite lambda.
* cone slack       per foot (mu F.n_i - |F - (F.n_i) n_i|) / |F|, n_i normalised: > 0 when the total force
  direction fits in that foot's friction cone.
* support distances  signed distance of xi (``icp_support_distance``) and of q (``support_margin``, the
  analytic proxy) to the convex hull of the stance contact points, positive inside, minus the Euclidean
  distance outside, like m_a with ``outside="euclidean"`` (segment for two feet, point for one).

Support distance: for a convex set K, m(q) = min over unit u of max_{k in K} u.(P_k - q). The minimum is
reached at an outward edge normal (q inside, or q outside facing an edge) or at the direction from a
vertex to q (q outside beyond a vertex), and any unit u gives an upper bound, so minimising over the finite
candidate set {perp(P_b - P_a) for ordered pairs a != b} U {q - P_k} (U the axes +-x, +-y) is exact for 1-4 feet (both
orientations of every pair, so it needs no hull). Swing feet enter through a penalty L (1 - c_k), L = 10 m,
on their support value: exact for binary flags, and with no foot in contact the distance is about -L. The
flags are a mask there, not differentiated (they are binary; the CoM height does carry their derivative).
Non-smooth points: the function is piecewise smooth (like m_a); the Jacobian is that of the active
candidate and foot (first index on ties in numpy; torch's amax/amin share the gradient among exact ties).
The structural ties (both feet of a two-foot segment along its normal) have equal gradients, so the choice
does not matter there. Directions are normalised as u = w / sqrt(|w|^2 + eps^2), eps = 1e-12 m, and a candidate's value
gets L (1 - |u|^2) added: nothing measurable unless |w| < ~1e-8 m, but a degenerate candidate (two feet at
the same point, q on a foot) gives +L instead of a false 0, so it never wins the minimum.

Mirror: every feature is declared like a lambda field with its parity (:data:`FEATURE_FIELDS`), so the
features of mirror_lambda(lam) are the signed permutation :func:`mirror_features` of the features of lam
(checked to the last bit in the tests): the tied network of :mod:`~margin_rl.stability.learned.margin_mlp` then stays
exactly mirror-invariant on [lambda, features].

Backends: one formulation, evaluated on plain numpy arrays (values), on :class:`_Jet` (numpy values with
their exact Jacobian d/dlambda carried forward) or on torch tensors (autograd, ONNX export).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from margin_rl.stability.analytic.lambda_state import (
    LAMBDA_DIM,
    LAMBDA_SLICES,
    MIRROR_LEGS,
    MIRROR_SIGN,
    MIRROR_SOURCE,
    N_FEET,
    LambdaField,
    check_lambda,
    float_array_with_last_dim,
)

__all__ = [
    "FEATURE_FIELDS",
    "FEATURE_MIRROR_SIGN",
    "FEATURE_MIRROR_SOURCE",
    "FEATURE_SLICES",
    "INPUT_MIRROR_SIGN",
    "INPUT_MIRROR_SOURCE",
    "N_FEATURES",
    "PHYSICS_INPUT_DIM",
    "PROXY_INDEX",
    "PhysicsConstants",
    "feature_names",
    "input_names",
    "mirror_features",
    "mirror_inputs",
    "physics_features",
    "physics_features_and_jacobian",
    "physics_features_torch",
    "physics_inputs",
    "support_distance",
]

FEATURE_FIELDS: tuple[LambdaField, ...] = (
    LambdaField("capture_point", (2,), "H", "m", "ICP xi = c_dot_xy sqrt(h / g) relative to the CoM", "polar"),
    LambdaField("com_height", (1,), "-", "m", "CoM height h above the stance contact points (mean)"),
    LambdaField("load_shift", (2,), "H", "m", "shift s of the statically feasible CoM region by the load", "polar"),
    LambdaField("shifted_capture_point", (2,), "H", "m", "q = xi - s", "polar"),
    LambdaField("capture_point_from_feet", (N_FEET, 2), "H", "m", "q - P_i,xy per foot", "polar"),
    LambdaField("friction_usage", (1,), "-", "-", "|F_xy| / (mu F_z)"),
    LambdaField("cone_slack", (N_FEET,), "-", "-", "(mu F.n_i - |F_t,i|) / |F| per foot"),
    LambdaField("icp_support_distance", (1,), "-", "m", "signed distance of xi to the stance hull"),
    LambdaField("support_margin", (1,), "-", "m", "signed distance of q to the stance hull (the proxy)"),
)

N_FEATURES: int = sum(f.size for f in FEATURE_FIELDS)
_OFFSETS = np.cumsum([0] + [f.size for f in FEATURE_FIELDS]).tolist()
FEATURE_SLICES: dict[str, slice] = {
    f.name: slice(a, b) for f, a, b in zip(FEATURE_FIELDS, _OFFSETS[:-1], _OFFSETS[1:], strict=True)
}
PROXY_INDEX: int = FEATURE_SLICES["support_margin"].start
"""Column of the analytic proxy (``support_margin``) in the feature vector."""

_LEGS = ("LF", "RF", "LH", "RH")


def feature_names() -> tuple[str, ...]:
    """One readable name per feature, e.g. ``load_shift.y``, ``capture_point_from_feet.LF.x``."""
    names: list[str] = []
    for f in FEATURE_FIELDS:
        prefixes = [f"{f.name}.{leg}" for leg in _LEGS] if f.shape[0] == N_FEET else [f.name]
        if f.shape[-1] == 2:  # a planar vector per prefix
            prefixes = [f"{prefix}.{axis}" for prefix in prefixes for axis in ("x", "y")]
        names.extend(prefixes)
    return tuple(names)


def _feature_mirror_map() -> tuple[np.ndarray, np.ndarray]:
    """The sagittal mirror on the features, read off their names: a feature's mirror partner has the left
    and right legs swapped, and the y component of a polar (planar vector) feature changes sign."""
    names = feature_names()
    swap = {leg: _LEGS[partner] for leg, partner in zip(_LEGS, MIRROR_LEGS, strict=True)}
    polar = {f.name for f in FEATURE_FIELDS if f.parity == "polar"}
    source, sign = np.zeros(N_FEATURES, dtype=int), np.ones(N_FEATURES)
    for k, name in enumerate(names):
        parts = name.split(".")
        source[k] = names.index(".".join(swap.get(p, p) for p in parts))
        if parts[0] in polar and parts[-1] == "y":
            sign[k] = -1.0
    return source, sign


FEATURE_MIRROR_SOURCE, FEATURE_MIRROR_SIGN = _feature_mirror_map()


def mirror_features(features: np.ndarray) -> np.ndarray:
    """Features of the mirrored state from those of the state: (..., N_FEATURES) -> new array."""
    arr = float_array_with_last_dim(features, N_FEATURES, "features")
    return arr[..., FEATURE_MIRROR_SOURCE] * FEATURE_MIRROR_SIGN


@dataclass(frozen=True)
class PhysicsConstants:
    """The robot constants the features need: total mass [kg], gravity [m/s^2], foot-sphere radius [m]."""

    mass: float
    gravity: float
    foot_radius: float

    def __post_init__(self) -> None:
        for name in ("mass", "gravity"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"PhysicsConstants.{name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.foot_radius) and self.foot_radius >= 0):
            raise ValueError(f"PhysicsConstants.foot_radius must be finite and >= 0, got {self.foot_radius!r}")

    @classmethod
    def for_robot(cls, robot: Any) -> PhysicsConstants:
        """From a :class:`margin_rl.robot.Robot` (``total_mass``, ``gravity``, ``foot_radius``)."""
        return cls(float(robot.total_mass), float(robot.gravity), float(robot.foot_radius))

    def to_array(self) -> np.ndarray:
        return np.array([self.mass, self.gravity, self.foot_radius], dtype=np.float64)

    @classmethod
    def from_array(cls, values: np.ndarray) -> PhysicsConstants:
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if values.shape != (3,):
            raise ValueError(f"physics constants must be (mass, gravity, foot_radius), got shape {values.shape}")
        return cls(*(float(v) for v in values))


# ----------------------------------------------------------------------------- constants of the formulation
CONTACT_DELTA = 1e-6  # weight of a swing foot in the CoM height (defines h with no foot in contact)
HEIGHT_FLOOR = 0.01  # [m] smooth floor of h (Table I heights are 0.3-0.7 m: a 0.1 mm change at most)
FORCE_FLOOR = 0.02  # smooth floor of F_z, as a fraction of m g (changes F_z = m g by 1e-4 relative)
SWING_PENALTY = 10.0  # [m] L: a swing foot's support value is lowered by L (1 - c)
DIRECTION_EPS = 1e-12  # [m] eps of the direction normalisation w / sqrt(|w|^2 + eps^2)
FORCE_EPS = 1e-3  # smooth norms of forces: eps = 1e-3 m g [N]
MU_FLOOR = 1e-3  # smooth floor of mu in the friction usage (finite for mu = 0; 1e-6 relative at mu = 0.2)


# ----------------------------------------------------------------------------- backends
class _Jet:
    """A numpy value with its exact Jacobian d value / d lambda: ``val`` (N, *s), ``jac`` (N, *s, 47).

    Forward-mode differentiation for the handful of operations the features use (arithmetic, sqrt, stack,
    per-sample gather); constants are plain numpy arrays or floats broadcasting against ``val``.
    """

    __slots__ = ("jac", "val")
    __array_ufunc__ = None  # ndarray (op) _Jet defers to _Jet's reflected operators

    def __init__(self, val: np.ndarray, jac: np.ndarray) -> None:
        self.val, self.jac = val, jac

    def __add__(self, other: object) -> _Jet:
        if isinstance(other, _Jet):
            return _Jet(self.val + other.val, self.jac + other.jac)
        return _Jet(self.val + other, self.jac)

    __radd__ = __add__

    def __neg__(self) -> _Jet:
        return _Jet(-self.val, -self.jac)

    def __sub__(self, other: object) -> _Jet:
        if isinstance(other, _Jet):
            return _Jet(self.val - other.val, self.jac - other.jac)
        return _Jet(self.val - other, self.jac)

    def __rsub__(self, other: object) -> _Jet:
        return _Jet(other - self.val, -self.jac)

    def __mul__(self, other: object) -> _Jet:
        if isinstance(other, _Jet):
            return _Jet(self.val * other.val, self.jac * other.val[..., None] + other.jac * self.val[..., None])
        c = np.asarray(other)
        return _Jet(self.val * c, self.jac * c[..., None])

    __rmul__ = __mul__

    def __truediv__(self, other: object) -> _Jet:
        if isinstance(other, _Jet):
            val = self.val / other.val
            return _Jet(val, (self.jac - other.jac * val[..., None]) / other.val[..., None])
        c = np.asarray(other)
        return _Jet(self.val / c, self.jac / c[..., None])

    def __rtruediv__(self, other: object) -> _Jet:
        val = other / self.val
        return _Jet(val, -self.jac * (val / self.val)[..., None])


class _NumpyOps:
    """Plain numpy values (no derivatives)."""

    @staticmethod
    def sqrt(x: Any) -> Any:
        return np.sqrt(x)

    @staticmethod
    def stack(items: list[Any]) -> Any:
        return np.stack(items, axis=1)


class _JetOps:
    """:class:`_Jet` values and Jacobians."""

    @staticmethod
    def sqrt(x: _Jet) -> _Jet:
        root = np.sqrt(x.val)
        return _Jet(root, x.jac / (2.0 * root)[..., None])

    @staticmethod
    def stack(items: list[_Jet]) -> _Jet:
        return _Jet(np.stack([i.val for i in items], axis=1), np.stack([i.jac for i in items], axis=1))


class _TorchOps:
    """torch tensors (autograd)."""

    def __init__(self) -> None:
        import torch  # lazy: the numpy paths never import torch

        self.torch = torch

    def sqrt(self, x: Any) -> Any:
        return self.torch.sqrt(x)

    def stack(self, items: list[Any]) -> Any:
        return self.torch.stack(items, dim=1)


def _floor(x: Any, scale: float, ops: Any) -> Any:
    """Smooth lower bound (x + sqrt(x^2 + scale^2)) / 2: about x for x >> scale, positive everywhere."""
    return 0.5 * (x + ops.sqrt(x * x + scale * scale))


# ----------------------------------------------------------------------------- the formulation
@dataclass
class _Terms:
    """Per-sample columns (N,) of the smooth part, in one backend's arrays."""

    contact_x: list[Any]  # P_i,x
    contact_y: list[Any]  # P_i,y
    contacts: list[Any]  # c_i
    features: list[Any]  # every feature column except the two support distances
    xi: tuple[Any, Any]
    q: tuple[Any, Any]


def _smooth_terms(col: Any, constants: PhysicsConstants, ops: Any) -> _Terms:
    """The smooth features from lambda's columns (``col(name, k)``: column k of a field, shape (N,))."""
    m, g, r = constants.mass, constants.gravity, constants.foot_radius
    contacts = [col("contacts", i) for i in range(N_FEET)]
    foot = [[col("feet", 3 * i + a) for a in range(3)] for i in range(N_FEET)]
    normal = [[col("normals", 3 * i + a) for a in range(3)] for i in range(N_FEET)]
    point = [[foot[i][a] - r * normal[i][a] for a in range(3)] for i in range(N_FEET)]

    # Sums over feet as (LF + RF) + (LH + RH): the mirror swaps the terms of each pair, and float addition
    # is commutative, so h is bit-identical for a state and its mirror image.
    total = (contacts[0] + contacts[1]) + (contacts[2] + contacts[3]) + N_FEET * CONTACT_DELTA
    weighted = [(contacts[i] + CONTACT_DELTA) * point[i][2] for i in range(N_FEET)]
    depth = (weighted[0] + weighted[1]) + (weighted[2] + weighted[3])
    h = _floor(-depth / total, HEIGHT_FLOOR, ops)
    time_constant = ops.sqrt(h * (1.0 / g))  # 1 / omega
    xi = (col("com_vel", 0) * time_constant, col("com_vel", 1) * time_constant)

    acc = [col("com_acc", a) for a in range(3)]
    f_ext = [col("ext_force", a) for a in range(3)]
    tau = [col("ext_torque", a) for a in range(3)]
    force = [m * acc[0] - f_ext[0], m * acc[1] - f_ext[1], m * (acc[2] + g) - f_ext[2]]
    fz = _floor(force[2], FORCE_FLOOR * m * g, ops)
    shift = ((h * force[0] - tau[1]) / fz, (h * force[1] + tau[0]) / fz)
    q = (xi[0] - shift[0], xi[1] - shift[1])

    eps2 = (FORCE_EPS * m * g) ** 2
    friction_usage = ops.sqrt(force[0] * force[0] + force[1] * force[1] + eps2) / (
        _floor(col("mu", 0), MU_FLOOR, ops) * fz
    )
    force_sq = force[0] * force[0] + force[1] * force[1] + force[2] * force[2]
    force_norm = ops.sqrt(force_sq + eps2)
    slack = []
    for i in range(N_FEET):
        n = normal[i]
        n_norm = ops.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        along = (force[0] * n[0] + force[1] * n[1] + force[2] * n[2]) / n_norm
        tangential = ops.sqrt(force_sq - along * along + eps2)
        slack.append((col("mu", 0) * along - tangential) / force_norm)

    relative = []
    for i in range(N_FEET):
        relative += [q[0] - point[i][0], q[1] - point[i][1]]
    columns = [xi[0], xi[1], h, shift[0], shift[1], q[0], q[1], *relative, friction_usage, *slack]
    return _Terms(
        contact_x=[point[i][0] for i in range(N_FEET)],
        contact_y=[point[i][1] for i in range(N_FEET)],
        contacts=contacts,
        features=columns,
        xi=xi,
        q=q,
    )


def _candidate_table() -> tuple[np.ndarray, ...]:
    """Candidate directions w = alpha (B - A) + beta perp(B - A) + (k_x, k_y), A, B indices into (P_0..P_3, q).

    Ordered pairs of feet (a, b), a != b: w = perp(P_b - P_a), perp(x, y) = (y, -x), an edge normal (both
    orientations over the two orders); one per foot k: w = q - P_k (from a vertex towards q); and the fixed
    axes +-x, +-y, which only matter when every other candidate is degenerate (all points coincide).
    The set is closed under the mirror y -> -y with left and right feet swapped.
    """
    pairs = [(a, b) for a in range(N_FEET) for b in range(N_FEET) if a != b]
    axes = [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)]
    first = np.array([a for a, _ in pairs] + list(range(N_FEET)) + [0] * len(axes))
    second = np.array([b for _, b in pairs] + [N_FEET] * N_FEET + [0] * len(axes))
    alpha = np.array([0.0] * len(pairs) + [1.0] * N_FEET + [0.0] * len(axes))
    beta = np.array([1.0] * len(pairs) + [0.0] * N_FEET + [0.0] * len(axes))
    kx = np.array([0.0] * (len(pairs) + N_FEET) + [k[0] for k in axes])
    ky = np.array([0.0] * (len(pairs) + N_FEET) + [k[1] for k in axes])
    return first, second, alpha, beta, kx, ky


_FIRST, _SECOND, _ALPHA, _BETA, _KX, _KY = _candidate_table()


def _support_values(xs: Any, ys: Any, qx: Any, qy: Any, contacts: Any, table: tuple[Any, ...]) -> Any:
    """u_c . (P_k - q) - L (1 - c_k) for candidates c (axis 1) and feet k (axis 2), dense.

    ``xs``, ``ys``: (N, 5) x and y of (P_0..P_3, q); ``contacts`` (N, 4); ``table``: the candidate arrays
    of :func:`_candidate_table` in the same array type (numpy or torch). Works for both alike.
    """
    first, second, alpha, beta, kx, ky = table
    dx = xs[:, second] - xs[:, first]
    dy = ys[:, second] - ys[:, first]
    wx = alpha * dx + beta * dy + kx  # perp(d) = (d_y, -d_x)
    wy = alpha * dy - beta * dx + ky
    norm2 = wx * wx + wy * wy + DIRECTION_EPS * DIRECTION_EPS
    norm = norm2**0.5
    ux, uy = wx / norm, wy / norm
    degenerate = SWING_PENALTY * (DIRECTION_EPS * DIRECTION_EPS) / norm2  # L (1 - |u|^2): L when w = 0
    px = xs[:, None, :N_FEET] - qx[:, None, None]
    py = ys[:, None, :N_FEET] - qy[:, None, None]
    support = ux[:, :, None] * px + uy[:, :, None] * py - SWING_PENALTY * (1.0 - contacts[:, None, :])
    return support + degenerate[:, :, None]


def _support_distance_numpy(xs: np.ndarray, ys: np.ndarray, contacts: np.ndarray) -> tuple[np.ndarray, ...]:
    """min over candidates of max over feet: values (N,), and the active candidate and foot (N,) each."""
    table = (_FIRST, _SECOND, _ALPHA, _BETA, _KX, _KY)
    values = _support_values(xs, ys, xs[:, N_FEET], ys[:, N_FEET], contacts, table)
    foot = values.argmax(axis=2)  # (N, C)
    best = np.take_along_axis(values, foot[:, :, None], axis=2)[:, :, 0]
    candidate = best.argmin(axis=1)
    rows = np.arange(len(xs))
    return best[rows, candidate], candidate, foot[rows, candidate]


def _gather(items: list[_Jet], index: np.ndarray) -> _Jet:
    """Per-sample choice among (N,) jets: out[n] = items[index[n]][n]."""
    stacked = _JetOps.stack(items)
    val = np.take_along_axis(stacked.val, index[:, None], axis=1)[:, 0]
    jac = np.take_along_axis(stacked.jac, index[:, None, None], axis=1)[:, 0]
    return _Jet(val, jac)


def _support_distance_jet(xs: list[_Jet], ys: list[_Jet], contacts: list[_Jet]) -> _Jet:
    """The support distance with its Jacobian: the active candidate and foot, differentiated (module doc)."""
    _, candidate, foot = _support_distance_numpy(
        np.stack([x.val for x in xs], 1), np.stack([y.val for y in ys], 1), np.stack([c.val for c in contacts], 1)
    )
    a, b, alpha, beta = _FIRST[candidate], _SECOND[candidate], _ALPHA[candidate], _BETA[candidate]
    dx, dy = _gather(xs, b) - _gather(xs, a), _gather(ys, b) - _gather(ys, a)
    wx = alpha * dx + beta * dy + _KX[candidate]
    wy = alpha * dy - beta * dx + _KY[candidate]
    norm2 = wx * wx + wy * wy + DIRECTION_EPS * DIRECTION_EPS
    norm = _JetOps.sqrt(norm2)
    ux, uy = wx / norm, wy / norm
    degenerate = SWING_PENALTY * (DIRECTION_EPS * DIRECTION_EPS) / norm2
    px = _gather(xs[:N_FEET], foot) - xs[N_FEET]
    py = _gather(ys[:N_FEET], foot) - ys[N_FEET]
    # The flags are a mask here, not a variable: no derivative (with one, the two feet of an edge, which
    # tie structurally, would give different gradients in the flags).
    flags = np.take_along_axis(np.stack([c.val for c in contacts], 1), foot[:, None], axis=1)[:, 0]
    return ux * px + uy * py - SWING_PENALTY * (1.0 - flags) + degenerate


def support_distance(feet_xy: np.ndarray, contacts: np.ndarray, point: np.ndarray) -> float | np.ndarray:
    """Signed distance [m] of ``point`` to the convex hull of the feet in contact (module docstring).

    Args:
        feet_xy: (..., 4, 2) contact points in the plane.
        contacts: (..., 4) flags (1 stance, 0 swing).
        point: (..., 2).

    Returns:
        Positive inside (the distance to the boundary), minus the Euclidean distance outside; a segment for
        two feet, a point for one; about -10 m with no foot in contact.
    """
    feet = np.asarray(feet_xy, dtype=float)
    c = np.asarray(contacts, dtype=float)
    p = np.asarray(point, dtype=float)
    if feet.shape[-2:] != (N_FEET, 2) or c.shape[-1:] != (N_FEET,) or p.shape[-1:] != (2,):
        raise ValueError(
            f"need feet (..., 4, 2), contacts (..., 4), point (..., 2); got {feet.shape}, {c.shape}, {p.shape}"
        )
    batch = np.broadcast_shapes(feet.shape[:-2], c.shape[:-1], p.shape[:-1])
    feet = np.broadcast_to(feet, (*batch, N_FEET, 2)).reshape(-1, N_FEET, 2)
    c = np.broadcast_to(c, (*batch, N_FEET)).reshape(-1, N_FEET)
    p = np.broadcast_to(p, (*batch, 2)).reshape(-1, 2)
    xs = np.concatenate([feet[:, :, 0], p[:, :1]], axis=1)
    ys = np.concatenate([feet[:, :, 1], p[:, 1:]], axis=1)
    value = _support_distance_numpy(xs, ys, c)[0].reshape(batch)
    return float(value) if value.ndim == 0 else value


# ----------------------------------------------------------------------------- public entry points
def _as_batch(lam: np.ndarray) -> tuple[np.ndarray, bool]:
    x = check_lambda(lam)
    if x.ndim == 1:
        return x[None, :], True
    if x.ndim != 2:
        raise ValueError(f"lam must have shape ({LAMBDA_DIM},) or (N, {LAMBDA_DIM}), got {x.shape}")
    return x, False


def _numpy_column(x: np.ndarray) -> Any:
    def col(name: str, k: int) -> np.ndarray:
        return x[:, LAMBDA_SLICES[name].start + k]

    return col


def physics_features(lam: np.ndarray, constants: PhysicsConstants) -> np.ndarray:
    """The features (float64): (47,) -> (N_FEATURES,), (N, 47) -> (N, N_FEATURES).

    Raises:
        ValueError: lambda of the wrong shape or with NaN/inf (the message names the field).
    """
    x, single = _as_batch(lam)
    terms = _smooth_terms(_numpy_column(x), constants, _NumpyOps)
    xs = np.stack([*terms.contact_x, terms.xi[0]], 1)
    ys = np.stack([*terms.contact_y, terms.xi[1]], 1)
    contacts = np.stack(terms.contacts, 1)
    icp_distance = _support_distance_numpy(xs, ys, contacts)[0]
    xs[:, N_FEET], ys[:, N_FEET] = terms.q
    proxy = _support_distance_numpy(xs, ys, contacts)[0]
    out = np.column_stack([*terms.features, icp_distance, proxy])
    return out[0] if single else out


def physics_features_and_jacobian(lam: np.ndarray, constants: PhysicsConstants) -> tuple[np.ndarray, np.ndarray]:
    """The features and their exact Jacobian d feature / d lambda: (47,) -> ((F,), (F, 47)), batches (N, ...)."""
    x, single = _as_batch(lam)
    n = len(x)

    def col(name: str, k: int) -> _Jet:
        j = LAMBDA_SLICES[name].start + k
        jac = np.zeros((n, LAMBDA_DIM))
        jac[:, j] = 1.0
        return _Jet(x[:, j].copy(), jac)

    terms = _smooth_terms(col, constants, _JetOps)
    icp_distance = _support_distance_jet(
        [*terms.contact_x, terms.xi[0]], [*terms.contact_y, terms.xi[1]], terms.contacts
    )
    proxy = _support_distance_jet([*terms.contact_x, terms.q[0]], [*terms.contact_y, terms.q[1]], terms.contacts)
    stacked = _JetOps.stack([*terms.features, icp_distance, proxy])
    if single:
        return stacked.val[0], stacked.jac[0]
    return stacked.val, stacked.jac


def physics_features_torch(lam: Any, constants: PhysicsConstants) -> Any:
    """The features of a torch tensor (..., 47) -> (..., N_FEATURES), differentiable (autograd) and traceable
    for ONNX export (dense candidates, amax/amin)."""
    import torch

    if lam.shape[-1] != LAMBDA_DIM:
        raise ValueError(f"lambda must have last dimension {LAMBDA_DIM}, got shape {tuple(lam.shape)}")
    batch = lam.shape[:-1]
    x = lam.reshape(-1, LAMBDA_DIM)

    def col(name: str, k: int) -> Any:
        return x[:, LAMBDA_SLICES[name].start + k]

    ops = _TorchOps()
    terms = _smooth_terms(col, constants, ops)
    contacts = torch.stack(terms.contacts, 1).detach()  # a mask in the support distance (as in numpy)
    table = (  # on lambda's device: a tensor elsewhere (the CPU's beside a GPU's) could not be combined with it
        torch.as_tensor(_FIRST, device=x.device),
        torch.as_tensor(_SECOND, device=x.device),
        *(torch.as_tensor(a, dtype=x.dtype, device=x.device) for a in (_ALPHA, _BETA, _KX, _KY)),
    )

    def distance(point: tuple[Any, Any]) -> Any:
        xs = torch.stack([*terms.contact_x, point[0]], 1)
        ys = torch.stack([*terms.contact_y, point[1]], 1)
        values = _support_values(xs, ys, point[0], point[1], contacts, table)
        return values.amax(dim=2).amin(dim=1)

    out = torch.stack([*terms.features, distance(terms.xi), distance(terms.q)], dim=1)
    return out.reshape(*batch, N_FEATURES)


# ----------------------------------------------------------------------------- the physics network's input
PHYSICS_INPUT_DIM: int = LAMBDA_DIM + N_FEATURES
"""Width of the physics network's input [lambda, features]."""

INPUT_MIRROR_SOURCE: np.ndarray = np.concatenate([MIRROR_SOURCE, LAMBDA_DIM + FEATURE_MIRROR_SOURCE])
INPUT_MIRROR_SIGN: np.ndarray = np.concatenate([MIRROR_SIGN, FEATURE_MIRROR_SIGN])
"""The mirror on [lambda, features], a signed permutation (an involution, equal signs on swapped entries)."""


def physics_inputs(lam: np.ndarray, constants: PhysicsConstants) -> np.ndarray:
    """[lambda, features]: (N, 47) -> (N, 47 + N_FEATURES) (float64)."""
    x, single = _as_batch(lam)
    out = np.concatenate([x, physics_features(x, constants)], axis=1)
    return out[0] if single else out


def mirror_inputs(x: np.ndarray) -> np.ndarray:
    """The mirror of network inputs: lambda (..., 47) or [lambda, features] (..., 47 + N_FEATURES)."""
    arr = np.asarray(x, dtype=float)
    if arr.ndim >= 1 and arr.shape[-1] == LAMBDA_DIM:
        return arr[..., MIRROR_SOURCE] * MIRROR_SIGN
    if arr.ndim >= 1 and arr.shape[-1] == PHYSICS_INPUT_DIM:
        return arr[..., INPUT_MIRROR_SOURCE] * INPUT_MIRROR_SIGN
    raise ValueError(f"inputs must have last dimension {LAMBDA_DIM} or {PHYSICS_INPUT_DIM}, got shape {arr.shape}")


def input_names(width: int) -> tuple[str, ...]:
    """Names of the network inputs of a given width (lambda's, then the features')."""
    from margin_rl.stability.analytic.lambda_state import lambda_names

    return lambda_names() + (feature_names() if width == PHYSICS_INPUT_DIM else ())
