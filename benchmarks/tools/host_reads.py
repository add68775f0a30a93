"""Counting what a block of torch code dispatches: every aten operation, the ones that read the host (synchronise
with the device), and the random numbers drawn. The device step's tests and ``profile_core_ops.py`` use it on Warp's
CPU device, where a host read costs nothing but is dispatched as it would be on a GPU."""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path
from typing import Any

import torch
from torch.utils._python_dispatch import TorchDispatchMode

HOST_READS = frozenset({"_local_scalar_dense", "nonzero", "is_nonzero", "item", "equal"})
"""Operations that return a value to the host (``bool(t)``, ``int(t)``, ``t.item()``, ``t.nonzero()``...)."""
INDEXING = frozenset({"index", "index_put", "index_put_"})
"""Operations that read the host when indexed by a boolean mask (its count of True entries sizes the result)."""
RANDOM = frozenset({"rand", "randint", "randn", "exponential", "exponential_", "uniform_", "normal_", "random_"})


ROOT = Path(__file__).resolve().parents[2]
SOURCES = tuple(str(ROOT / folder) for folder in ("envs", "margin_rl"))
"""The package's source folders, whose lines :class:`DispatchCounter` attributes operations to (``by_source``)."""


class DispatchCounter(TorchDispatchMode):
    """Counts per aten operation (:attr:`ops`), host reads (:attr:`host_reads`: by name, a boolean-mask indexing
    as ``index[bool]``) and random numbers drawn (:attr:`random_numbers`); with ``by_source``, also per line of the
    package's source that dispatched them (:attr:`sources`: ``"envs/core.py:512"`` -> operation -> count, the
    innermost line outside ``margin_rl/arrays.py``'s helpers; slow: a look at the stack per operation)."""

    def __init__(self, by_source: bool = False) -> None:
        super().__init__()
        self.ops: Counter[str] = Counter()
        self.host_reads: Counter[str] = Counter()
        self.random_numbers = 0
        self.by_source = by_source
        self.sources: dict[str, Counter[str]] = {}

    def __torch_dispatch__(self, func: Any, types: Any, args: tuple = (), kwargs: dict | None = None) -> Any:
        kwargs = kwargs or {}
        name = func.overloadpacket.__name__
        self.ops[name] += 1
        if self.by_source:
            self.sources.setdefault(_source_line(), Counter())[name] += 1
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


def _source_line() -> str:
    """The innermost frame of the caller's stack in the package's source (an array helper's caller, not the
    helper), as ``<folder>/<file>:<line>``; "elsewhere" when none is."""
    frame = sys._getframe(2)
    while frame is not None:
        path = frame.f_code.co_filename
        if path.startswith(SOURCES) and not path.endswith("arrays.py"):
            return f"{Path(path).relative_to(ROOT)}:{frame.f_lineno}"
        frame = frame.f_back
    return "elsewhere"
