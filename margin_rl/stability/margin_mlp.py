"""The margin MLP as a torch module (training and differentiable use); numpy inference is in ``learned``."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from margin_rl.stability.learned import ARCHITECTURE, MarginWeights


class MarginMLP(nn.Module):
    """47-256-128-128-1 softsign MLP on raw lambda, with input and output scaling as buffers.

    ``forward(lam)``: (..., 47) -> (...) margin [m]. Gradients flow to lambda (for optimisation) and to
    the parameters (for training); the normalisation buffers are fixed.
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
    ) -> None:
        super().__init__()
        widths = ARCHITECTURE
        self.layers = nn.ModuleList(nn.Linear(widths[i], widths[i + 1]) for i in range(len(widths) - 1))
        self.activation = nn.Softsign()
        self.register_buffer("input_mean", torch.as_tensor(input_mean, dtype=dtype))
        self.register_buffer("input_std", torch.as_tensor(input_std, dtype=dtype))
        self.register_buffer("output_scale", torch.tensor([output_mean, output_std], dtype=dtype))
        self.register_buffer("lam_low", torch.as_tensor(lam_low, dtype=dtype))
        self.register_buffer("lam_high", torch.as_tensor(lam_high, dtype=dtype))
        self.to(dtype)

    def normalized_forward(self, x: torch.Tensor) -> torch.Tensor:
        """Network output in normalised units (what the training loss sees)."""
        h = x
        for layer in self.layers[:-1]:
            h = self.activation(layer(h))
        return self.layers[-1](h)[..., 0]

    def forward(self, lam: torch.Tensor) -> torch.Tensor:
        x = (lam - self.input_mean) / self.input_std
        return self.normalized_forward(x) * self.output_scale[1] + self.output_scale[0]

    @classmethod
    def from_weights(cls, weights: MarginWeights, dtype: torch.dtype | None = None) -> MarginMLP:
        """Module with the given parameters, in ``dtype`` (float32 by default)."""
        module = cls(
            weights.input_mean,
            weights.input_std,
            weights.output_mean,
            weights.output_std,
            weights.lam_low,
            weights.lam_high,
            dtype=dtype or torch.float32,
        )
        with torch.no_grad():
            for layer, w, b in zip(module.layers, weights.weights, weights.biases, strict=True):
                layer.weight.copy_(torch.as_tensor(w))
                layer.bias.copy_(torch.as_tensor(b))
        return module

    def to_weights(self) -> MarginWeights:
        """Plain-numpy parameters for saving (see :func:`margin_rl.stability.learned.save_weights`)."""

        def numpy(t: torch.Tensor) -> np.ndarray:
            return t.detach().cpu().double().numpy()

        return MarginWeights(
            weights=tuple(numpy(layer.weight) for layer in self.layers),
            biases=tuple(numpy(layer.bias) for layer in self.layers),
            input_mean=numpy(self.input_mean),
            input_std=numpy(self.input_std),
            output_mean=float(self.output_scale[0]),
            output_std=float(self.output_scale[1]),
            lam_low=numpy(self.lam_low),
            lam_high=numpy(self.lam_high),
        )
