"""The margin MLP as torch modules: :class:`MarginMLP` to train, :class:`MarginModule` to use trained weights.

:class:`MarginModule` (``LearnedMargin.torch_module()``) evaluates the folded weights of
:class:`~margin_rl.network.DenseNetwork`, the one implementation the numpy inference and the planner's CasADi
expression use too. :class:`MarginMLP` holds the trainable parameters in normalised units, evaluated by
:func:`margin_rl.network.torch_forward`; ``to_weights`` saves them as :class:`MarginWeights`.

Two parameterisations of the same 47-256-128-128-1 softsign network:

* plain: every weight free (the paper's network);
* ``mirror_tied``: the weights are tied so that the network is *exactly* invariant under the sagittal
  mirror of lambda (:func:`~margin_rl.stability.analytic.lambda_state.mirror_lambda`), a symmetry of the analytic
  margin of a left-right symmetric robot. The hidden units come in mirror pairs (first half, second
  half of each layer) and, with Q the mirror as a signed permutation of the normalised input and
  S the swap of the two halves of a hidden layer,

      layer 1:      W_1 = [U; U Q],          b_1 = [c; c]        so  W_1 Q x + b_1 = S (W_1 x + b_1)
      layers 2, 3:  W_k = [[A, B], [B, A]],  b_k = [d; d]        so  W_k S h + b_k = S (W_k h + b_k)
      output:       w   = [v, v]                                 so  w S h = w h

  Softsign is elementwise and commutes with S, hence m(Q x) = m(x). Q x = mirror(x) in normalised
  coordinates needs a mirror-symmetric normalisation (mean with M mu = mu, equal scales on swapped
  entries), which :func:`~margin_rl.stability.learned.training.build_model` fits on the mirror-augmented
  training split. ``to_weights`` expands the tied parameters into ordinary dense matrices, so saved
  weights, the numpy inference, the ONNX export and :class:`MarginModule` are the same for both.

The physics-informed model (``architecture="physics"``) is a :class:`MarginMLP` on [lambda, physics features]
(:mod:`~margin_rl.stability.learned.features`; training feeds it precomputed inputs) plus ``proxy_weight`` x the
analytic proxy; :class:`MarginModule` computes the features in torch. The features of the mirrored state are a
signed permutation of the features, so Q above extends to the input [lambda, features] (``input_mirror``) and
the same tying keeps the whole model exactly invariant.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import torch
from torch import nn

from margin_rl.network import DenseNetwork, torch_forward
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, MIRROR_SIGN, MIRROR_SOURCE
from margin_rl.stability.learned.features import (
    INPUT_MIRROR_SIGN,
    INPUT_MIRROR_SOURCE,
    PHYSICS_INPUT_DIM,
    PROXY_INDEX,
    PhysicsConstants,
    input_names,
    physics_features_torch,
)
from margin_rl.stability.learned.mlp_weights import ACTIVATION, ARCHITECTURE, MarginWeights


def _uniform(shape: tuple[int, ...], fan_in: int) -> nn.Parameter:
    """nn.Linear's default initialisation range, U(-1/sqrt(fan_in), 1/sqrt(fan_in)), from torch's global seed."""
    bound = 1.0 / math.sqrt(fan_in)
    return nn.Parameter(torch.empty(shape).uniform_(-bound, bound))


class MarginMLP(nn.Module):
    """47-256-128-128-1 softsign MLP on raw lambda, with input and output scaling as buffers.

    ``forward(lam)``: (..., 47) -> (...) margin [m]. Gradients flow to lambda (for optimisation) and to
    the parameters (for training); the normalisation buffers are fixed. ``mirror_tied=True`` ties the
    weights so that the network is exactly mirror-invariant (module docstring). ``widths`` other than the
    paper's are for capacity experiments (``benchmarks/studies/bench_margin_capacity.py``): such a network trains
    and evaluates here, but its weights are refused by :class:`~margin_rl.stability.learned.mlp_weights.MarginWeights`.

    Raises:
        ValueError: ``mirror_tied`` with a normalisation that is not mirror-symmetric (then the tied
            network would not be invariant in lambda); fit it on mirror-augmented data.
    """

    def __init__(
        self,
        input_mean: np.ndarray,
        input_std: np.ndarray,
        output_mean: float,
        output_std: float,
        lam_low: np.ndarray,
        lam_high: np.ndarray,
        dtype: torch.dtype = torch.float32,
        mirror_tied: bool = False,
        widths: tuple[int, ...] = ARCHITECTURE,
    ) -> None:
        super().__init__()
        # The mirror as a signed permutation of this network's input: lambda's, or that of [lambda, features].
        mirror_source, mirror_sign = (
            (INPUT_MIRROR_SOURCE, INPUT_MIRROR_SIGN)
            if len(input_mean) == PHYSICS_INPUT_DIM
            else (MIRROR_SOURCE, MIRROR_SIGN)
        )
        if len(widths) < 2 or widths[0] != len(input_mean) or widths[-1] != 1:
            raise ValueError(f"widths must run from {len(input_mean)} inputs to 1 output, got {widths}")
        self.mirror_tied = bool(mirror_tied)
        if self.mirror_tied:
            _check_mirror_symmetric(
                np.asarray(input_mean, float), np.asarray(input_std, float), mirror_source, mirror_sign
            )
            halves = [w // 2 for w in widths[1:-1]]
            if any(2 * h != w for h, w in zip(halves, widths[1:-1], strict=True)):
                raise ValueError(f"mirror_tied needs even hidden widths, got {widths[1:-1]}")
            self.layers = nn.ModuleList()
            self.first = nn.ParameterDict(
                {"U": _uniform((halves[0], widths[0]), widths[0]), "c": _uniform((halves[0],), widths[0])}
            )
            self.hidden = nn.ModuleList(
                nn.ParameterDict(
                    {
                        "AB": _uniform((h_out, 2 * h_in), 2 * h_in),  # [A | B]
                        "d": _uniform((h_out,), 2 * h_in),
                    }
                )
                for h_in, h_out in itertools.pairwise(halves)
            )
            fan_in = 2 * halves[-1]
            self.last = nn.ParameterDict({"v": _uniform((1, halves[-1]), fan_in), "e": _uniform((1,), fan_in)})
            self.register_buffer("mirror_source", torch.as_tensor(mirror_source, dtype=torch.long))
            self.register_buffer("mirror_sign", torch.as_tensor(mirror_sign, dtype=dtype))
        else:
            self.layers = nn.ModuleList(nn.Linear(widths[i], widths[i + 1]) for i in range(len(widths) - 1))
        self.register_buffer("input_mean", torch.as_tensor(input_mean, dtype=dtype))
        self.register_buffer("input_std", torch.as_tensor(input_std, dtype=dtype))
        self.register_buffer("output_scale", torch.tensor([output_mean, output_std], dtype=dtype))
        self.register_buffer("lam_low", torch.as_tensor(lam_low, dtype=dtype))
        self.register_buffer("lam_high", torch.as_tensor(lam_high, dtype=dtype))
        self.to(dtype)

    @classmethod
    def from_weights(
        cls, weights: MarginWeights, mirror_tied: bool = False, dtype: torch.dtype = torch.float32, atol: float = 1e-5
    ) -> MarginMLP:
        """The trainable network of saved ``weights`` (the inverse of :meth:`to_weights`), to continue a fit.

        The normalisation and input ranges are the saved ones. ``mirror_tied`` reads the free parameters back
        from the dense matrices (the first half of each layer's rows, ``v`` the first half of the output row)
        after checking that the matrices have the tied structure to ``atol``.

        Raises:
            ValueError: physics weights (their features are not part of this module), or ``mirror_tied`` with
                weights that are not tied (names the layer): continue such a fit with ``mirror="none"``.
        """
        if weights.architecture != "paper":
            raise ValueError(f"only the paper network can be continued, these weights are {weights.architecture!r}")
        widths = (weights.weights[0].shape[1], *(w.shape[0] for w in weights.weights))
        model = cls(
            input_mean=weights.input_mean,
            input_std=weights.input_std,
            output_mean=weights.output_mean,
            output_std=weights.output_std,
            lam_low=weights.lam_low,
            lam_high=weights.lam_high,
            dtype=dtype,
            mirror_tied=mirror_tied,
            widths=widths,
        )
        with torch.no_grad():
            if not mirror_tied:
                for layer, w, b in zip(model.layers, weights.weights, weights.biases, strict=True):
                    layer.weight.copy_(torch.as_tensor(w, dtype=dtype))
                    layer.bias.copy_(torch.as_tensor(b, dtype=dtype))
                return model
            half, half_last = widths[1] // 2, widths[-2] // 2
            model.first["U"].copy_(torch.as_tensor(weights.weights[0][:half], dtype=dtype))
            model.first["c"].copy_(torch.as_tensor(weights.biases[0][:half], dtype=dtype))
            for block, w, b in zip(model.hidden, weights.weights[1:-1], weights.biases[1:-1], strict=True):
                block["AB"].copy_(torch.as_tensor(w[: w.shape[0] // 2], dtype=dtype))
                block["d"].copy_(torch.as_tensor(b[: b.shape[0] // 2], dtype=dtype))
            model.last["v"].copy_(torch.as_tensor(weights.weights[-1][:, :half_last], dtype=dtype))
            model.last["e"].copy_(torch.as_tensor(weights.biases[-1], dtype=dtype))
        for k, ((w, b), w_saved, b_saved) in enumerate(
            zip(model.dense_parameters(), weights.weights, weights.biases, strict=True)
        ):
            deviation = max(
                float(np.abs(w.detach().double().numpy() - w_saved).max()),
                float(np.abs(b.detach().double().numpy() - b_saved).max()),
            )
            if deviation > atol:
                raise ValueError(
                    f"layer {k} of the weights is not mirror-tied (largest deviation {deviation:.2e}): "
                    "continue this network with mirror 'none'"
                )
        return model

    def dense_parameters(self) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """(W_k, b_k) of every layer as dense tensors (differentiable in the tied parameters)."""
        if not self.mirror_tied:
            return [(layer.weight, layer.bias) for layer in self.layers]
        U, c = self.first["U"], self.first["c"]
        # Q is a signed permutation, (Q x)[k] = sign[k] x[source[k]], with source an involution and equal
        # signs on swapped entries, so the columns of U Q are (U Q)[:, j] = sign[j] U[:, source[j]].
        mirrored = U[:, self.mirror_source] * self.mirror_sign
        out = [(torch.cat([U, mirrored]), torch.cat([c, c]))]
        for block in self.hidden:
            top, d = block["AB"], block["d"]
            half = top.shape[1] // 2
            bottom = torch.cat([top[:, half:], top[:, :half]], dim=1)  # [A | B] -> [B | A]
            out.append((torch.cat([top, bottom]), torch.cat([d, d])))
        v, e = self.last["v"], self.last["e"]
        out.append((torch.cat([v, v], dim=1), e))
        return out

    def normalized_forward(self, x: torch.Tensor) -> torch.Tensor:
        """Network output in normalised units (what the training loss sees)."""
        return torch_forward(x, self.dense_parameters(), ACTIVATION)[..., 0]

    def forward(self, lam: torch.Tensor) -> torch.Tensor:
        x = (lam - self.input_mean) / self.input_std
        return self.normalized_forward(x) * self.output_scale[1] + self.output_scale[0]

    def to_weights(self) -> MarginWeights:
        """Plain-numpy dense parameters for saving (see
        :func:`margin_rl.stability.learned.mlp_weights.save_weights`)."""

        def numpy(t: torch.Tensor) -> np.ndarray:
            return t.detach().cpu().double().numpy()

        params = self.dense_parameters()
        return MarginWeights(
            weights=tuple(numpy(w) for w, _ in params),
            biases=tuple(numpy(b) for _, b in params),
            input_mean=numpy(self.input_mean),
            input_std=numpy(self.input_std),
            output_mean=float(self.output_scale[0]),
            output_std=float(self.output_scale[1]),
            lam_low=numpy(self.lam_low),
            lam_high=numpy(self.lam_high),
        )


def _check_mirror_symmetric(
    mean: np.ndarray, std: np.ndarray, source: np.ndarray, sign: np.ndarray, rtol: float = 1e-6
) -> None:
    """Refuse an input normalisation that does not commute with the mirror (names the first bad entry)."""
    scale = np.maximum(np.abs(mean).max(), 1.0)
    bad_mean = np.abs(mean[source] * sign - mean) > rtol * scale
    bad_std = np.abs(std[source] - std) > rtol * np.maximum(std, 1e-12)
    bad = np.nonzero(bad_mean | bad_std)[0]
    if bad.size:
        name = input_names(len(mean))[bad[0]]
        raise ValueError(
            f"mirror_tied needs a mirror-symmetric input normalisation; {name} and its mirror "
            "entry differ: fit the normalisation on mirror-augmented data (training.build_model(..., mirror=True))"
        )


class MarginModule(nn.Module):
    """Trained weights as a module: raw lambda (..., 47) -> m_l (...) [m], what ``LearnedMargin.torch_module``
    returns.

    ``network`` (the folded layers, :meth:`MarginWeights.network`) runs as
    :meth:`~margin_rl.network.DenseNetwork.torch_module` in ``dtype`` (float32 by default). With physics
    ``constants`` its input is [lambda, :func:`~margin_rl.stability.learned.features.physics_features_torch`]
    and ``proxy_weight`` x the proxy feature is added; gradients flow to lambda through the features.
    """

    def __init__(
        self,
        network: DenseNetwork,
        dtype: torch.dtype | None = None,
        constants: PhysicsConstants | None = None,
        proxy_weight: float = 0.0,
    ) -> None:
        super().__init__()
        expected = PHYSICS_INPUT_DIM if constants is not None else LAMBDA_DIM
        if network.in_dim != expected or network.out_dim != 1:
            raise ValueError(f"the network maps {network.in_dim} inputs to {network.out_dim}; expected {expected} to 1")
        self.network = network.torch_module(dtype)
        self.constants = constants
        self.proxy_weight = float(proxy_weight)

    def forward(self, lam: torch.Tensor) -> torch.Tensor:
        if self.constants is None:
            return self.network(lam)[..., 0]
        features = physics_features_torch(lam, self.constants)
        out = self.network(torch.cat([lam, features], dim=-1))[..., 0]
        if self.proxy_weight != 0.0:
            out = out + self.proxy_weight * features[..., PROXY_INDEX]
        return out
