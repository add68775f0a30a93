"""The contact problem both stability criteria share: input checks, contact geometry and the solver kit.

Robot-agnostic (arrays in, arrays out); used by the feasible region (:mod:`~margin_rl.stability.geometry.region`)
and the feasible wrench polytope (:mod:`~margin_rl.stability.fwp.feasibility`):

* the inputs as typed, frozen groups: :class:`ContactSet` (where and how the robot touches the ground),
  :class:`LegLimits` (the legs' Jacobians, torque limits and bias torques) and :class:`CentroidalLoad`
  (mass, accelerations, external wrench, gravity: the wrench the contacts must produce);
* :func:`validate_contact_arrays` (the shared checks of the contact arrays) and the scalar and array
  checks it is made of (:func:`as_array`, :func:`as_rows`, :func:`check_finite`, :func:`positive_scalar`,
  :func:`parse_friction`, :func:`torque_bounds`);
* :func:`gravito_inertial_wrench` (eq. 14-15 of seed 004) and :func:`tangent_bases` of the contact normals;
* the Clarabel kit: :func:`solver_settings` and the statuses :data:`SOLVED` / :data:`INFEASIBLE`.

The groups hold their values as given; they are validated, in a fixed order and with messages that name
the argument, by the function that solves the problem (e.g. :func:`~margin_rl.stability.geometry.region.solve_region`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import clarabel
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DEFAULT_CONTACT_TORQUE_LIMIT",
    "INFEASIBLE",
    "SOLVED",
    "CentroidalLoad",
    "ContactSet",
    "LegLimits",
    "as_array",
    "as_rows",
    "check_finite",
    "frozen_array",
    "gravito_inertial_wrench",
    "parse_friction",
    "positive_scalar",
    "solver_settings",
    "tangent_bases",
    "torque_bounds",
    "validate_contact_arrays",
]

FloatArray = NDArray[np.float64]

#: Default w_M of eq. (3) [N m].  The paper lets w_M -> 0; 0.01 N m changes the region of a
#: 30 kg robot by at most n * 0.01 / 294 m ~ 0.1 mm (4 feet) and gives a two-contact region a
#: half-width <= 2 sqrt(2) * 0.01 / 294 m ~ 0.1 mm, while keeping it full-dimensional.
DEFAULT_CONTACT_TORQUE_LIMIT: float = 1e-2

# AlmostSolved is *not* accepted: it meets only the reduced tolerances (5e-5 on the gap), and a
# point that far from optimal along a nearly flat face breaks the angular order of the support
# points; such directions are retried with the robust solver instead.
SOLVED = (clarabel.SolverStatus.Solved,)
INFEASIBLE = (clarabel.SolverStatus.PrimalInfeasible, clarabel.SolverStatus.AlmostPrimalInfeasible)


def frozen_array(a: ArrayLike, dtype: Any = np.float64) -> Any:
    """A read-only copy (results are frozen dataclasses; their arrays must not change either)."""
    out = np.array(a, dtype=dtype)
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class ContactSet:
    """Where and how the robot touches the ground (frame H: origin at the CoM, z up).

    Attributes:
        points: (n, 3) contact points [m] relative to the CoM.
        normals: (n, 3) contact normals (out of the ground, into the robot); normalised when solved.
        stance: (n,) bool (or 0/1): which contacts are active; the rows of the others are ignored
            entirely (they may hold anything, even NaN).
        mu: friction coefficient (> 0), the same for all contacts.
        friction: ``"cone"`` (exact second-order cone, eq. 1) or ``("pyramid", k)`` (k >= 3 faces,
            inscribed in the cone).
        contact_torque_limit: w_M of eq. (3) [N m] (>= 0).
    """

    points: ArrayLike
    normals: ArrayLike
    stance: ArrayLike
    mu: float
    friction: str | tuple[str, int] = "cone"
    contact_torque_limit: float = DEFAULT_CONTACT_TORQUE_LIMIT


@dataclass(frozen=True)
class LegLimits:
    """The legs behind the contacts: what their joints can push (eq. 2).

    Attributes:
        jacobians: (n, 3, k) translational foot Jacobians w.r.t. each leg's k joints, frame H [m/rad].
        torque_limits: (n, k) symmetric limits ``|tau| <= limit`` (>= 0, may be inf), or a pair
            (lower, upper) of (n, k) arrays [N m].
        leg_bias: (n, k) bias torques delta_i [N m] (the joint torques needed are
            ``tau_i = delta_i - J_i^T f_i``); zeros if None.
    """

    jacobians: ArrayLike
    torque_limits: ArrayLike | tuple[ArrayLike, ArrayLike]
    leg_bias: ArrayLike | None = None


@dataclass(frozen=True)
class CentroidalLoad:
    """What the contacts must balance: mass, accelerations, external wrench and gravity (frame H).

    Attributes:
        mass: total mass [kg] (> 0).
        com_acc: (3,) CoM acceleration [m/s^2].
        ang_momentum_rate: (3,) rate of the centroidal angular momentum [N m].
        ext_force, ext_torque: (3,) external wrench on the robot, applied at the CoM [N], [N m].
        gravity: gravity magnitude g [m/s^2] (> 0); gravity is (0, 0, -g).
    """

    mass: float
    com_acc: ArrayLike = (0.0, 0.0, 0.0)
    ang_momentum_rate: ArrayLike = (0.0, 0.0, 0.0)
    ext_force: ArrayLike = (0.0, 0.0, 0.0)
    ext_torque: ArrayLike = (0.0, 0.0, 0.0)
    gravity: float = 9.81

    def wrench(self) -> FloatArray:
        """(6,) gravito-inertial wrench about the CoM (:func:`gravito_inertial_wrench`); validates."""
        return gravito_inertial_wrench(
            self.mass, self.com_acc, self.ang_momentum_rate, self.ext_force, self.ext_torque, self.gravity
        )


# --------------------------------------------------------------------------------------------
# Input validation
# --------------------------------------------------------------------------------------------


def as_array(name: str, value: ArrayLike, shape: tuple[int, ...]) -> FloatArray:
    """A float array of exactly ``shape``; the message names ``name``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {shape}") from exc
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    return arr


