"""Counting what a block of torch code dispatches: every aten operation, the ones that read the host (synchronise
with the device), and the random numbers drawn. The device step's tests and ``profile_core_ops.py`` use it on Warp's
CPU device, where a host read costs nothing but is dispatched as it would be on a GPU."""

from __future__ import annotations

from collections import Counter
from typing import Any

import torch
from torch.utils._python_dispatch import TorchDispatchMode

HOST_READS = frozenset({"_local_scalar_dense", "nonzero", "is_nonzero", "item", "equal"})
"""Operations that return a value to the host (``bool(t)``, ``int(t)``, ``t.item()``, ``t.nonzero()``...)."""
INDEXING = frozenset({"index", "index_put", "index_put_"})
"""Operations that read the host when indexed by a boolean mask (its count of True entries sizes the result)."""
RANDOM = frozenset({"rand", "randint", "randn", "exponential", "exponential_", "uniform_", "normal_", "random_"})


class DispatchCounter(TorchDispatchMode):
    """Counts per aten operation (:attr:`ops`), host reads (:attr:`host_reads`: by name, a boolean-mask indexing
    as ``index[bool]``) and random numbers drawn (:attr:`random_numbers`)."""

    def __init__(self) -> None:
        super().__init__()
        self.ops: Counter[str] = Counter()
        self.host_reads: Counter[str] = Counter()
        self.random_numbers = 0

    def __torch_dispatch__(self, func: Any, types: Any, args: tuple = (), kwargs: dict | None = None) -> Any:
        kwargs = kwargs or {}
        name = func.overloadpacket.__name__
        self.ops[name] += 1
        if name in HOST_READS:
            self.host_reads[name] += 1
        if name in INDEXING and len(args) > 1:
            indices = args[1] if isinstance(args[1], (list, tuple)) else [args[1]]
            if any(isinstance(i, torch.Tensor) and i.dtype == torch.bool for i in indices):
                self.host_reads[f"{name}[bool]"] += 1
        out = func(*args, **kwargs)
        if name in RANDOM and isinstance(out, torch.Tensor):
            self.random_numbers += out.numel()
        return out

    @property
    def total(self) -> int:
        return sum(self.ops.values())
