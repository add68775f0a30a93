"""Dense feed-forward networks, robot-agnostic: one set of folded weights, three forms (numpy, torch, CasADi).

A trained network is stored as its dense layers plus the affine normalisation of its input and output
(``y = out_offset + out_scale * net((x - in_offset) / in_scale)``). :meth:`DenseNetwork.fold` folds that
normalisation into the first and last layers, once, so that every form is a plain chain::

    h_0 = x,   h_k = act(W_k h_{k-1} + b_k) (hidden layers),   y = W_L h_{L-1} + b_L

    W_1 <- W_1 / in_scale (columns),   b_1 <- b_1 - W_1 in_offset,
    W_L <- out_scale * W_L (rows),     b_L <- out_scale * b_L + out_offset

with ``act`` one of :data:`ACTIVATIONS` (``softsign(z) = z / (1 + |z|)``, ``relu(z) = max(z, 0)``).
The same folded weights give

* numpy: ``net(x)`` ((in,) -> (out,), (N, in) -> (N, out), float64), ``net.value_float32(x)`` (batches in
  float32, about twice as fast), ``net.value_and_grad(x)`` and ``net.jacobian(x)`` (exact backpropagation;
  relu'(0) = 0, as in torch and CasADi's ``fmax``), ``net.hessian(x)`` (exact, one-output networks);
* torch: ``net.torch_module(dtype)``, an ``nn.Sequential`` of ``Linear`` and activation modules;
* CasADi: ``net.casadi(x)``, an expression of a symbolic (in, n) matrix, one column per input.

For training, :func:`torch_sequential` builds the same layer stack with fresh parameters and
:func:`torch_forward` evaluates it from (weight, bias) pairs (e.g. tied parameterisations). The weights
files of the networks built on this (``.npz`` without pickles, beside a JSON model card recording their
sha256) share :func:`layer_arrays`, :func:`read_layers`, :func:`save_arrays`, :func:`read_arrays`,
:func:`verify_sha256` and :func:`write_card`. torch and CasADi are imported only by the forms that need
them.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.atomic import atomic_savez, atomic_write_text
from margin_rl.provenance import sha256_file

__all__ = [
    "ACTIVATIONS",
    "DenseNetwork",
    "input_scaling",
    "layer_arrays",
    "read_arrays",
    "read_layers",
    "save_arrays",
    "torch_forward",
    "torch_sequential",
    "verify_sha256",
    "write_card",
]

FloatArray = NDArray[np.float64]

ACTIVATIONS: tuple[str, ...] = ("softsign", "relu")
"""Hidden-layer activations: ``softsign(z) = z / (1 + |z|)`` and ``relu(z) = max(z, 0)``."""


MIN_INPUT_STD = 1e-8
"""An input column whose training standard deviation is below this is constant (e.g. flat-ground normals)."""


def input_scaling(x: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(mean, std) of each column of training inputs (N, in), in their dtype: the normalisation
    :meth:`DenseNetwork.fold` takes; a constant column's std (below :data:`MIN_INPUT_STD`) is replaced by 1, so it
    passes unscaled instead of being divided by zero."""
    x = np.asarray(x)
    std = x.std(axis=0)
    return x.mean(axis=0), np.where(std > MIN_INPUT_STD, std, 1.0)


def _check_activation(activation: str) -> str:
    if activation not in ACTIVATIONS:
        raise ValueError(f"unknown activation {activation!r}; known: {', '.join(ACTIVATIONS)}")
    return activation


