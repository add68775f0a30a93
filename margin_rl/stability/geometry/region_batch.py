"""The Feasible Region's conic program for many states of one contact configuration, one solver for all.

:func:`~margin_rl.stability.geometry.region.solve_region` assembles the program of one state and sets up a
Clarabel solver for it (the KKT system's sparsity is analysed in that set-up); only the objective
changes between its support directions. Labelling a data set solves thousands of such programs whose
*structure* is the same for every state with the same number of stance feet, joints per leg and
friction model: only the values change. This module keeps that structure fixed:

* :class:`ProgramStructure`: the structural non-zeros of ``A`` (every entry that may be non-zero for
  some state, in CSC order), the row count and the cones of one configuration (cached);
* :func:`program_values`: ``A``'s values on that structure and ``b`` for a batch of states at once
  (numpy over the batch, the same rows as ``region_program.build_program``: shared helpers);
* :class:`ReusedRegionSolver`: one Clarabel solver per structure whose data are replaced state by
  state (``update(A=..., b=...)``, no new set-up) and a support oracle for
  :func:`~margin_rl.stability.geometry.projection.iterative_projection`, with the robust retry of
  :func:`solve_region`.

A structural zero kept in ``A`` (e.g. the x component of a flat-ground normal) is an explicit zero to
Clarabel: the same problem. Clarabel scales updated data with the equilibration computed at set-up
(that of the first state), which changes the iterates, not the optimum: support values agree with a
fresh solver's to the solver tolerance (1e-8), though an interior-point point inside an optimal face
may sit elsewhere on that face; the focused projection's bracket covers this (see
:mod:`~margin_rl.stability.analytic.margin`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from margin_rl.stability.geometry.region_program import (
    CLIP_BOX_DIRECTIONS,
    FAST_SETTINGS,
    N_EQUILIBRIUM_ROWS,
    ROBUST_SETTINGS,
    ROW_TORQUE,
    SupportOracle,
    fill_equilibrium,
    friction_blocks,
    torque_blocks,
)

__all__ = ["ProgramStructure", "ReusedRegionSolver", "program_values"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ProgramStructure:
    """Sparsity structure and cones of the region's program for ``n_stance`` feet with ``n_joints`` joints
    per leg and ``n_faces`` pyramid faces (0: exact cone); all torque bounds finite (arrays read-only).

    Attributes:
        n_var: 4 + 3 n (c_x, c_y, W_x, W_y, then the forces).
        n_rows: rows of ``A`` (equalities, boxes, 2 k torque rows and the friction rows per foot).
        rows, cols: (nnz,) indices of the structural non-zeros, in CSC order (column, then row).
        indptr: (n_var + 1,) CSC column pointers of that structure.
    """

    n_stance: int
    n_joints: int
    n_faces: int
    n_var: int
    n_rows: int
    rows: NDArray[np.intp]
    cols: NDArray[np.intp]
    indptr: NDArray[np.int32]

    @staticmethod
    @functools.cache
    def of(n_stance: int, n_joints: int, n_faces: int) -> ProgramStructure:
        """The structure of one configuration (cached: the same object for equal arguments)."""
        n, k = n_stance, n_joints
        pattern = np.zeros((1, _row_friction(n, k) + n * _friction_rows(n_faces), 4 + 3 * n), dtype=bool)
        ones = np.ones((1, n, 3))
        # Every entry that a state may set: the equilibrium rows with non-zero data, the boxes, full blocks.
        fill_equilibrium(pattern, np.zeros(pattern.shape[:2]), ones, np.ones((1, 3)), np.ones((1, 3)))
        pattern[0, N_EQUILIBRIUM_ROWS:ROW_TORQUE, 0:4] |= np.abs(_box_rows()) > 0
        rows_tau, cols_tau = _block_index(n, 2 * k, ROW_TORQUE)
        pattern[0, rows_tau, cols_tau] = True
        rows_f, cols_f = _block_index(n, _friction_rows(n_faces), _row_friction(n, k))
        pattern[0, rows_f, cols_f] = True
        cols, rows = np.nonzero(pattern[0].T)  # column-major order = CSC order
        indptr = np.searchsorted(cols, np.arange(pattern.shape[2] + 1)).astype(np.int32)
        for a in (rows, cols, indptr):
            a.flags.writeable = False
        return ProgramStructure(n, k, n_faces, 4 + 3 * n, pattern.shape[1], rows, cols, indptr)

    def cones(self) -> list[Any]:
        """Zero(6) x NonNeg(boxes, torques[, pyramid rows]) [x SOC(3)^n]."""
        if self.n_faces:
            return [clarabel.ZeroConeT(N_EQUILIBRIUM_ROWS), clarabel.NonnegativeConeT(self.n_rows - N_EQUILIBRIUM_ROWS)]
        row_friction = _row_friction(self.n_stance, self.n_joints)
        linear = [clarabel.ZeroConeT(N_EQUILIBRIUM_ROWS), clarabel.NonnegativeConeT(row_friction - N_EQUILIBRIUM_ROWS)]
        return linear + [clarabel.SecondOrderConeT(3)] * self.n_stance

    def matrix(self, values: FloatArray) -> sp.csc_matrix:
        """``A`` of one state from its (nnz,) values (explicit zeros kept: the structure is the point)."""
        return sp.csc_matrix((values, self.rows.astype(np.int32), self.indptr), shape=(self.n_rows, self.n_var))


def _friction_rows(n_faces: int) -> int:
    return n_faces + 1 if n_faces else 3


def _row_friction(n: int, k: int) -> int:
    return ROW_TORQUE + 2 * k * n


def _box_rows() -> FloatArray:
    """The 8 box rows on (c_x, c_y, W_x, W_y): |c| <= extent, then |W| <= n w_M."""
    out = np.zeros((8, 4))
    out[0:4, 0:2] = CLIP_BOX_DIRECTIONS
    out[4:8, 2:4] = CLIP_BOX_DIRECTIONS
    return out


@functools.cache
def _block_index(n: int, r: int, row0: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices (n, r, 1) and (n, 1, 3) placing n per-foot (r, 3) blocks on the force columns from row0."""
    rows = row0 + np.arange(n * r).reshape(n, r, 1)
    cols = 4 + 3 * np.arange(n).reshape(n, 1, 1) + np.arange(3).reshape(1, 1, 3)
    rows.flags.writeable = cols.flags.writeable = False
    return rows, cols


