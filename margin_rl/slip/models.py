r"""Small MLP approximations of the return map :math:`P(s, a)` and failure margin :math:`M(s, a)`.

Both networks map :math:`z = [y, \dot x, \alpha, \Delta L]` through two hidden layers of 64
ReLU units (paper §V-A):

.. math::
    \hat z = (z - c_{in}) / r_{in}, \quad
    h_1 = \mathrm{relu}(W_0 \hat z + b_0), \quad h_2 = \mathrm{relu}(W_1 h_1 + b_1), \quad
    f(z) = c_{out} + r_{out} \odot (W_2 h_2 + b_2),

with fixed input normalisation to the eq. (13) box (:math:`c_{in}` its centre,
:math:`r_{in}` its half-widths) and output de-normalisation from the training targets.
:math:`P` outputs ``[dx, y1, xdot1]`` and :math:`M` outputs the scalar margin.

Weights are bundled as ``.npz`` (no pickle) next to a JSON card that records the SHA-256 of
each file; :func:`load_bundle` refuses files whose checksum does not match.  The same
weights evaluate in numpy (:meth:`MLP.__call__`, :meth:`MLP.jacobian`) and symbolically in
CasADi (:meth:`MLP.casadi`, for the planner's exact derivatives); training uses the PyTorch
twin in :mod:`margin_rl.slip.train`, so this module does not import torch.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.provenance import sha256_file
from margin_rl.slip.margin import BOX_HIGH, BOX_LOW

__all__ = [
    "BUNDLE_DIR",
    "MLP",
    "Bundle",
    "load_bundle",
]

FloatArray = NDArray[np.float64]

#: Where the trained weights ship inside the package.
BUNDLE_DIR = Path(__file__).resolve().parent / "weights"
_KEYS = ("W0", "b0", "W1", "b1", "W2", "b2", "in_offset", "in_scale", "out_offset", "out_scale")


def box_normalisation() -> tuple[FloatArray, FloatArray]:
    """Input offset and scale mapping the eq. (13) box to :math:`[-1, 1]^4`."""
    return 0.5 * (BOX_LOW + BOX_HIGH), 0.5 * (BOX_HIGH - BOX_LOW)


@dataclass(frozen=True)
class MLP:
    """A 2-hidden-layer ReLU network with fixed affine input/output normalisation.

    ``weights[i]`` has shape ``(out, in)`` (PyTorch's ``Linear`` convention).
    """

    weights: tuple[FloatArray, FloatArray, FloatArray]
    biases: tuple[FloatArray, FloatArray, FloatArray]
    in_offset: FloatArray
    in_scale: FloatArray
    out_offset: FloatArray
    out_scale: FloatArray

    def __post_init__(self) -> None:
        dims = [self.weights[0].shape[1]] + [w.shape[0] for w in self.weights]
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            if w.ndim != 2 or w.shape[1] != dims[i] or b.shape != (w.shape[0],):
                raise ValueError(f"layer {i} has inconsistent shapes: W {w.shape}, b {b.shape}")
        if self.in_offset.shape != (dims[0],) or self.in_scale.shape != (dims[0],):
            raise ValueError("in_offset/in_scale must match the input dimension")
        if self.out_offset.shape != (dims[-1],) or self.out_scale.shape != (dims[-1],):
            raise ValueError("out_offset/out_scale must match the output dimension")

    @property
    def in_dim(self) -> int:
        return int(self.weights[0].shape[1])

    @property
    def out_dim(self) -> int:
        return int(self.weights[-1].shape[0])

    # -------------------------------------------------------------------- numpy

    def __call__(self, z: ArrayLike) -> FloatArray:
        """Evaluate on ``z`` of shape ``(n, in_dim)`` or ``(in_dim,)``."""
        x = (np.asarray(z, dtype=float) - self.in_offset) / self.in_scale
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = x @ w.T + b
            if i < 2:
                x = np.maximum(x, 0.0)
        return self.out_offset + self.out_scale * x

    def jacobian(self, z: ArrayLike) -> FloatArray:
        """Exact Jacobian :math:`\\partial f / \\partial z` at one point, shape ``(out, in)``.

        ReLU's derivative is taken as 0 at 0 (as PyTorch and CasADi's ``fmax`` do).
        """
        x = (np.asarray(z, dtype=float).reshape(-1) - self.in_offset) / self.in_scale
        jac = np.diag(1.0 / self.in_scale)
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = w @ x + b
            jac = w @ jac
            if i < 2:
                active = x > 0.0
                x = np.where(active, x, 0.0)
                jac = jac * active[:, None]
        return self.out_scale[:, None] * jac

    # -------------------------------------------------------------------- casadi

    def casadi(self, z: Any) -> Any:
        """The same function as a CasADi expression of the column vector ``z`` (SX or MX)."""
        import casadi as ca

        x = (z - ca.DM(self.in_offset)) / ca.DM(self.in_scale)
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = ca.mtimes(ca.DM(w), x) + ca.DM(b)
            if i < 2:
                x = ca.fmax(x, 0.0)
        return ca.DM(self.out_offset) + ca.DM(self.out_scale) * x

    # -------------------------------------------------------------------- files

    def arrays(self) -> dict[str, FloatArray]:
        """Plain arrays for :func:`numpy.savez`."""
        out = {f"W{i}": w for i, w in enumerate(self.weights)}
        out.update({f"b{i}": b for i, b in enumerate(self.biases)})
        out.update(
            in_offset=self.in_offset, in_scale=self.in_scale, out_offset=self.out_offset, out_scale=self.out_scale
        )
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, ArrayLike]) -> MLP:
        missing = [k for k in _KEYS if k not in arrays]
        if missing:
            raise ValueError(f"weight arrays lack {missing}")

        def get(k: str) -> FloatArray:
            return np.asarray(arrays[k], dtype=float)

        return cls(
            weights=(get("W0"), get("W1"), get("W2")),
            biases=(get("b0"), get("b1"), get("b2")),
            in_offset=get("in_offset"),
            in_scale=get("in_scale"),
            out_offset=get("out_offset"),
            out_scale=get("out_scale"),
        )

    @classmethod
    def load(cls, path: Path | str) -> MLP:
        with np.load(Path(path), allow_pickle=False) as data:
            return cls.from_arrays({k: data[k] for k in data.files})


@dataclass(frozen=True)
class Bundle:
    """Trained return map ``P``, margin ``M`` and their model card."""

    return_map: MLP
    margin: MLP
    card: dict[str, Any]


def load_bundle(directory: Path | str = BUNDLE_DIR) -> Bundle:
    """Load ``card.json`` and the two ``.npz`` files it names, verifying their SHA-256.

    Raises
    ------
    FileNotFoundError
        If the card or a weight file is missing.
    ValueError
        If a checksum does not match the card.
    """
    root = Path(directory)
    card = json.loads((root / "card.json").read_text())
    nets: dict[str, MLP] = {}
    for role in ("return_map", "margin"):
        entry = card["files"][role]
        path = root / entry["file"]
        digest = sha256_file(path)
        if digest != entry["sha256"]:
            raise ValueError(f"checksum mismatch for {path}: card says {entry['sha256']}, file is {digest}")
        nets[role] = MLP.load(path)
    return Bundle(return_map=nets["return_map"], margin=nets["margin"], card=card)
