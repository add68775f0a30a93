"""The learned margin's network as data: architecture, weights, their files and model cards.

One module for the types both the numpy inference (:mod:`~margin_rl.stability.learned.model`) and the torch
modules (:mod:`~margin_rl.stability.learned.margin_mlp`) use, so that neither imports the other:

* :data:`ARCHITECTURE` (the layer widths of seed 000 §IV-A), :data:`ARCHITECTURES` (``"paper"``: that
  network on raw lambda; ``"physics"``: the same hidden layers on [lambda, the physics features of
  :mod:`~margin_rl.stability.learned.features`], plus ``proxy_weight`` times the analytic proxy) and
  :class:`MarginWeights` (the parameters in plain numpy, validated against the architecture and the lambda
  layout; :meth:`MarginWeights.network` folds them into the :class:`~margin_rl.network.DenseNetwork` that
  gives the numpy, torch and CasADi forms);
* the bundled files: :func:`weights_dir`, :func:`bundled_robots`, :func:`bundled_weights`, :func:`weights_path`
  (``"<robot>"``: the default network of the environments and the planner, trained on Table I and on the
  states walking policies visit (learned margin v5); ``"<robot>_table_i"``: the network trained on seed 000's
  Table I alone, the v1 default, kept as named historical weights);
* :func:`save_weights` (``<path>.npz`` and its model card ``<path>.json``), :func:`layout_signature`,
  :data:`WEIGHTS_FORMAT` and :class:`WeightsError`.
"""

from __future__ import annotations

import hashlib
import importlib.resources
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from margin_rl.network import DenseNetwork, layer_arrays, read_layers, save_arrays, write_card
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, LAMBDA_FIELDS, lambda_names
from margin_rl.stability.learned.features import N_FEATURES, PhysicsConstants, feature_names

__all__ = [
    "ACTIVATION",
    "ARCHITECTURE",
    "ARCHITECTURES",
    "WEIGHTS_FORMAT",
    "MarginWeights",
    "WeightsError",
    "architecture_widths",
    "bundled_robots",
    "bundled_weights",
    "layout_signature",
    "save_weights",
    "weights_dir",
    "weights_path",
]

ARCHITECTURE: tuple[int, ...] = (LAMBDA_DIM, 256, 128, 128, 1)
"""Layer widths of seed 000 §IV-A."""
ACTIVATION = "softsign"
"""The hidden layers' activation (seed 000 §IV-A), every architecture."""

ARCHITECTURES: tuple[str, ...] = ("paper", "physics")
"""``paper``: :data:`ARCHITECTURE` on raw lambda. ``physics``: the same hidden layers on
[lambda, physics features] (47 + N_FEATURES inputs), output plus ``proxy_weight`` x the analytic proxy."""


def architecture_widths(architecture: str) -> tuple[int, ...]:
    """Layer widths of a named architecture.

    Raises:
        WeightsError: an unknown name (lists the known ones).
    """
    if architecture == "paper":
        return ARCHITECTURE
    if architecture == "physics":
        return (LAMBDA_DIM + N_FEATURES, *ARCHITECTURE[1:])
    raise WeightsError(f"unknown architecture {architecture!r}; known: {', '.join(ARCHITECTURES)}")


WEIGHTS_FORMAT = 1


class WeightsError(ValueError):
    """A weights file that is missing, corrupted or does not match this package."""


def layout_signature() -> str:
    """Hash of the lambda layout; weights trained on another layout are refused."""
    text = ";".join(f"{f.name}:{f.shape}:{f.frame}" for f in LAMBDA_FIELDS)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def weights_dir() -> Path:
    """Directory of the bundled weights (package data ``margin_rl/stability/weights``)."""
    return Path(str(importlib.resources.files("margin_rl.stability.learned").joinpath("weights")))


WEIGHTS_VARIANTS: tuple[str, ...] = ("table_i",)
"""Suffixes of bundled weights other than a robot's default: ``"<robot>_<variant>"``."""


