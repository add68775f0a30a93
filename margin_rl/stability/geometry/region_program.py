r"""The Feasible Region's conic program of one state and its support oracle (one Clarabel solver per region).

The program's rows, variables and cones are derived in the :mod:`~margin_rl.stability.geometry.region`
docstring: the Newton-Euler equalities (:func:`fill_equilibrium`), the clipping box on c_xy, the contact
torque bounds, the joint-torque rows of each stance leg (:func:`torque_blocks`) and the friction cones or
pyramids (:func:`friction_blocks`); :func:`build_program` assembles them. :class:`SupportOracle` maximises
a^T c over the program's feasible set, direction after direction, for
:func:`~margin_rl.stability.geometry.projection.iterative_projection`. The batched programs of
:mod:`~margin_rl.stability.geometry.region_batch` share these row builders and the oracle.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from margin_rl.stability.geometry.contact import INFEASIBLE, SOLVED, solver_settings, tangent_bases
from margin_rl.stability.geometry.projection import SUPPORT_FAILED, SUPPORT_INFEASIBLE, SUPPORT_OK

__all__ = [
    "CLIP_BOX_DIRECTIONS",
    "FAST_SETTINGS",
    "N_EQUILIBRIUM_ROWS",
    "ROBUST_SETTINGS",
    "ROW_TORQUE",
    "ConicProgram",
    "SupportOracle",
    "build_program",
    "fill_equilibrium",
    "friction_blocks",
    "torque_blocks",
    "zero_cost",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ConicProgram:
    """One state's program in Clarabel's form: ``A x + s = b``, ``s`` in ``cones``, over ``n_var`` variables."""

    A: sp.csc_matrix
    b: FloatArray
    cones: list[Any]
    n_var: int


@functools.lru_cache(maxsize=64)
def _block_diag_index(n: int, r: int, row0: int = 0) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices ``(rows, cols)``, shapes (n, r, 1) and (n, 1, 3), that place n per-foot (r, 3) blocks on
    the diagonal of the force columns (4 + 3 i ...) from row ``row0`` on; cached, read-only."""
    rows = row0 + np.arange(n * r).reshape(n, r, 1)
    cols = 4 + 3 * np.arange(n).reshape(n, 1, 1) + np.arange(3).reshape(1, 1, 3)
    rows.flags.writeable = cols.flags.writeable = False
    return rows, cols


def _block_diag(blocks: FloatArray) -> FloatArray:
    """(n, r, 3) per-foot blocks -> (n r, 4 + 3 n) rows acting block-diagonally on (f_1, ..., f_n).

    The first 4 (zero) columns are those of (c_x, c_y, W_x, W_y).
    """
    n, r, _ = blocks.shape
    out = np.zeros((n * r, 4 + 3 * n))
    rows, cols = _block_diag_index(n, r)
    out[rows, cols] = blocks
    return out


def _dense_to_csc(a: FloatArray) -> sp.csc_matrix:
    """CSC matrix of the non-zero entries of a dense matrix, in CSC order (columns, then rows).

    The same arrays as ``sp.csc_matrix(dense)`` (explicit zeros dropped, rows sorted), about 2x faster
    for these tiny matrices; fastest when ``a`` is Fortran-ordered (its column-major ravel is then a
    view). Indices are int32, which spares scipy's constructor a downcast.
    """
    m, n = a.shape
    flat = a.ravel(order="F")
    nz = np.flatnonzero(flat)
    indptr = np.searchsorted(nz, np.arange(n + 1) * m).astype(np.int32)  # first entry of each column
    return sp.csc_matrix((flat[nz], (nz % m).astype(np.int32), indptr), shape=(m, n))


CLIP_BOX_DIRECTIONS = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
# Row offsets of the blocks of A: 6 Newton-Euler equalities, then 4 clipping-box rows on c and 4
# rows |W| <= n w_M, then the torque and friction rows.
N_EQUILIBRIUM_ROWS: int = 6
ROW_TORQUE: int = N_EQUILIBRIUM_ROWS + 8


