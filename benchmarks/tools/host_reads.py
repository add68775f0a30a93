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
from torch.utils._pytree import tree_leaves

HOST_READS = frozenset({"_local_scalar_dense", "nonzero", "is_nonzero", "item", "equal"})
"""Operations that return a value to the host (``bool(t)``, ``int(t)``, ``t.item()``, ``t.nonzero()``...)."""
INDEXING = frozenset({"index", "index_put", "index_put_"})
"""Operations that read the host when indexed by a boolean mask (its count of True entries sizes the result)."""
GATHERS = frozenset({"index", "index_select", "gather"})
"""Operations that read from their first argument only the elements they return (counted so by ``bytes_moved``)."""
RANDOM = frozenset({"rand", "randint", "randn", "exponential", "exponential_", "uniform_", "normal_", "random_"})


ROOT = Path(__file__).resolve().parents[2]
SOURCES = tuple(str(ROOT / folder) for folder in ("envs", "margin_rl"))
"""The package's source folders, whose lines :class:`DispatchCounter` attributes operations to (``by_source``)."""


class DispatchCounter(TorchDispatchMode):
    """Counts per aten operation (:attr:`ops`), host reads (:attr:`host_reads`: by name, a boolean-mask indexing
    as ``index[bool]``) and random numbers drawn (:attr:`random_numbers`); of the operations, the views
    (:attr:`views`: new metadata over the same memory, no kernel launched on a device) and the bytes the others
    read and write (:attr:`bytes_moved`: their tensor arguments and results, each as its shape and dtype make it, a
    gather's source as much as it returns, an in-place result counted as written: what a device's memory carries
    for them, broadcasts and caches aside); with ``by_source``, also per line of the package's source that
    dispatched them (:attr:`sources`: ``"envs/core.py:512"`` -> operation -> count, the innermost line outside
    ``margin_rl/arrays.py``'s helpers; slow: a look at the stack per operation), and the bytes each line's kernels
    move (:attr:`source_bytes`)."""

    def __init__(self, by_source: bool = False) -> None:
        super().__init__()
        self.ops: Counter[str] = Counter()
        self.host_reads: Counter[str] = Counter()
        self.random_numbers = 0
        self.views = 0
        self.bytes_moved = 0
        self.by_source = by_source
        self.sources: dict[str, Counter[str]] = {}
        self.source_bytes: Counter[str] = Counter()

    def __torch_dispatch__(self, func: Any, types: Any, args: tuple = (), kwargs: dict | None = None) -> Any:
        kwargs = kwargs or {}
        name = func.overloadpacket.__name__
        self.ops[name] += 1
        line = _source_line() if self.by_source else ""
        if self.by_source:
            self.sources.setdefault(line, Counter())[name] += 1
        if name in HOST_READS:
            self.host_reads[name] += 1
        if name in INDEXING and len(args) > 1:
            indices = args[1] if isinstance(args[1], (list, tuple)) else [args[1]]
            if any(isinstance(i, torch.Tensor) and i.dtype == torch.bool for i in indices):
                self.host_reads[f"{name}[bool]"] += 1
        out = func(*args, **kwargs)
        if name in RANDOM and isinstance(out, torch.Tensor):
            self.random_numbers += out.numel()
        if func.is_view:
            self.views += 1
            return out
        if name in GATHERS:  # the source as much as is gathered from it, the indices, the result
            moved = _tensor_bytes((args[1:], kwargs)) + 2 * _tensor_bytes(out)
        else:
            moved = _tensor_bytes((args, kwargs)) + _tensor_bytes(out)
        self.bytes_moved += moved
        if self.by_source:
            self.source_bytes[line] += moved
        return out

    @property
    def total(self) -> int:
        return sum(self.ops.values())

    @property
    def kernels(self) -> int:
        """The operations that are not views: on a device, a kernel launched (or a copy) each."""
        return self.total - self.views


def _tensor_bytes(tree: Any) -> int:
    """Bytes of the tensors in a nest of tuples, lists and dicts (each as viewed: elements times their size)."""
    return sum(t.numel() * t.element_size() for t in tree_leaves(tree) if isinstance(t, torch.Tensor))


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