def as_rows(name: str, value: ArrayLike, columns: int, rows: str = "n", min_rows: int = 0) -> FloatArray:
    """A (rows, columns) float array with at least ``min_rows`` rows; the message names ``name``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric ({rows}, {columns}) array") from exc
    if arr.ndim != 2 or arr.shape[1] != columns or arr.shape[0] < min_rows:
        at_least = f" with {rows} >= {min_rows}" if min_rows else ""
        raise ValueError(f"{name} must have shape ({rows}, {columns}){at_least}, got {np.shape(arr)}")
    return arr


def check_finite(name: str, arr: FloatArray) -> None:
    """Raise a ValueError naming ``name`` if ``arr`` holds NaN or inf."""
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite (no NaN/inf)")


def positive_scalar(name: str, value: float, allow_zero: bool = False) -> float:
    """``value`` as a finite float > 0 (>= 0 with ``allow_zero``); the message names ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real number") from exc
    if not math.isfinite(v) or v < 0.0 or (v == 0.0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {bound}, got {value!r}")
    return v


def parse_friction(friction: Any) -> int:
    """Return 0 for the exact cone, else the number of pyramid faces (>= 3)."""
    if isinstance(friction, str):
        if friction == "cone":
            return 0
        raise ValueError(f"friction must be 'cone' or ('pyramid', k), got {friction!r}")
    if (
        isinstance(friction, (tuple, list))
        and len(friction) == 2
        and friction[0] == "pyramid"
        and isinstance(friction[1], (int, np.integer))
        and not isinstance(friction[1], bool)
        and friction[1] >= 3
    ):
        return int(friction[1])
    raise ValueError(f"friction must be 'cone' or ('pyramid', k) with integer k >= 3, got {friction!r}")


def torque_bounds(torque_limits: Any, n: int, k: int, idx: NDArray[np.intp]) -> tuple[FloatArray, FloatArray]:
    """(lower, upper) bounds of the stance legs ``idx``; rows of swing legs are not inspected."""
    try:
        arr = np.asarray(torque_limits, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError("torque_limits must be an (n, k) array or a (lower, upper) pair") from exc
    if arr.ndim == 3:
        if arr.shape != (2, n, k):
            raise ValueError(
                f"torque_limits as a (lower, upper) pair must be two ({n}, {k}) arrays matching "
                f"jacobians (n, 3, k), got {arr.shape[1:]}"
            )
        lo, hi = arr[0][idx], arr[1][idx]
    elif arr.ndim == 2:
        if arr.shape != (n, k):
            raise ValueError(f"torque_limits must have shape ({n}, {k}) matching jacobians (n, 3, k), got {arr.shape}")
        lim = arr[idx]
        if (lim < 0.0).any():
            raise ValueError("torque_limits (symmetric) must be >= 0")
        lo, hi = -lim, lim
    else:
        raise ValueError("torque_limits must be an (n, k) array or a (lower, upper) pair of (n, k) arrays")
    if np.isnan(lo).any() or np.isnan(hi).any():
        raise ValueError("torque_limits must not contain NaN")
    if (lo == np.inf).any() or (hi == -np.inf).any():
        raise ValueError("torque_limits: lower must be < +inf and upper > -inf")
    if (lo > hi).any():
        raise ValueError("torque_limits: lower > upper for some joint")
    return lo, hi


def tangent_bases(normals: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Orthonormal tangents t1, t2, each (..., n, 3) like the unit ``normals``, with (t1, t2, n) right-handed.

    t1 is the projection of the x axis on the tangent plane (of y when the normal is nearly
    along x), so for flat ground t1 = x, t2 = y and a mirror y -> -y maps the basis to itself up
    to the sign of t2 (which leaves the pyramid's set of face directions unchanged). Leading axes
    (a batch of states) are element-wise: each row's result does not depend on the others.
    """
    nx, ny, nz = normals[..., 0], normals[..., 1], normals[..., 2]
    use_x = np.abs(nx) < 0.9
    # t1 = ref - n (n . ref) with ref = x (or y), normalised.
    dot = np.where(use_x, nx, ny)
    t1 = -normals * dot[..., None]
    t1[..., 0] += use_x
    t1[..., 1] += ~use_x
    t1 /= np.sqrt(np.einsum("...j,...j->...", t1, t1))[..., None]
    # t2 = n x t1, written out (np.cross has a large fixed overhead on tiny arrays).
    ax, ay, az = t1[..., 0], t1[..., 1], t1[..., 2]
    t2 = np.empty_like(t1)
    t2[..., 0], t2[..., 1], t2[..., 2] = ny * az - nz * ay, nz * ax - nx * az, nx * ay - ny * ax
    return t1, t2


# --------------------------------------------------------------------------------------------
# Solver kit
# --------------------------------------------------------------------------------------------


def solver_settings(robust: bool, tol: float = 1e-8, max_iter: int = 100) -> Any:
    """Clarabel settings: the fast ones, or the robust fallback (iterative refinement on).

    Iterative refinement of the KKT solves costs ~1/3 of the solve time on these tiny problems
    and, in our tests, changes the optimal support values by < 1e-9 m; it is therefore off by
    default and only used to retry a direction whose fast solve did not converge.
    """
    s = clarabel.DefaultSettings()
    s.verbose = False
    # No presolve: the data contain no infinite bounds, and presolve may forbid data updates.
    s.presolve_enable = False
    s.max_iter = max_iter
    s.tol_gap_abs = tol
    s.tol_gap_rel = tol
    s.tol_feas = tol
    s.iterative_refinement_enable = robust
    return s


def gravito_inertial_wrench(
    mass: float,
    com_acc: ArrayLike = (0.0, 0.0, 0.0),
    ang_momentum_rate: ArrayLike = (0.0, 0.0, 0.0),
    ext_force: ArrayLike = (0.0, 0.0, 0.0),
    ext_torque: ArrayLike = (0.0, 0.0, 0.0),
    gravity: float = 9.81,
    com: ArrayLike = (0.0, 0.0, 0.0),
) -> FloatArray:
    r"""Wrench :math:`w_{GI} = \dot h - w_G - w_{ext}` the contacts must produce (eq. 14-15), frame H.

    See the :mod:`~margin_rl.stability.geometry.region` docstring for the derivation: with
    :math:`F = m(\ddot c - \vec g) - f_{ext}`, :math:`w_{GI} = (F,\ \dot L - \tau_{ext} + c \times F)`,
    moments about the origin of H.

    Parameters
    ----------
    mass : float
        Total mass [kg] (> 0).
    com_acc : (3,) array_like
        CoM acceleration [m/s^2].
    ang_momentum_rate : (3,) array_like
        Rate of centroidal angular momentum :math:`\dot L` [N m].
    ext_force, ext_torque : (3,) array_like
        External wrench on the robot, force applied at the CoM [N], [N m].
    gravity : float
        Gravity magnitude [m/s^2] (> 0); gravity is (0, 0, -g) in H.
    com : (3,) array_like
        CoM position [m] relative to the moment reference (zero: moments about the CoM, which is how
        :func:`fwp_feasibility` and the feasible region use it). A non-zero ``com`` evaluates the
        state with the CoM displaced by ``com`` and everything else fixed.

    Returns
    -------
    (6,) ndarray
        ``(force, moment)`` [N, N m].
    """
    m = positive_scalar("mass", mass)
    g = positive_scalar("gravity", gravity)
    vec = {}
    for name, value in (
        ("com_acc", com_acc),
        ("ang_momentum_rate", ang_momentum_rate),
        ("ext_force", ext_force),
        ("ext_torque", ext_torque),
        ("com", com),
    ):
        arr = as_array(name, value, (3,))
        check_finite(name, arr)
        vec[name] = arr
    force = m * (vec["com_acc"] - np.array([0.0, 0.0, -g])) - vec["ext_force"]
    # com x force, written out (np.cross has a large fixed overhead on 3-vectors; same operations).
    (cx, cy, cz), (fx, fy, fz) = vec["com"].tolist(), force.tolist()
    com_x_force = np.array([cy * fz - cz * fy, cz * fx - cx * fz, cx * fy - cy * fx])
    wrench = np.empty(6)
    wrench[:3] = force
    wrench[3:] = vec["ang_momentum_rate"] - vec["ext_torque"] + com_x_force
    return wrench


def validate_contact_arrays(
    points: ArrayLike,
    normals: ArrayLike,
    stance: ArrayLike,
    jacobians: ArrayLike,
    torque_limits: ArrayLike | tuple[ArrayLike, ArrayLike],
    leg_bias: ArrayLike | None,
    points_name: str = "feet",
    min_joints: int = 1,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.intp]]:
    """Shared input checks of the contact-based criteria (feasible region, wrench polytope).

    Shapes are checked for all n contacts; values only for the stance contacts, whose rows are
    returned: ``(points, unit normals, jacobians, torque_lo, torque_hi, leg_bias, stance_indices)``
    (swing rows may hold anything, even NaN).

    Raises:
        ValueError: naming the malformed argument.
    """
    pts = as_rows(points_name, points, 3)
    n_all = pts.shape[0]
    nrm = as_array("normals", normals, (n_all, 3))
    stance_a = np.asarray(stance)
    if stance_a.shape != (n_all,):
        raise ValueError(f"stance must have shape ({n_all},), got {stance_a.shape}")
    if stance_a.dtype != np.bool_:
        if not np.issubdtype(stance_a.dtype, np.integer) or np.any((stance_a != 0) & (stance_a != 1)):
            raise ValueError("stance must be boolean (or 0/1 integers)")
        stance_a = stance_a.astype(bool)
    try:
        jac = np.asarray(jacobians, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError("jacobians must be a numeric (n, 3, k) array") from exc
    if jac.ndim != 3 or jac.shape[:2] != (n_all, 3) or jac.shape[2] < min_joints:
        raise ValueError(f"jacobians must have shape ({n_all}, 3, k) with k >= {min_joints}, got {jac.shape}")
    k = jac.shape[2]
    idx = np.flatnonzero(stance_a)
    lo, hi = torque_bounds(torque_limits, n_all, k, idx)
    bias = np.zeros((n_all, k)) if leg_bias is None else as_array("leg_bias", leg_bias, (n_all, k))

    pts_s = pts[idx]
    check_finite(points_name, pts_s)
    nrm_s = nrm[idx]
    check_finite("normals", nrm_s)
    lengths = np.linalg.norm(nrm_s, axis=1)
    if (lengths < 1e-9).any():
        raise ValueError("normals must be non-zero for stance contacts")
    jac_s = jac[idx]
    check_finite("jacobians", jac_s)
    bias_s = bias[idx]
    check_finite("leg_bias", bias_s)
    return pts_s, nrm_s / lengths[:, None], jac_s, lo, hi, bias_s, idx
