"""margin_rl.arrays: which namespace a computation's inputs get."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from margin_rl.arrays import namespace


def test_numpy_inputs_and_python_values_get_numpy_itself() -> None:
    """numpy itself (its own functions and numbers), also for numpy scalars and plain Python values."""
    assert namespace(np.zeros(3), 1.0, [1, 2], np.float64(2.0), True) is np
    assert namespace() is np


def test_torch_tensors_get_the_torch_namespace_on_their_device() -> None:
    xp = namespace(torch.zeros(3, dtype=torch.float64), 0.5)
    assert xp.__name__ == "array_api_compat.torch"
    assert xp.concat([torch.ones(2), torch.zeros(1)], axis=0).tolist() == [1.0, 1.0, 0.0]


def test_mixed_kinds_are_refused() -> None:
    with pytest.raises(TypeError, match="Multiple namespaces"):
        namespace(np.zeros(2), torch.zeros(2))