def bundled_weights() -> tuple[str, ...]:
    """Names of every bundled weights file (``LearnedMargin.load(name)``): robots and ``<robot>_<variant>``."""
    return tuple(sorted(p.stem for p in weights_dir().glob("*.npz")))


def bundled_robots() -> tuple[str, ...]:
    """Robots with bundled (default) learned-margin weights."""
    return tuple(n for n in bundled_weights() if not n.endswith(tuple(f"_{v}" for v in WEIGHTS_VARIANTS)))


def weights_path(robot_or_path: str | Path) -> Path:
    """The ``.npz`` file meant by a robot name (bundled weights) or a path (its card is the ``.json`` beside it).

    Raises:
        WeightsError: a name that is not a bundled robot (lists the bundled ones).
    """
    text = str(robot_or_path)
    if text.endswith(".npz") or "/" in text or Path(text).suffix:
        return Path(text).with_suffix(".npz")
    if text not in bundled_weights():
        raise WeightsError(f"no learned margin for robot {text!r}; bundled: {', '.join(bundled_weights()) or 'none'}")
    return weights_dir() / f"{text}.npz"


@dataclass(frozen=True)
class MarginWeights:
    """Parameters of the margin MLP in plain numpy (float32 on disk).

    For ``architecture="physics"`` the network's input is [lambda, features] (47 + N_FEATURES entries, so
    ``input_mean``/``input_std`` have that length), ``physics`` holds the feature constants (mass [kg],
    gravity [m/s^2], foot radius [m]) and the output adds ``proxy_weight`` x the ``support_margin``
    feature; ``lam_low``/``lam_high`` stay the 47 lambda ranges.
    """

    weights: tuple[np.ndarray, ...]  # W_k (out, in)
    biases: tuple[np.ndarray, ...]  # b_k (out,)
    input_mean: np.ndarray  # (47,) (physics: (47 + N_FEATURES,))
    input_std: np.ndarray  # same shape
    output_mean: float  # [m]
    output_std: float  # [m]
    lam_low: np.ndarray  # (47,) smallest value of each entry in the training split
    lam_high: np.ndarray  # (47,) largest value
    architecture: str = "paper"
    physics: np.ndarray | None = None  # (3,) PhysicsConstants.to_array() for "physics"
    proxy_weight: float = 0.0

    @property
    def constants(self) -> PhysicsConstants:
        """The feature constants of a physics model."""
        if self.physics is None:
            raise WeightsError(f"{self.architecture} weights carry no physics constants")
        return PhysicsConstants.from_array(self.physics)

    def network(self) -> DenseNetwork:
        """The layers with the input normalisation folded into the first and the output scaling into the
        last, once: raw network input (lambda, or [lambda, features]) -> margin [m] before any proxy."""
        return DenseNetwork.fold(
            self.weights,
            self.biases,
            ACTIVATION,
            in_offset=self.input_mean,
            in_scale=self.input_std,
            out_offset=self.output_mean,
            out_scale=self.output_std,
        )

    def validate(self, source: str = "weights") -> None:
        expected = architecture_widths(self.architecture)
        widths = [self.weights[0].shape[1]] + [w.shape[0] for w in self.weights]
        if tuple(widths) != expected:
            raise WeightsError(f"{source}: layer widths {widths}, expected {list(expected)}")
        if self.architecture == "physics":
            if self.physics is None or np.shape(self.physics) != (3,):
                raise WeightsError(f"{source}: physics weights need (mass, gravity, foot_radius)")
            try:
                PhysicsConstants.from_array(self.physics)
            except ValueError as exc:
                raise WeightsError(f"{source}: {exc}") from exc
            if not np.isfinite(self.proxy_weight):
                raise WeightsError(f"{source}: non-finite proxy weight")
        for k, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            if b.shape != (w.shape[0],):
                raise WeightsError(f"{source}: bias {k} has shape {b.shape}, expected ({w.shape[0]},)")
        for name, size in (("input_mean", expected[0]), ("input_std", expected[0]), ("lam_low", LAMBDA_DIM),
                           ("lam_high", LAMBDA_DIM)):  # fmt: skip
            if getattr(self, name).shape != (size,):
                raise WeightsError(f"{source}: {name} must have shape ({size},)")
        if not np.all(self.input_std > 0) or not self.output_std > 0:
            raise WeightsError(f"{source}: normalisation scales must be positive")
        arrays = [*self.weights, *self.biases, self.input_mean, self.input_std, self.lam_low, self.lam_high]
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise WeightsError(f"{source}: non-finite parameters")

    def to_arrays(self) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = layer_arrays(self.weights, self.biases)
        out |= {
            "input_mean": self.input_mean.astype(np.float64),
            "input_std": self.input_std.astype(np.float64),
            "output_scale": np.array([self.output_mean, self.output_std], dtype=np.float64),
            "lam_low": self.lam_low.astype(np.float64),
            "lam_high": self.lam_high.astype(np.float64),
        }
        if self.architecture != "paper":  # paper files keep exactly their historical keys
            out["architecture"] = np.array(self.architecture)  # a unicode scalar: no pickle needed
            out["physics_constants"] = np.asarray(self.physics, dtype=np.float64)
            out["proxy_weight"] = np.array([self.proxy_weight], dtype=np.float64)
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], source: str = "weights") -> MarginWeights:
        architecture = str(arrays["architecture"]) if "architecture" in arrays else "paper"
        if architecture not in ARCHITECTURES:
            raise WeightsError(f"{source}: unknown architecture {architecture!r}; known: {', '.join(ARCHITECTURES)}")
        n_layers = len(ARCHITECTURE) - 1
        required = [f"W{i}" for i in range(n_layers)] + [f"b{i}" for i in range(n_layers)]
        required += ["input_mean", "input_std", "output_scale", "lam_low", "lam_high"]
        if architecture == "physics":
            required += ["physics_constants", "proxy_weight"]
        missing = [k for k in required if k not in arrays]
        if missing:
            raise WeightsError(f"{source}: missing arrays {missing}")
        weights, biases = read_layers(arrays, n_layers)
        w = cls(
            weights=weights,
            biases=biases,
            input_mean=np.asarray(arrays["input_mean"], dtype=np.float64),
            input_std=np.asarray(arrays["input_std"], dtype=np.float64),
            output_mean=float(arrays["output_scale"][0]),
            output_std=float(arrays["output_scale"][1]),
            lam_low=np.asarray(arrays["lam_low"], dtype=np.float64),
            lam_high=np.asarray(arrays["lam_high"], dtype=np.float64),
            architecture=architecture,
            physics=np.asarray(arrays["physics_constants"], dtype=np.float64) if architecture == "physics" else None,
            proxy_weight=float(np.asarray(arrays["proxy_weight"]).reshape(-1)[0]) if architecture == "physics" else 0.0,
        )
        w.validate(source)
        return w


def save_weights(weights: MarginWeights, path: str | Path, card: dict[str, object]) -> dict[str, object]:
    """Write ``<path>.npz`` and its model card ``<path>.json`` (with the npz's sha256 and layout)."""
    path = Path(path).with_suffix("")
    weights.validate(str(path))
    npz = path.with_suffix(".npz")
    digest = save_arrays(npz, weights.to_arrays())
    physics = {}
    if weights.architecture != "paper":
        constants = weights.constants
        physics = {
            "model": weights.architecture,
            "features": list(feature_names()),
            "physics_constants": {"mass_kg": constants.mass, "gravity": constants.gravity,
                                  "foot_radius_m": constants.foot_radius},
            "proxy_weight": weights.proxy_weight,
        }  # fmt: skip
    full_card = {
        "format": WEIGHTS_FORMAT,
        "architecture": list(architecture_widths(weights.architecture)),
        "activation": ACTIVATION,
        "lambda_layout": layout_signature(),
        "lambda_names": list(lambda_names()),
        **physics,
        **card,
        "file": npz.name,
        "sha256": digest,
    }
    write_card(path.with_suffix(".json"), full_card)
    return full_card
