"""One set of equations for numpy arrays and torch tensors: the array namespace of a computation's inputs.

The environments' equations (rewards, terminations, lambda) are written once in the names of the Python array API
standard and run on whichever kind of array their inputs are: numpy on ``mujoco.batch``, torch tensors (on any
device) beside MuJoCo Warp. :func:`namespace` returns numpy itself for numpy inputs (numpy 2 implements the
standard's names, so the numbers are numpy's bit for bit, at numpy's speed) and ``array_api_compat``'s namespace
for any other kind.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from array_api_compat import array_namespace, is_array_api_obj

_HOST_VALUES = (np.ndarray, np.generic, float, int, bool, list, tuple)
"""Values that mean numpy: its arrays and scalars, and Python numbers and sequences (they take numpy's kind)."""


def namespace(*values: Any) -> Any:
    """The array namespace of ``values``: ``numpy`` when every value is a numpy array, a numpy scalar or a Python
    number or sequence; otherwise that of the arrays among them (``array_api_compat.torch`` for torch tensors, on
    their device). TypeError when numpy arrays and torch tensors are mixed."""
    if all(isinstance(v, _HOST_VALUES) for v in values):
        return np
    return array_namespace(*(v for v in values if is_array_api_obj(v)))