def program_values(
    structure: ProgramStructure,
    feet: FloatArray,
    normals: FloatArray,
    mu: FloatArray,
    jac: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    bias: FloatArray,
    force: FloatArray,
    moment: FloatArray,
    w_max: float,
    extent: float,
) -> tuple[FloatArray, FloatArray]:
    """``A``'s values on ``structure`` (N, nnz) and ``b`` (N, rows) of N states' programs.

    The stance feet's arrays: feet, unit normals (N, n, 3), mu (N,), jac (N, n, 3, k), torque bounds
    lo, hi and bias torques (N, n, k) (all finite), force and moment (N, 3) of the gravito-inertial
    wrench. Equal, entry by entry, to ``region_program.build_program`` of each state (whose ``A`` omits the
    entries that happen to be zero).

    Raises:
        ValueError: a torque bound that is not finite (its row would be dropped: another structure).
    """
    n_states, n, k = jac.shape[0], structure.n_stance, structure.n_joints
    tau_blocks, tau_b = torque_blocks(jac, lo, hi, bias)
    if not np.isfinite(tau_b).all():
        raise ValueError("program_values needs finite torque bounds; solve such states with solve_region")
    a = np.zeros((n_states, structure.n_rows, structure.n_var))
    b = np.zeros((n_states, structure.n_rows))  # the friction rows' right-hand side stays 0
    fill_equilibrium(a, b, feet, force, moment)
    a[:, N_EQUILIBRIUM_ROWS:ROW_TORQUE, 0:4] = _box_rows()
    b[:, N_EQUILIBRIUM_ROWS : N_EQUILIBRIUM_ROWS + 4] = extent
    b[:, N_EQUILIBRIUM_ROWS + 4 : ROW_TORQUE] = n * w_max
    row_friction = _row_friction(n, k)
    rows_tau, cols_tau = _block_index(n, 2 * k, ROW_TORQUE)
    a[:, rows_tau, cols_tau] = tau_blocks
    b[:, ROW_TORQUE:row_friction] = tau_b.reshape(n_states, -1)
    rows_f, cols_f = _block_index(n, _friction_rows(structure.n_faces), row_friction)
    a[:, rows_f, cols_f] = friction_blocks(normals, mu, structure.n_faces)
    return a[:, structure.rows, structure.cols], b


class ReusedRegionSolver(SupportOracle):
    """One Clarabel solver per :class:`ProgramStructure`, re-used for every state of that structure.

    Set up once from a *reference* program of the structure (its values fix Clarabel's equilibration,
    which data updates keep); :meth:`load` then replaces the program's data (``A``'s values and ``b``)
    without a new set-up, and the instance is the support oracle of that state for
    :func:`~margin_rl.stability.geometry.projection.iterative_projection`, exactly as ``solve_region``'s (whose
    solving and robust retry it inherits): maximise ``a^T c`` by updating the objective only, and
    retry a failed direction once with a robust solver set up from the current data. Every state is
    solved through the same update, so a state's result does not depend on the states loaded before
    it (nor on how a data set is cut into batches). Counters are per loaded state.
    """

    def __init__(self, structure: ProgramStructure, reference_values: FloatArray, reference_b: FloatArray) -> None:
        self.structure = structure
        self._cones = structure.cones()
        self._p = sp.csc_matrix((structure.n_var, structure.n_var))
        self._q = np.zeros(structure.n_var)
        self._values, self._b = reference_values, reference_b
        a = structure.matrix(reference_values)
        self._fast = clarabel.DefaultSolver(self._p, self._q, a, reference_b, self._cones, FAST_SETTINGS)
        self._robust: Any = None
        self.n_solves = self.n_retries = self.n_failed = 0

    def load(self, values: FloatArray, b: FloatArray) -> None:
        """Make the program of one state current: (nnz,) values of ``A`` and (rows,) ``b``."""
        self._values, self._b = values, b
        self._robust = None
        self.n_solves = self.n_retries = self.n_failed = 0
        self._fast.update(A=values, b=b)

    def _new_robust_solver(self) -> Any:
        a = self.structure.matrix(self._values)
        return clarabel.DefaultSolver(self._p, self._q, a, self._b, self._cones, ROBUST_SETTINGS)
