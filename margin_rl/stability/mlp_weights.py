"""The learned margin's network as data: architecture, weights, their files and model cards.

One module for the types both the numpy inference (:mod:`~margin_rl.stability.learned`) and the torch
module (:mod:`~margin_rl.stability.margin_mlp`) use, so that neither imports the other:

* :data:`ARCHITECTURE` (the layer widths of seed 000 §IV-A) and :class:`MarginWeights` (the parameters in
  plain numpy, validated against the architecture and the lambda layout);
* the bundled files: :func:`weights_dir`, :func:`bundled_robots`, :func:`weights_path`;
* :func:`save_weights` (``<path>.npz`` and its model card ``<path>.json``), :func:`layout_signature`,
  :data:`WEIGHTS_FORMAT` and :class:`WeightsError`.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from margin_rl.atomic import atomic_savez, atomic_write_text
from margin_rl.provenance import sha256_file
from margin_rl.stability.lambda_state import LAMBDA_DIM, LAMBDA_FIELDS, lambda_names

__all__ = [
    "ARCHITECTURE",
    "WEIGHTS_FORMAT",
    "MarginWeights",
    "WeightsError",
    "bundled_robots",
    "layout_signature",
    "save_weights",
    "weights_dir",
    "weights_path",
]

ARCHITECTURE: tuple[int, ...] = (LAMBDA_DIM, 256, 128, 128, 1)
"""Layer widths of seed 000 §IV-A."""

WEIGHTS_FORMAT = 1


class WeightsError(ValueError):
    """A weights file that is missing, corrupted or does not match this package."""


def layout_signature() -> str:
    """Hash of the lambda layout; weights trained on another layout are refused."""
    text = ";".join(f"{f.name}:{f.shape}:{f.frame}" for f in LAMBDA_FIELDS)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def weights_dir() -> Path:
    """Directory of the bundled weights (package data ``margin_rl/stability/weights``)."""
    return Path(str(importlib.resources.files("margin_rl.stability").joinpath("weights")))


def bundled_robots() -> tuple[str, ...]:
    """Robots with bundled learned-margin weights."""
    return tuple(sorted(p.stem for p in weights_dir().glob("*.npz")))


def weights_path(robot_or_path: str | Path) -> Path:
    """The ``.npz`` file meant by a robot name (bundled weights) or a path (its card is the ``.json`` beside it).

    Raises:
        WeightsError: a name that is not a bundled robot (lists the bundled ones).
    """
    text = str(robot_or_path)
    if text.endswith(".npz") or "/" in text or Path(text).suffix:
        return Path(text).with_suffix(".npz")
    if text not in bundled_robots():
        raise WeightsError(f"no learned margin for robot {text!r}; bundled: {', '.join(bundled_robots()) or 'none'}")
    return weights_dir() / f"{text}.npz"


@dataclass(frozen=True)
class MarginWeights:
    """Parameters of the margin MLP in plain numpy (float32 on disk)."""

    weights: tuple[np.ndarray, ...]  # W_k (out, in)
    biases: tuple[np.ndarray, ...]  # b_k (out,)
    input_mean: np.ndarray  # (47,)
    input_std: np.ndarray  # (47,)
    output_mean: float  # [m]
    output_std: float  # [m]
    lam_low: np.ndarray  # (47,) smallest value of each entry in the training split
    lam_high: np.ndarray  # (47,) largest value

    def validate(self, source: str = "weights") -> None:
        widths = [self.weights[0].shape[1]] + [w.shape[0] for w in self.weights]
        if tuple(widths) != ARCHITECTURE:
            raise WeightsError(f"{source}: layer widths {widths}, expected {list(ARCHITECTURE)}")
        for k, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            if b.shape != (w.shape[0],):
                raise WeightsError(f"{source}: bias {k} has shape {b.shape}, expected ({w.shape[0]},)")
        for name in ("input_mean", "input_std", "lam_low", "lam_high"):
            if getattr(self, name).shape != (LAMBDA_DIM,):
                raise WeightsError(f"{source}: {name} must have shape ({LAMBDA_DIM},)")
        if not np.all(self.input_std > 0) or not self.output_std > 0:
            raise WeightsError(f"{source}: normalisation scales must be positive")
        arrays = [*self.weights, *self.biases, self.input_mean, self.input_std, self.lam_low, self.lam_high]
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise WeightsError(f"{source}: non-finite parameters")

    def to_arrays(self) -> dict[str, np.ndarray]:
        out = {f"W{k}": w.astype(np.float32) for k, w in enumerate(self.weights)}
        out |= {f"b{k}": b.astype(np.float32) for k, b in enumerate(self.biases)}
        out |= {
            "input_mean": self.input_mean.astype(np.float64),
            "input_std": self.input_std.astype(np.float64),
            "output_scale": np.array([self.output_mean, self.output_std], dtype=np.float64),
            "lam_low": self.lam_low.astype(np.float64),
            "lam_high": self.lam_high.astype(np.float64),
        }
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], source: str = "weights") -> MarginWeights:
        n_layers = len(ARCHITECTURE) - 1
        required = [f"W{i}" for i in range(n_layers)] + [f"b{i}" for i in range(n_layers)]
        required += ["input_mean", "input_std", "output_scale", "lam_low", "lam_high"]
        missing = [k for k in required if k not in arrays]
        if missing:
            raise WeightsError(f"{source}: missing arrays {missing}")
        w = cls(
            weights=tuple(np.asarray(arrays[f"W{i}"], dtype=np.float64) for i in range(n_layers)),
            biases=tuple(np.asarray(arrays[f"b{i}"], dtype=np.float64) for i in range(n_layers)),
            input_mean=np.asarray(arrays["input_mean"], dtype=np.float64),
            input_std=np.asarray(arrays["input_std"], dtype=np.float64),
            output_mean=float(arrays["output_scale"][0]),
            output_std=float(arrays["output_scale"][1]),
            lam_low=np.asarray(arrays["lam_low"], dtype=np.float64),
            lam_high=np.asarray(arrays["lam_high"], dtype=np.float64),
        )
        w.validate(source)
        return w


def save_weights(weights: MarginWeights, path: str | Path, card: dict[str, object]) -> dict[str, object]:
    """Write ``<path>.npz`` and its model card ``<path>.json`` (with the npz's sha256 and layout)."""
    path = Path(path).with_suffix("")
    weights.validate(str(path))
    npz = path.with_suffix(".npz")
    atomic_savez(npz, **weights.to_arrays())
    full_card = {
        "format": WEIGHTS_FORMAT,
        "architecture": list(ARCHITECTURE),
        "activation": "softsign",
        "lambda_layout": layout_signature(),
        "lambda_names": list(lambda_names()),
        **card,
        "file": npz.name,
        "sha256": sha256_file(npz),
    }
    atomic_write_text(path.with_suffix(".json"), json.dumps(full_card, indent=2) + "\n")
    return full_card