def fill_equilibrium(a: FloatArray, b: FloatArray, feet: FloatArray, force: FloatArray, moment: FloatArray) -> None:
    """Rows 0-5 of ``A x + s = b`` (s = 0): Newton  sum_i f_i = F,  Euler  sum_i p_i x f_i + W - c x F = M,
    with ``force`` F [N] and ``moment`` M = L_dot - tau_ext [N m] (module docstring).

    With c = (c_x, c_y, 0): -(c x F) = (-c_y F_z, c_x F_z, -(c_x F_y - c_y F_x)). Column 4 + 3 i + j
    holds component j of f_i, so row 3 gets (p_i x f_i)_x = p_y f_z - p_z f_y as -p_z at f_y and p_y
    at f_z, and so on. Leading axes are states: ``a`` (..., rows, cols), ``feet`` (..., n, 3), ``force``
    and ``moment`` (..., 3) (one state, or a batch with :mod:`~margin_rl.stability.geometry.region_batch`).
    """
    fx, fy, fz = force[..., 0], force[..., 1], force[..., 2]
    a[..., 0, 4::3] = a[..., 1, 5::3] = a[..., 2, 6::3] = 1.0  # sum_i f_i
    a[..., 3, 1] = -fz
    a[..., 4, 0] = fz
    a[..., 5, 0] = -fy
    a[..., 5, 1] = fx
    a[..., 3, 2] = a[..., 4, 3] = 1.0  # W_x, W_y
    px, py, pz = feet[..., 0], feet[..., 1], feet[..., 2]
    a[..., 3, 5::3], a[..., 3, 6::3] = -pz, py
    a[..., 4, 4::3], a[..., 4, 6::3] = pz, -px
    a[..., 5, 4::3], a[..., 5, 5::3] = -py, px
    b[..., 0:3] = force
    b[..., 3:6] = moment


