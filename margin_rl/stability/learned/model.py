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
* ``model.network``: the layers with the normalisation folded in (:class:`~margin_rl.network.DenseNetwork`), the
  one implementation behind the numpy value and gradient, the torch module and the planner's CasADi expression
  (:func:`margin_rl.planning.mlp.margin_function`);
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

from margin_rl.network import read_arrays, verify_sha256
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


class LearnedMargin:
    """The learned stability margin of one robot (see the module docstring)."""

    def __init__(self, weights: MarginWeights, card: dict[str, object] | None = None, name: str = "") -> None:
        weights.validate(name or "weights")
        self.params = weights
        self.card = dict(card or {})
        self.name = name
        self.architecture = weights.architecture
        self._constants = weights.constants if weights.architecture == "physics" else None
        # The normalisation folded into the layers, once: float64 for single states and gradients, float32
        # for batched values; the torch and CasADi forms come from the same folded weights.
        self.network = weights.network()

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
        verify_sha256(npz, card.get("sha256"), WeightsError)
        if card.get("format") != WEIGHTS_FORMAT:
            raise WeightsError(f"{npz}: weights format {card.get('format')!r}, this package reads {WEIGHTS_FORMAT}")
        if card.get("lambda_layout") != layout_signature():
            raise WeightsError(f"{npz}: trained for another lambda layout ({card.get('lambda_layout')!r})")
        try:
            arrays = read_arrays(npz)
        except (ValueError, OSError) as exc:
            raise WeightsError(f"{npz}: unreadable weights ({exc})") from exc
        return cls(MarginWeights.from_arrays(arrays, str(npz)), card, name=str(card.get("robot", npz.stem)))

    # ------------------------------------------------------------------ inference (numpy)
    def _network_input(
        self, x: np.ndarray, jacobian: bool = False
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(network input, proxy term, d features / d lambda): lambda itself for the paper architecture; for
        physics weights the batch [lambda, features] (N, 47 + N_FEATURES), proxy_weight x proxy (N,) and, with
        ``jacobian``, the features' Jacobian (N, N_FEATURES, 47)."""
        if x.ndim not in (1, 2):
            raise ValueError(f"lam must have shape (47,) or (N, 47), got {x.shape}")
        if self._constants is None:
            return x, None, None
        batch = x if x.ndim == 2 else x[None, :]
        if jacobian:
            features, d_features = physics_features_and_jacobian(batch, self._constants)
        else:
            features, d_features = physics_features(batch, self._constants), None
        proxy = self.params.proxy_weight * features[:, PROXY_INDEX]
        return np.concatenate([batch, features], axis=1), proxy, d_features

    def __call__(self, lam: np.ndarray) -> float | np.ndarray:
        """m_l [m] of one lambda (47,) -> float (float64), or of a batch (N, 47) -> (N,) (float32 layers)."""
        x = check_lambda(lam)
        z, proxy, _ = self._network_input(x)
        if x.ndim == 1:
            if proxy is None:
                return float(self.network(z)[0])
            return float(self.network(z[0])[0] + proxy[0])
        value = self.network.value_float32(z)[:, 0].astype(np.float64)
        return value if proxy is None else value + proxy

    def value_and_grad(self, lam: np.ndarray) -> tuple[float | np.ndarray, np.ndarray]:
        """(m_l, dm_l/dlambda) by exact backpropagation: (47,) -> (float, (47,)), (N, 47) -> ((N,), (N, 47)).

        Physics weights chain the features' exact Jacobian: dm/dlam = dm/dz_lam + dm/dz_f J_f + proxy_weight
        J_proxy.
        """
        x = check_lambda(lam)
        z, proxy, d_features = self._network_input(x, jacobian=True)
        value, jacobian = self.network.value_and_grad(z)
        if proxy is None:
            if x.ndim == 1:
                return float(value[0]), jacobian[0]
            return value[:, 0], jacobian[:, 0]
        g = jacobian[:, 0]
        value = value[:, 0] + proxy
        grad = g[:, :LAMBDA_DIM] + np.einsum("nf,nfj->nj", g[:, LAMBDA_DIM:], d_features)
        grad += self.params.proxy_weight * d_features[:, PROXY_INDEX]
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
        """The network as a ``torch.nn.Module`` mapping raw lambda (..., 47) to m_l (...) [m], in ``dtype``
        (float32 by default): :class:`~margin_rl.stability.learned.margin_mlp.MarginModule` on the folded
        weights of :attr:`network` (with the physics features and proxy for physics weights)."""
        # Lazy: torch is heavy, and the numpy paths (environments, dataset workers) never need it.
        from margin_rl.stability.learned.margin_mlp import MarginModule

        return MarginModule(self.network, dtype, self._constants, self.params.proxy_weight)

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