class DenseNetwork:
    """A dense network with its normalisation folded in (module docstring); immutable by convention.

    ``weights[k]`` has shape (out, in) (torch's ``Linear`` convention), ``biases[k]`` (out,); both are
    kept in float64. Build one from trained weights with :meth:`fold`.

    Raises:
        ValueError: inconsistent shapes, non-finite parameters or an unknown activation.
    """

    def __init__(self, weights: Sequence[ArrayLike], biases: Sequence[ArrayLike], activation: str) -> None:
        self.activation = _check_activation(activation)
        self.weights = tuple(np.ascontiguousarray(w, dtype=np.float64) for w in weights)
        self.biases = tuple(np.asarray(b, dtype=np.float64) for b in biases)
        if not self.weights or len(self.weights) != len(self.biases):
            raise ValueError(f"need as many biases as weight matrices (>= 1), got {len(weights)} and {len(biases)}")
        for k, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            if w.ndim != 2 or b.shape != (w.shape[0],) or (k and w.shape[1] != self.weights[k - 1].shape[0]):
                raise ValueError(f"layer {k} has inconsistent shapes: W {w.shape}, b {b.shape}")
            if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                raise ValueError(f"layer {k} has non-finite parameters")
        # The float32 batch path multiplies by contiguous transposes (h @ W^T), made once here.
        self._weights32_t = tuple(np.ascontiguousarray(w.T.astype(np.float32)) for w in self.weights)
        self._biases32 = tuple(b.astype(np.float32) for b in self.biases)

    @classmethod
    def fold(
        cls,
        weights: Sequence[ArrayLike],
        biases: Sequence[ArrayLike],
        activation: str,
        *,
        in_offset: ArrayLike = 0.0,
        in_scale: ArrayLike = 1.0,
        out_offset: ArrayLike = 0.0,
        out_scale: ArrayLike = 1.0,
    ) -> DenseNetwork:
        """The network ``out_offset + out_scale * net((x - in_offset) / in_scale)`` with the affine maps
        folded into the first and last layers (scalars or per-entry vectors), in float64."""
        W = [np.asarray(w, dtype=np.float64) for w in weights]
        b = [np.asarray(x, dtype=np.float64) for x in biases]
        in_offset = np.broadcast_to(np.asarray(in_offset, dtype=np.float64), (W[0].shape[1],))
        in_scale = np.broadcast_to(np.asarray(in_scale, dtype=np.float64), (W[0].shape[1],))
        out_offset = np.broadcast_to(np.asarray(out_offset, dtype=np.float64), (W[-1].shape[0],))
        out_scale = np.broadcast_to(np.asarray(out_scale, dtype=np.float64), (W[-1].shape[0],))
        if not (np.all(in_scale != 0) and np.all(out_scale != 0)):
            raise ValueError("normalisation scales must be nonzero")
        W[0] = W[0] / in_scale[None, :]
        b[0] = b[0] - W[0] @ in_offset
        W[-1] = W[-1] * out_scale[:, None]
        b[-1] = b[-1] * out_scale + out_offset
        return cls(W, b, activation)

    # ------------------------------------------------------------------ shape
    @property
    def widths(self) -> tuple[int, ...]:
        """(in, hidden..., out)."""
        return (self.weights[0].shape[1], *(w.shape[0] for w in self.weights))

    @property
    def in_dim(self) -> int:
        return int(self.weights[0].shape[1])

    @property
    def out_dim(self) -> int:
        return int(self.weights[-1].shape[0])

    def _check(self, x: ArrayLike) -> FloatArray:
        x = np.asarray(x, dtype=np.float64)
        if x.ndim not in (1, 2) or x.shape[-1] != self.in_dim:
            raise ValueError(f"input must have shape ({self.in_dim},) or (N, {self.in_dim}), got {x.shape}")
        return x

    # ------------------------------------------------------------------ numpy
    def _activate(self, z: FloatArray) -> FloatArray:
        return z / (1.0 + np.abs(z)) if self.activation == "softsign" else np.maximum(z, 0.0)

    def _activate_with_derivative(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        if self.activation == "softsign":
            a = 1.0 + np.abs(z)
            return z / a, 1.0 / (a * a)
        return np.maximum(z, 0.0), (z > 0.0).astype(np.float64)

    def __call__(self, x: ArrayLike) -> FloatArray:
        """Output (out,) of one input (in,), or (N, out) of a batch (N, in), in float64."""
        h = self._check(x)
        hidden = zip(self.weights[:-1], self.biases[:-1], strict=True)
        if h.ndim == 1:
            for W, b in hidden:
                h = self._activate(W @ h + b)
            return self.weights[-1] @ h + self.biases[-1]
        for W, b in hidden:
            h = self._activate(h @ W.T + b)
        return h @ self.weights[-1].T + self.biases[-1]

    def value_float32(self, x: ArrayLike) -> NDArray[np.float32]:
        """Output (N, out) of a batch (N, in), computed in float32 in place (no temporaries of the batch size
        beyond one per layer)."""
        h = self._check(x)
        if h.ndim != 2:
            raise ValueError(f"value_float32 takes a batch (N, {self.in_dim}), got {h.shape}")
        h = h.astype(np.float32)
        for WT, b in zip(self._weights32_t[:-1], self._biases32[:-1], strict=True):
            h = h @ WT
            h += b
            if self.activation == "softsign":
                denominator = np.abs(h)
                denominator += 1.0
                h /= denominator
            else:
                np.maximum(h, 0.0, out=h)
        return h @ self._weights32_t[-1] + self._biases32[-1]

    def value_and_grad(self, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(output, Jacobian) by exact backpropagation: (in,) -> ((out,), (out, in)), (N, in) -> ((N, out),
        (N, out, in)), float64. One reverse sweep per output."""
        h = self._check(x)
        derivatives = []
        hidden = zip(self.weights[:-1], self.biases[:-1], strict=True)
        W_last, b_last = self.weights[-1], self.biases[-1]
        if h.ndim == 1:  # matrix-vector products: tens of microseconds, so no per-call overhead beyond them
            for W, b in hidden:
                h, d = self._activate_with_derivative(W @ h + b)
                derivatives.append(d)
            backward = list(zip(self.weights[-2::-1], derivatives[::-1], strict=True))
            value, jacobian = np.empty(self.out_dim), np.empty((self.out_dim, self.in_dim))
            for row, w in enumerate(W_last):
                g = w
                for W, d in backward:
                    g = (g * d) @ W
                jacobian[row] = g
                value[row] = w @ h + b_last[row]
            return value, jacobian
        for W, b in hidden:
            h, d = self._activate_with_derivative(h @ W.T + b)
            derivatives.append(d)
        value = h @ W_last.T + b_last
        rows = []
        for w in W_last:
            g = np.broadcast_to(w, (h.shape[0], w.shape[0]))
            for W, d in zip(reversed(self.weights[:-1]), reversed(derivatives), strict=True):
                g = (g * d) @ W
            rows.append(g)
        return value, rows[0][:, None, :] if len(rows) == 1 else np.stack(rows, axis=1)

    def jacobian(self, x: ArrayLike) -> FloatArray:
        """d output / d input: (out, in) at one input, (N, out, in) for a batch."""
        return self.value_and_grad(x)[1]

    def hessian(self, x: ArrayLike) -> FloatArray:
        """d^2 output / d input^2 of a one-output network, exact: (in,) -> (in, in), (N, in) -> (N, in, in).

        With z_l = W_l h_(l-1) + b_l, h_l = act(z_l), A_l = dz_l/dx (A_1 = W_1, A_(l+1) = W_(l+1) diag(act'(z_l))
        A_l) and a_l = dy/dh_l (the backpropagated adjoint), the affine layers add no curvature, so
        H = sum_l A_l^T diag(act''(z_l) a_l) A_l. softsign''(z) = -2 sign(z) / (1 + |z|)^3; relu'' = 0 (almost
        everywhere: a relu network's Hessian is zero).

        Raises:
            ValueError: a network with more than one output, or an input of the wrong shape.
        """
        if self.out_dim != 1:
            raise ValueError(f"hessian() takes a network with one output, this one has {self.out_dim}")
        x = self._check(x)
        single = x.ndim == 1
        h = x[None] if single else x
        first, second = [], []
        for W, b in zip(self.weights[:-1], self.biases[:-1], strict=True):
            z = h @ W.T + b
            h, d1 = self._activate_with_derivative(z)
            first.append(d1)
            second.append(-2.0 * np.sign(z) * d1 * np.sqrt(d1) if self.activation == "softsign" else np.zeros_like(z))
        adjoints = []
        adjoint = np.broadcast_to(self.weights[-1][0], (h.shape[0], self.weights[-1].shape[1]))
        for W, d1 in zip(reversed(self.weights[:-1]), reversed(first), strict=True):
            adjoints.append(adjoint)
            adjoint = (adjoint * d1) @ W
        adjoints.reverse()
        A = np.broadcast_to(self.weights[0], (h.shape[0], *self.weights[0].shape))
        hessian = np.zeros((h.shape[0], self.in_dim, self.in_dim))
        for layer, (d2, a) in enumerate(zip(second, adjoints, strict=True)):
            if layer:
                A = np.matmul(self.weights[layer], first[layer - 1][:, :, None] * A)
            hessian += np.matmul(np.swapaxes(A, 1, 2), (d2 * a)[:, :, None] * A)
        return hessian[0] if single else hessian

    # ------------------------------------------------------------------ torch
    def torch_module(self, dtype: Any = None) -> Any:
        """The network as a ``torch.nn.Sequential`` (inputs (..., in) -> (..., out)), in ``dtype`` (float32
        by default). Its parameters are the folded weights; gradients flow to the input."""
        import torch

        dtype = dtype or torch.float32
        module = torch_sequential(self.widths, self.activation, initialise=False, dtype=dtype)
        linear = [m for m in module if isinstance(m, torch.nn.Linear)]
        with torch.no_grad():
            for layer, w, b in zip(linear, self.weights, self.biases, strict=True):
                layer.weight.copy_(torch.as_tensor(w, dtype=dtype))
                layer.bias.copy_(torch.as_tensor(b, dtype=dtype))
        return module

    # ------------------------------------------------------------------ CasADi
    def casadi(self, x: Any) -> Any:
        """The network on a symbolic (in, n) CasADi matrix (SX or MX): (out, n), one column per input.

        Constant weight matrices and dense products per layer, so a batch of columns is one product per
        layer and CasADi's derivatives are exact backpropagation.
        """
        import casadi as ca

        n = x.size2()

        def affine(W: FloatArray, b: FloatArray, h: Any) -> Any:
            return ca.mtimes(ca.DM(W), h) + ca.repmat(ca.DM(b), 1, n)

        h = x
        for W, b in zip(self.weights[:-1], self.biases[:-1], strict=True):
            z = affine(W, b, h)
            h = z / (1 + ca.fabs(z)) if self.activation == "softsign" else ca.fmax(z, 0)
        return affine(self.weights[-1], self.biases[-1], h)


# ---------------------------------------------------------------------- torch pieces for training
def torch_sequential(widths: Sequence[int], activation: str, *, initialise: bool = True, dtype: Any = None) -> Any:
    """``nn.Sequential(Linear, act, ..., Linear)`` for layer ``widths`` (in, hidden..., out).

    ``initialise``: torch's default initialisation from its global seed (for training); False leaves the
    parameters uninitialised and the global random state untouched (for copying weights in).
    """
    from torch import nn

    module = {"softsign": nn.Softsign, "relu": nn.ReLU}[_check_activation(activation)]
    layers: list[nn.Module] = []
    for k in range(len(widths) - 1):
        if initialise:
            layers.append(nn.Linear(widths[k], widths[k + 1], dtype=dtype))
        else:
            layers.append(nn.utils.skip_init(nn.Linear, widths[k], widths[k + 1], dtype=dtype))
        if k < len(widths) - 2:
            layers.append(module())
    return nn.Sequential(*layers)


def torch_forward(x: Any, layers: Sequence[tuple[Any, Any]], activation: str) -> Any:
    """The network of (weight, bias) tensors on ``x`` (..., in) -> (..., out), differentiable in both."""
    from torch.nn import functional

    act = {"softsign": functional.softsign, "relu": functional.relu}[_check_activation(activation)]
    h = x
    for weight, bias in layers[:-1]:
        h = act(functional.linear(h, weight, bias))
    weight, bias = layers[-1]
    return functional.linear(h, weight, bias)


# ---------------------------------------------------------------------- weights files and model cards
def layer_arrays(weights: Sequence[ArrayLike], biases: Sequence[ArrayLike]) -> dict[str, NDArray[np.float32]]:
    """``{"W0": ..., "b0": ..., "W1": ...}`` in float32, the layers' keys in a weights file."""
    out = {f"W{k}": np.asarray(w, dtype=np.float32) for k, w in enumerate(weights)}
    return out | {f"b{k}": np.asarray(b, dtype=np.float32) for k, b in enumerate(biases)}


def read_layers(
    arrays: Mapping[str, ArrayLike], n_layers: int
) -> tuple[tuple[FloatArray, ...], tuple[FloatArray, ...]]:
    """(weights, biases) in float64 from the keys of :func:`layer_arrays` (KeyError names a missing one)."""
    weights = tuple(np.asarray(arrays[f"W{k}"], dtype=np.float64) for k in range(n_layers))
    return weights, tuple(np.asarray(arrays[f"b{k}"], dtype=np.float64) for k in range(n_layers))


def save_arrays(path: str | Path, arrays: Mapping[str, ArrayLike]) -> str:
    """Write ``arrays`` to the ``.npz`` file ``path`` atomically, without pickles; returns its sha256 (for
    the model card)."""
    atomic_savez(path, **arrays)
    return sha256_file(path)


def verify_sha256(path: str | Path, recorded: object, error: type[Exception] = ValueError) -> None:
    """Raise ``error`` unless the file's sha256 is the one its card recorded."""
    digest = sha256_file(path)
    if recorded != digest:
        raise error(
            f"{path}: checksum mismatch (card {recorded!r}, file {digest!r}): "
            "the file is corrupted or does not belong to this card"
        )


def read_arrays(path: str | Path) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file, read without allowing pickles."""
    with np.load(path, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def write_card(path: str | Path, card: Mapping[str, Any]) -> None:
    """A model card as indented JSON, atomically."""
    atomic_write_text(path, json.dumps(card, indent=2) + "\n")