def torque_blocks(jac: FloatArray, lo: FloatArray, hi: FloatArray, bias: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per-foot torque rows ``J_i^T f_i <= delta_i - lo_i`` and ``-J_i^T f_i <= hi_i - delta_i``: blocks
    (..., n, 2 k, 3) and right-hand sides (..., n, 2 k), from jac (..., n, 3, k) and (..., n, k) arrays."""
    jt = np.swapaxes(jac, -1, -2)  # (..., n, k, 3)
    return np.concatenate([jt, -jt], axis=-2), np.concatenate([bias - lo, hi - bias], axis=-1)


def friction_blocks(normals: FloatArray, mu: Any, n_faces: int) -> FloatArray:
    """Per-foot friction rows (..., n, r, 3) from unit normals (..., n, 3) and mu (scalar or (...,)).

    Pyramid (``n_faces`` k > 0): d_j^T f - mu cos(pi/k) n^T f <= 0 for the k face directions d_j, then
    -n^T f <= 0 (r = k + 1, non-negative cone). Cone (k = 0): s = -A f = (mu n^T f, t1^T f, t2^T f) in
    the second-order cone (r = 3).
    """
    t1, t2 = tangent_bases(normals)
    mu_b = np.asarray(mu)[..., None, None]  # broadcasts over (n, 3)
    if n_faces:
        th = 2.0 * np.pi * np.arange(n_faces) / n_faces
        d = np.cos(th)[:, None] * t1[..., None, :] + np.sin(th)[:, None] * t2[..., None, :]
        faces = d - (mu_b[..., None] * math.cos(math.pi / n_faces)) * normals[..., None, :]
        return np.concatenate([faces, -normals[..., None, :]], axis=-2)
    return -np.stack([mu_b * normals, t1, t2], axis=-2)


def build_program(
    feet: FloatArray,
    normals: FloatArray,
    mu: float,
    jac: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    bias: FloatArray,
    force: FloatArray,
    moment: FloatArray,
    n_faces: int,
    w_max: float,
    extent: float,
) -> ConicProgram:
    """Assemble ``A x + s = b`` with ``s`` in Zero(6) x NonNeg(.) [x SOC(3)^n] (stance feet only).

    Row blocks: 6 Newton-Euler equalities; 4 clipping-box rows on c; 4 rows |W| <= n w_M;
    2 k torque rows per foot (finite bounds only); then the friction rows, per foot either
    k_p + 1 pyramid rows (non-negative cone) or 3 rows of a second-order cone.

    A is filled in place in one Fortran-ordered array (its column-major ravel is then the CSC
    order); only its non-zero entries are passed to Clarabel.
    """
    n, k = jac.shape[0], jac.shape[2]
    n_var = 4 + 3 * n

    # Torque rows: J_i^T f_i <= delta_i - lo_i and -J_i^T f_i <= hi_i - delta_i.
    tau_blocks, tau_bounds = torque_blocks(jac, lo, hi, bias)
    tau_b = tau_bounds.ravel()
    finite = np.isfinite(tau_b)
    all_finite = bool(finite.all())
    n_tau = tau_b.size if all_finite else int(finite.sum())
    fric_blocks = friction_blocks(normals, mu, n_faces)
    row_fric = ROW_TORQUE + n_tau
    n_rows = row_fric + fric_blocks.shape[0] * fric_blocks.shape[1]

    a = np.zeros((n_rows, n_var), order="F")
    b = np.zeros(n_rows)  # the friction rows' right-hand side stays 0
    fill_equilibrium(a, b, feet, force, moment)
    # Clipping box on c and aggregated contact-torque box.
    a[N_EQUILIBRIUM_ROWS : N_EQUILIBRIUM_ROWS + 4, 0:2] = CLIP_BOX_DIRECTIONS
    a[N_EQUILIBRIUM_ROWS + 4 : ROW_TORQUE, 2:4] = CLIP_BOX_DIRECTIONS
    b[N_EQUILIBRIUM_ROWS : N_EQUILIBRIUM_ROWS + 4] = extent
    b[N_EQUILIBRIUM_ROWS + 4 : ROW_TORQUE] = n * w_max
    if all_finite:
        a[_block_diag_index(n, 2 * k, ROW_TORQUE)] = tau_blocks
        b[ROW_TORQUE:row_fric] = tau_b
    else:  # rows with an infinite bound are dropped
        a[ROW_TORQUE:row_fric] = _block_diag(tau_blocks)[finite]
        b[ROW_TORQUE:row_fric] = tau_b[finite]
    a[_block_diag_index(n, fric_blocks.shape[1], row_fric)] = fric_blocks

    cones = [clarabel.ZeroConeT(N_EQUILIBRIUM_ROWS)]
    if n_faces:
        cones.append(clarabel.NonnegativeConeT(n_rows - N_EQUILIBRIUM_ROWS))
    else:
        cones.append(clarabel.NonnegativeConeT(row_fric - N_EQUILIBRIUM_ROWS))
        cones += [clarabel.SecondOrderConeT(3)] * n
    return ConicProgram(_dense_to_csc(a), b, cones, n_var)


FAST_SETTINGS = solver_settings(robust=False)
ROBUST_SETTINGS = solver_settings(robust=True)
_ZERO_COSTS: dict[int, sp.csc_matrix] = {}


def zero_cost(n_var: int) -> sp.csc_matrix:
    """The all-zero quadratic cost (cached: Clarabel copies its inputs)."""
    p = _ZERO_COSTS.get(n_var)
    if p is None:
        p = _ZERO_COSTS.setdefault(n_var, sp.csc_matrix((n_var, n_var)))
    return p


class SupportOracle:
    """Maximise a^T c over the equilibrium set, re-using one Clarabel solver across directions.

    Only the linear cost q changes between directions (``solver.update(q=...)``), so the
    problem is set up (and its KKT pattern analysed) once per region.  A direction whose fast
    solve fails is retried once with a robust solver, built lazily.
    """

    def __init__(self, prob: ConicProgram) -> None:
        self._prob = prob
        self._q = np.zeros(prob.n_var)
        self._fast = clarabel.DefaultSolver(zero_cost(prob.n_var), self._q, prob.A, prob.b, prob.cones, FAST_SETTINGS)
        self._robust: Any = None
        self.n_solves = 0
        self.n_retries = 0
        self.n_failed = 0

    def _new_robust_solver(self) -> Any:
        """The retry solver (iterative refinement on) of the current program."""
        prob = self._prob
        return clarabel.DefaultSolver(zero_cost(prob.n_var), self._q, prob.A, prob.b, prob.cones, ROBUST_SETTINGS)

    def _solve(self, solver: Any, ax: float, ay: float) -> tuple[int, float, float]:
        self.n_solves += 1
        q = self._q
        q[0] = -ax
        q[1] = -ay
        solver.update(q=q)
        sol = solver.solve()
        status = sol.status
        if status in SOLVED:
            x = sol.x
            return SUPPORT_OK, x[0], x[1]
        if status in INFEASIBLE:
            return SUPPORT_INFEASIBLE, math.nan, math.nan
        return SUPPORT_FAILED, math.nan, math.nan

    def __call__(self, ax: float, ay: float) -> tuple[int, float, float]:
        out = self._solve(self._fast, ax, ay)
        if out[0] != SUPPORT_FAILED:
            # Interior-point infeasibility certificates are reliable: no second opinion.
            return out
        if self._robust is None:
            self._robust = self._new_robust_solver()
        self.n_retries += 1
        out = self._solve(self._robust, ax, ay)
        if out[0] == SUPPORT_FAILED:
            self.n_failed += 1
        return out
