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

Weights are bundled as ``.npz`` (no pickle; the layers and the four normalisation vectors, float32) next to
a JSON card that records the SHA-256 of each file; :func:`load_bundle` refuses files whose checksum does
not match and folds each network's normalisation into its layers, giving a
:class:`margin_rl.network.DenseNetwork`: numpy value and Jacobian, and the CasADi expression the planner
uses for exact derivatives. Training uses :func:`margin_rl.network.torch_sequential` in
:mod:`margin_rl.slip.train`, so this module does not import torch.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.network import (
    DenseNetwork,
    layer_arrays,
    read_arrays,
    read_layers,
    save_arrays,
    verify_sha256,
    write_card,
)
from margin_rl.slip.margin import BOX_HIGH, BOX_LOW

__all__ = [
    "ACTIVATION",
    "BUNDLE_DIR",
    "ROLES",
    "Bundle",
    "box_normalisation",
    "load_bundle",
    "load_network",
    "network_arrays",
    "network_from_arrays",
    "save_bundle",
]

FloatArray = NDArray[np.float64]

#: Where the trained weights ship inside the package.
BUNDLE_DIR = Path(__file__).resolve().parent / "weights"
#: The two networks of a bundle, each in ``<role>.npz``.
ROLES = ("return_map", "margin")
#: Hidden-layer activation of both networks.
ACTIVATION = "relu"
_N_LAYERS = 3
_NORMALISATION = ("in_offset", "in_scale", "out_offset", "out_scale")


def box_normalisation() -> tuple[FloatArray, FloatArray]:
    """Input offset and scale mapping the eq. (13) box to :math:`[-1, 1]^4`."""
    return 0.5 * (BOX_LOW + BOX_HIGH), 0.5 * (BOX_HIGH - BOX_LOW)


def network_arrays(
    weights: tuple[ArrayLike, ...],
    biases: tuple[ArrayLike, ...],
    in_offset: ArrayLike,
    in_scale: ArrayLike,
    out_offset: ArrayLike,
    out_scale: ArrayLike,
) -> dict[str, NDArray[np.float32]]:
    """A network's file content: layers ``W0..W2``, ``b0..b2`` and the normalisation vectors, float32."""
    if len(weights) != _N_LAYERS:
        raise ValueError(f"the SLIP networks have {_N_LAYERS} layers, got {len(weights)}")
    normalisation = dict(zip(_NORMALISATION, (in_offset, in_scale, out_offset, out_scale), strict=True))
    return layer_arrays(weights, biases) | {k: np.asarray(v, dtype=np.float32) for k, v in normalisation.items()}


def network_from_arrays(arrays: Mapping[str, ArrayLike]) -> DenseNetwork:
    """The network of :func:`network_arrays`' content, its normalisation folded into the layers.

    Raises
    ------
    ValueError
        If an array is missing or the shapes are inconsistent.
    """
    try:
        weights, biases = read_layers(arrays, _N_LAYERS)
        norm = {k: np.asarray(arrays[k], dtype=np.float64) for k in _NORMALISATION}
    except KeyError as exc:
        raise ValueError(f"weight arrays lack {exc.args[0]!r}") from exc
    n_in, n_out = weights[0].shape[1], weights[-1].shape[0]
    for key, size in zip(_NORMALISATION, (n_in, n_in, n_out, n_out), strict=True):
        if norm[key].shape != (size,):
            raise ValueError(f"{key} must have shape ({size},), got {norm[key].shape}")
    return DenseNetwork.fold(weights, biases, ACTIVATION, **norm)


def load_network(path: Path | str) -> DenseNetwork:
    """A network from its ``.npz`` file (without checking a card)."""
    return network_from_arrays(read_arrays(path))


@dataclass(frozen=True)
class Bundle:
    """Trained return map ``P``, margin ``M`` and their model card."""

    return_map: DenseNetwork
    margin: DenseNetwork
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
    nets: dict[str, DenseNetwork] = {}
    for role in ROLES:
        entry = card["files"][role]
        path = root / entry["file"]
        verify_sha256(path, entry["sha256"])
        nets[role] = load_network(path)
    return Bundle(return_map=nets["return_map"], margin=nets["margin"], card=card)


def save_bundle(
    directory: Path | str, arrays: Mapping[str, Mapping[str, ArrayLike]], card: Mapping[str, Any]
) -> dict[str, Any]:
    """Write ``<role>.npz`` for both :data:`ROLES` (``arrays[role]``: :func:`network_arrays`) and ``card.json``,
    atomically; the card gains ``files`` (name and SHA-256 of each) and is returned."""
    root = Path(directory)
    files = {role: {"file": f"{role}.npz", "sha256": save_arrays(root / f"{role}.npz", arrays[role])} for role in ROLES}
    full = {**card, "files": files}
    write_card(root / "card.json", full)
    return full
