"""Learned stability margin m_l = MLP(lambda) of seed 000 §IV: fast value, gradient and torch module.

The network is the paper's: 47 - 256 - 128 - 128 - 1, softsign activations, with input normalisation
(fitted on the training split) and output scaling stored with the weights, so every entry point takes
raw lambda (:mod:`margin_rl.stability.analytic.lambda_state`) and returns metres::

    m_l(lam) = s_y * MLP((lam - mu_x) / s_x) + mu_y,     softsign(z) = z / (1 + |z|)

``LearnedMargin.load("anymal_c")`` reads the bundled weights (``weights/<robot>.npz``, never a
pickle) and checks them against their model card (``weights/<robot>.json``: sha256, layout, shapes); the
weight and architecture types are in :mod:`~margin_rl.stability.learned.mlp_weights` (shared with the torch module
:mod:`~margin_rl.stability.learned.margin_mlp`, so that neither imports the other) and re-exported here (``name as
name`` imports), where users import them.

* ``model(lam)``: one lambda (47,) -> float, or a batch (N, 47) -> (N,), in numpy (microseconds);
* ``model.grad(lam)``: dm/dlambda by exact backpropagation in numpy, (47,) or (N, 47);
* ``model.value_and_grad(lam)``: both in one pass;
* ``model.torch_module()``: the same network as a ``torch.nn.Module`` for differentiable use;
* ``model.export_onnx(path)``: ONNX for C++ users;
* ``model.out_of_distribution(lam)``: True where lambda leaves the per-field ranges seen in training
  (``model.outside_ranges(lam)``: which entries).

Weights with ``architecture="physics"`` (``model.architecture``) feed the same layers with [lambda, the
physics features of :mod:`~margin_rl.stability.learned.features`] and add ``proxy_weight`` x the analytic proxy;
every entry point above still takes raw lambda, and the gradient chains the features' exact Jacobian.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from margin_rl.provenance import sha256_file
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, LAMBDA_FIELDS, check_lambda
from margin_rl.stability.learned.features import PROXY_INDEX, physics_features, physics_features_and_jacobian
from margin_rl.stability.learned.mlp_weights import ARCHITECTURE as ARCHITECTURE
from margin_rl.stability.learned.mlp_weights import (
    WEIGHTS_FORMAT,
    MarginWeights,
    WeightsError,
    layout_signature,
    weights_path,
)
from margin_rl.stability.learned.mlp_weights import bundled_robots as bundled_robots
from margin_rl.stability.learned.mlp_weights import save_weights as save_weights
from margin_rl.stability.learned.mlp_weights import weights_dir as weights_dir

_CONTACTS = slice(sum(f.size for f in LAMBDA_FIELDS[:8]), sum(f.size for f in LAMBDA_FIELDS[:9]))


def _softsign(z: np.ndarray) -> np.ndarray:
    return z / (1.0 + np.abs(z))


class LearnedMargin:
    """The learned stability margin of one robot (see the module docstring)."""

    def __init__(self, weights: MarginWeights, card: dict[str, object] | None = None, name: str = "") -> None:
        weights.validate(name or "weights")
        self.params = weights
        self.card = dict(card or {})
        self.name = name
        self.architecture = weights.architecture
        self._constants = weights.constants if weights.architecture == "physics" else None
        # Fold the input normalisation into the first layer and the output scaling into the last:
        # one matmul chain at inference, in float64 for the single-state path and float32 in batches.
        W = [w.copy() for w in weights.weights]
        b = [x.copy() for x in weights.biases]
        W[0] = weights.weights[0] / weights.input_std[None, :]
        b[0] = weights.biases[0] - W[0] @ weights.input_mean
        W[-1] = weights.weights[-1] * weights.output_std
        b[-1] = weights.biases[-1] * weights.output_std + weights.output_mean
        self._W64 = [np.ascontiguousarray(w) for w in W]
        self._b64 = b
        self._W32T = [np.ascontiguousarray(w.T.astype(np.float32)) for w in W]
        self._b32 = [x.astype(np.float32) for x in b]

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, robot_or_path: str | Path) -> LearnedMargin:
        """Bundled weights of a robot (``"anymal_b"``, ``"anymal_c"``) or a ``.npz`` path with its card.

        Raises:
            WeightsError: unknown robot (lists the bundled ones), missing card, checksum mismatch
                (corrupted file), other lambda layout or format.
        """
        npz = weights_path(robot_or_path)
        card_path = npz.with_suffix(".json")
        if not npz.is_file():
            raise WeightsError(f"weights file not found: {npz}")
        if not card_path.is_file():
            raise WeightsError(f"model card not found next to the weights: {card_path}")
        try:
            card = json.loads(card_path.read_text())
        except json.JSONDecodeError as exc:
            raise WeightsError(f"{card_path}: malformed model card ({exc})") from exc
        digest = sha256_file(npz)
        if card.get("sha256") != digest:
            raise WeightsError(
                f"{npz}: checksum mismatch (card {card.get('sha256')!r}, file {digest!r}): "
                "the file is corrupted or does not belong to this card"
            )
        if card.get("format") != WEIGHTS_FORMAT:
            raise WeightsError(f"{npz}: weights format {card.get('format')!r}, this package reads {WEIGHTS_FORMAT}")
        if card.get("lambda_layout") != layout_signature():
            raise WeightsError(f"{npz}: trained for another lambda layout ({card.get('lambda_layout')!r})")
        try:
            with np.load(npz, allow_pickle=False) as data:
                arrays = {k: data[k] for k in data.files}
        except (ValueError, OSError) as exc:
            raise WeightsError(f"{npz}: unreadable weights ({exc})") from exc
        return cls(MarginWeights.from_arrays(arrays, str(npz)), card, name=str(card.get("robot", npz.stem)))

    # ------------------------------------------------------------------ inference (numpy)
    def __call__(self, lam: np.ndarray) -> float | np.ndarray:
        """m_l [m] of one lambda (47,) -> float, or of a batch (N, 47) -> (N,)."""
        x = check_lambda(lam)
        if self._constants is not None:
            return self._physics_value(x)
        if x.ndim == 1:
            h = x
            for W, b in zip(self._W64[:-1], self._b64[:-1], strict=True):
                h = _softsign(W @ h + b)
            return float((self._W64[-1] @ h + self._b64[-1])[0])
        if x.ndim != 2:
            raise ValueError(f"lam must have shape (47,) or (N, 47), got {x.shape}")
        h = x.astype(np.float32)
        for WT, b in zip(self._W32T[:-1], self._b32[:-1], strict=True):
            h = h @ WT
            h += b
            # softsign in place: h / (1 + |h|) without temporaries of the batch size.
            denominator = np.abs(h)
            denominator += 1.0
            h /= denominator
        return (h @ self._W32T[-1] + self._b32[-1])[:, 0].astype(np.float64)

    def value_and_grad(self, lam: np.ndarray) -> tuple[float | np.ndarray, np.ndarray]:
        """(m_l, dm_l/dlambda) by exact backpropagation: (47,) -> (float, (47,)), (N, 47) -> ((N,), (N, 47))."""
        x = check_lambda(lam)
        if self._constants is not None:
            return self._physics_value_and_grad(x)
        if x.ndim == 1:
            return self._value_and_grad_one(x)
        h = x
        if h.ndim != 2:
            raise ValueError(f"lam must have shape (47,) or (N, 47), got {x.shape}")
        return self._mlp_value_and_grad(h)

    def _mlp_value_and_grad(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The network on a batch of (raw) inputs (N, in) and d output / d input (N, in), float64."""
        derivatives = []
        for W, b in zip(self._W64[:-1], self._b64[:-1], strict=True):
            z = h @ W.T + b
            a = 1.0 + np.abs(z)
            derivatives.append(1.0 / (a * a))  # softsign'(z)
            h = z / a
        value = (h @ self._W64[-1].T + self._b64[-1])[:, 0]
        g = np.broadcast_to(self._W64[-1], (h.shape[0], self._W64[-1].shape[1]))
        for W, d in zip(reversed(self._W64[:-1]), reversed(derivatives), strict=True):
            g = (g * d) @ W
        return value, g

    def _value_and_grad_one(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """Matrix-vector version for one lambda (no batch broadcasting: tens of microseconds)."""
        h = x
        derivatives = []
        for W, b in zip(self._W64[:-1], self._b64[:-1], strict=True):
            z = W @ h + b
            a = 1.0 + np.abs(z)
            h = z / a
            derivatives.append(1.0 / (a * a))
        w_last = self._W64[-1][0]
        g = w_last
        for W, d in zip(reversed(self._W64[:-1]), reversed(derivatives), strict=True):
            g = (g * d) @ W
        return float(w_last @ h + self._b64[-1][0]), g

    # ------------------------------------------------------------------ the physics architecture
    def _physics_value(self, x: np.ndarray) -> float | np.ndarray:
        """[lambda, features] through the layers (float64 for one lambda, float32 in batches) + the proxy."""
        if x.ndim not in (1, 2):
            raise ValueError(f"lam must have shape (47,) or (N, 47), got {x.shape}")
        batch = x if x.ndim == 2 else x[None, :]
        features = physics_features(batch, self._constants)
        z = np.concatenate([batch, features], axis=1)
        proxy = self.params.proxy_weight * features[:, PROXY_INDEX]
        if x.ndim == 1:
            h = z[0]
            for W, b in zip(self._W64[:-1], self._b64[:-1], strict=True):
                h = _softsign(W @ h + b)
            return float((self._W64[-1] @ h + self._b64[-1])[0] + proxy[0])
        h = z.astype(np.float32)
        for WT, b in zip(self._W32T[:-1], self._b32[:-1], strict=True):
            h = _softsign(h @ WT + b)
        return (h @ self._W32T[-1] + self._b32[-1])[:, 0].astype(np.float64) + proxy

    def _physics_value_and_grad(self, x: np.ndarray) -> tuple[float | np.ndarray, np.ndarray]:
        """Chain rule through the features: dm/dlam = dm/dz_lam + dm/dz_f J_f + proxy_weight J_proxy."""
        if x.ndim not in (1, 2):
            raise ValueError(f"lam must have shape (47,) or (N, 47), got {x.shape}")
        batch = x if x.ndim == 2 else x[None, :]
        features, jacobian = physics_features_and_jacobian(batch, self._constants)
        value, g = self._mlp_value_and_grad(np.concatenate([batch, features], axis=1))
        w = self.params.proxy_weight
        value = value + w * features[:, PROXY_INDEX]
        grad = g[:, :LAMBDA_DIM] + np.einsum("nf,nfj->nj", g[:, LAMBDA_DIM:], jacobian)
        grad += w * jacobian[:, PROXY_INDEX]
        if x.ndim == 1:
            return float(value[0]), grad[0]
        return value, grad

    def grad(self, lam: np.ndarray) -> np.ndarray:
        """dm_l/dlambda [m per lambda unit]: (47,) or (N, 47)."""
        return self.value_and_grad(lam)[1]

    def outside_ranges(self, lam: np.ndarray) -> np.ndarray:
        """Per entry: True where lambda (47,) or (N, 47) is outside the range seen in the training split.

        Contact flags are binary and always in range. The ranges are widened by 1e-6 of their width (at
        least 1e-7): they were stored from float32 samples, so a bound reached exactly, like the unit z of a
        flat-ground normal, reads 1 - 6e-8 and would otherwise flag every state on flat ground.
        """
        x = check_lambda(lam)
        slack = np.maximum(1e-6 * (self.params.lam_high - self.params.lam_low), 1e-7)
        outside = (x < self.params.lam_low - slack) | (x > self.params.lam_high + slack)
        outside[..., _CONTACTS] = False
        return outside

    def out_of_distribution(self, lam: np.ndarray) -> bool | np.ndarray:
        """True where some entry of lambda is outside the range seen in the training split
        (:meth:`outside_ranges`); the network's error grows quickly there (seed 000 Fig. 3)."""
        result = self.outside_ranges(lam).any(axis=-1)
        return bool(result) if result.ndim == 0 else result

    # ------------------------------------------------------------------ torch and ONNX
    def torch_module(self, dtype: object = None):
        """The network as a ``torch.nn.Module`` mapping raw lambda (..., 47) to m_l (...) [m]
        (:class:`~margin_rl.stability.learned.margin_mlp.MarginMLP`, or ``PhysicsMarginMLP`` for physics weights)."""
        # Lazy: torch is heavy, and the numpy paths (environments, dataset workers) never need it.
        from margin_rl.stability.learned.margin_mlp import MarginMLP

        return MarginMLP.from_weights(self.params, dtype=dtype)

    def export_onnx(self, path: str | Path) -> Path:
        """Export the network (raw lambda (N, 47) -> m_l (N,)) to ONNX, opset 17."""
        import torch  # lazy, as in torch_module

        module = self.torch_module(torch.float32).eval()
        path = Path(path)
        example = torch.zeros(1, LAMBDA_DIM, dtype=torch.float32)
        with warnings.catch_warnings():
            # The physics features' candidate tables are constants: the tracer's warning about them is moot.
            warnings.filterwarnings("ignore", category=torch.jit.TracerWarning)
            torch.onnx.export(
                module,
                (example,),
                str(path),
                input_names=["lam"],
                output_names=["margin"],
                dynamic_axes={"lam": {0: "batch"}, "margin": {0: "batch"}},
                opset_version=17,
                dynamo=False,
            )
        return path
