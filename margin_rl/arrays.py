"""One set of equations for numpy arrays and torch tensors: the array namespace of a computation's inputs.

The environments' equations (rewards, terminations, lambda) are written once in the names of the Python array API
standard and run on whichever kind of array their inputs are: numpy on ``mujoco.batch``, torch tensors (on any
device) beside MuJoCo Warp. :func:`namespace` returns numpy itself for numpy inputs (numpy 2 implements the
standard's names, so the numbers are numpy's bit for bit, at numpy's speed) and ``array_api_compat``'s namespace
for any other kind.
"""

from __future__ import annotations

from itertools import accumulate
from typing import Any

import numpy as np
from array_api_compat import array_namespace, is_array_api_obj

Array = Any
"""A numpy array or a torch tensor on any device (what the environments' equations take and answer, in the kind of
their inputs): an annotation for code that runs on both."""

_HOST_VALUES = (np.ndarray, np.generic, float, int, bool, list, tuple)
"""Values that mean numpy: its arrays and scalars, and Python numbers and sequences (they take numpy's kind)."""


def namespace(*values: Any) -> Any:
    """The array namespace of ``values``: ``numpy`` when every value is a numpy array, a numpy scalar or a Python
    number or sequence; otherwise that of the arrays among them (``array_api_compat.torch`` for torch tensors, on
    their device). TypeError when numpy arrays and torch tensors are mixed."""
    if all(isinstance(v, _HOST_VALUES) for v in values):
        return np
    return array_namespace(*(v for v in values if is_array_api_obj(v)))


def to_numpy(value: Any) -> np.ndarray:
    """``value`` as a numpy array: numpy arrays and Python values as they are (no copy), a tensor copied to the host
    (the Gymnasium and SB3 edges of a core that computes on a device)."""
    if isinstance(value, _HOST_VALUES):
        return np.asarray(value)
    return np.asarray(value.detach().cpu().numpy()) if hasattr(value, "detach") else np.asarray(value)


def like(value: Any, reference: Any, dtype: Any = None) -> Any:
    """``value`` (numpy, Python or a tensor) as an array of ``reference``'s kind and device, in ``dtype`` (default:
    ``value``'s own); no copy where it already is one (numpy stays numpy, bit for bit)."""
    xp = namespace(reference)
    if xp is np:
        return np.asarray(to_numpy(value), dtype=dtype)
    import torch  # a tensor reference: torch is loaded already

    if isinstance(value, np.ndarray) and not value.flags.writeable:
        value = value.copy()  # torch shares a numpy array's memory and would write through a read-only view
    return torch.as_tensor(value, dtype=dtype, device=reference.device)


def finite_mask(values: Any) -> Any:
    """Where ``values`` is finite (bool, same shape), as ``|x| <= the largest float of its dtype``: false for NaN
    and inf alike, the same answer as ``isfinite`` in two operations (torch's ``isfinite`` dispatches four, each a
    kernel launch on a device)."""
    xp = namespace(values)
    return xp.abs(values) <= xp.finfo(values.dtype).max


def finite_or_zero(values: Any) -> Any:
    """``values`` with every NaN and inf replaced by 0 (a new array): ``where(finite_mask(x), x, 0)`` in one
    operation (``nan_to_num``, numpy's and torch's alike)."""
    xp = namespace(values)
    return xp.nan_to_num(values, nan=0.0, posinf=0.0, neginf=0.0)


def split_columns(block: Any, widths: Any) -> tuple[Any, ...]:
    """Views of consecutive column ranges of ``block`` (N, sum(widths)), of ``widths`` columns each, in one
    operation on torch (``split``; numpy: the slices): a block read once and named by parts, without a slice
    dispatched per part."""
    widths = [int(w) for w in widths]
    stops = list(accumulate(widths))
    if not stops or stops[-1] != int(block.shape[1]):
        total = stops[-1] if stops else 0
        raise ValueError(f"column widths {widths} sum to {total}, but the block has {block.shape[1]} columns")
    if namespace(block) is np:  # slices (numpy's split is the same views, made in Python at more cost)
        return tuple(block[:, stop - width : stop] for width, stop in zip(widths, stops, strict=True))
    return tuple(block.split(widths, dim=1))


def unstack(values: Any, axis: int = 1) -> tuple[Any, ...]:
    """The slices of ``values`` along ``axis`` (views; by default the columns ``values[:, k]``): the standard's
    ``unstack`` in one operation on torch (``unbind``; ``array_api_compat``'s dispatches a ``permute`` first),
    numpy's own."""
    if namespace(values) is np:
        return np.unstack(values, axis=axis)
    return values.unbind(axis)


ALL_ROWS = slice(None)
"""The rows argument that means every row (:func:`rows_of`)."""


def rows_of(values: Any, rows: Any) -> Any:
    """``values[rows]`` for ``rows`` an index array, or ``values`` itself for :data:`ALL_ROWS` (a view of every row
    would be one more operation dispatched on a device, for nothing)."""
    if isinstance(rows, slice) and rows == ALL_ROWS:
        return values
    return values[rows]


def reshaped(values: Any, shape: tuple[int, ...]) -> Any:
    """``values`` reshaped to ``shape`` (whole numbers, no -1), ``values`` itself where it has that shape already
    (on a device a reshape is an operation dispatched from Python even when it changes nothing)."""
    return values if tuple(values.shape) == shape else namespace(values).reshape(values, shape)


def take_last(values: Any, index: Any) -> Any:
    """``values[..., index]`` for an integer ``index`` (k,) of ``values``' kind, as a new C-ordered array: numpy's
    ``take``, torch's ``index_select`` (one operation; the standard's ``take`` dispatches four on torch)."""
    if namespace(values) is np:
        return np.take(values, index, axis=-1)
    return values.index_select(-1, index)


def write_where(target: Any, mask: Any, values: Any) -> None:
    """``target = where(mask, values, target)`` in place: ``mask`` (N,) bool selects rows of ``target`` (N, ...)
    (or is shaped to broadcast over them already, e.g. (N, 1)); ``values``, broadcast to ``target``, is a scalar or
    an array. One operation on torch (``masked_fill_`` for a scalar, ``where`` into ``target`` for an array),
    ``copyto`` on numpy; no host read, the same work whichever rows the mask holds."""
    rows = mask if mask.ndim == target.ndim else mask.reshape(mask.shape + (1,) * (target.ndim - mask.ndim))
    if namespace(target) is np:
        np.copyto(target, values, where=rows)
    elif isinstance(values, (int, float, bool, np.generic)):
        target.masked_fill_(rows, values.item() if isinstance(values, np.generic) else values)
    else:
        import torch  # tensors: torch is loaded already

        torch.where(rows, values, target, out=target)


def rotate(rotations: Any, vectors: Any, inverse: bool = False) -> Any:
    """Vectors turned by a batch of rotation matrices: R_n v (``inverse``: R_n^T v), for ``rotations`` (N, 3, 3) and
    ``vectors`` (N, 3), or (N, k, 3) for k vectors per matrix; the result has ``vectors``' shape.

    One equation, two routes: numpy computes it with ``einsum`` (its numbers, bit for bit, as they always were);
    torch with one batched product (``bmm``): ``torch.einsum`` dispatches nine views around the same product, and on
    a device every dispatched operation costs host time.
    """
    xp = namespace(rotations, vectors)
    single = vectors.ndim == 2
    if xp is np:
        return (
            np.einsum("nji,nj->ni" if inverse else "nij,nj->ni", rotations, vectors)
            if single
            else np.einsum("nji,nkj->nki" if inverse else "nij,nkj->nki", rotations, vectors)
        )
    import torch  # tensors: torch is loaded already

    rows = vectors[:, None, :] if single else vectors  # (N, k, 3): each turned vector is a row, v^T R^T or v^T R
    turned = torch.bmm(rows, rotations if inverse else rotations.mT)
    return turned[:, 0] if single else turned


_CONSTANTS: dict[tuple[Any, ...], Any] = {}


def constant(values: Any, reference: Any) -> Any:
    """A small constant array (an index, offsets: numpy or Python ``values``) in ``reference``'s kind and on its
    device, copied there once per device and kept: a step on a device builds nothing from host data, so it runs
    with no host-to-device copy and can be recorded as a graph. numpy: ``values`` as an array, as it is."""
    host = np.asarray(values)
    if namespace(reference) is np:
        return host
    key = (host.dtype.str, host.shape, host.tobytes(), str(reference.device))
    if key not in _CONSTANTS:
        _CONSTANTS[key] = like(host, reference)
    return _CONSTANTS[key]


class TorchRandom:
    """The draws the environments make, from a ``torch.Generator`` on a device, under numpy ``Generator``'s names and
    arguments (``uniform``, ``integers``, ``exponential``), so that one piece of code draws on either: the host's
    numpy generator beside ``mujoco.batch``, this beside a physics on a device. float64 draws, int64 integers.
    Pickles (and deep-copies) with its state."""

    def __init__(self, seed: int | None, device: Any) -> None:
        import torch

        self.device = torch.device(device)
        self.generator = torch.Generator(device=self.device)
        self._column_bounds: dict[tuple[Any, ...], tuple[Any, ...]] = {}
        if seed is None:
            self.generator.seed()
        else:
            self.generator.manual_seed(int(seed))

    def _shape(self, size: Any) -> tuple[int, ...]:
        return (int(size),) if isinstance(size, (int, np.integer)) else tuple(int(s) for s in size)

    def uniform(self, low: float = 0.0, high: float = 1.0, size: Any = 1) -> Any:
        """U[low, high) of shape ``size`` (scalar bounds)."""
        import torch

        draws = torch.rand(self._shape(size), generator=self.generator, dtype=torch.float64, device=self.device)
        return low + (high - low) * draws

    def uniform_columns(self, n: int, bounds: tuple[ColumnBounds, ...]) -> list[Any]:
        """:func:`uniform_columns` on this generator: one (n, columns) draw, scaled per column, split."""
        import torch

        if bounds not in self._column_bounds:  # per column: low, and high - low (made once per set of bounds)
            widths, low, high = _column_bounds(bounds)
            self._column_bounds[bounds] = (
                widths,
                torch.as_tensor(low, device=self.device),
                torch.as_tensor(high - low, device=self.device),
            )
        widths, lows, ranges = self._column_bounds[bounds]
        draws = torch.rand((n, sum(widths)), generator=self.generator, dtype=torch.float64, device=self.device)
        pieces = split_columns(lows + ranges * draws, widths)
        return [piece if entry[2] is not None else piece[:, 0] for piece, entry in zip(pieces, bounds, strict=True)]

    def integers(self, low: int, high: int, size: Any = 1) -> Any:
        """Integers in [low, high) of shape ``size``."""
        import torch

        shape = self._shape(size)
        return torch.randint(int(low), int(high), shape, generator=self.generator, device=self.device)

    def exponential(self, scale: float = 1.0, size: Any = 1) -> Any:
        """Exponential draws of mean ``scale`` (> 0) of shape ``size``."""
        import torch

        draws = torch.empty(self._shape(size), dtype=torch.float64, device=self.device)
        return draws.exponential_(1.0 / scale, generator=self.generator)

    @property
    def state(self) -> Any:
        """The generator's state (a CPU byte tensor), for checkpoints: assign it back to restore the draws."""
        return self.generator.get_state()

    @state.setter
    def state(self, value: Any) -> None:
        self.generator.set_state(value)

    def __getstate__(self) -> dict[str, Any]:
        return {"device": str(self.device), "state": self.state}

    def __setstate__(self, saved: dict[str, Any]) -> None:
        self.__init__(0, saved["device"])
        self.state = saved["state"]


ColumnBounds = tuple[Any, Any, "int | None"]
"""One array of :func:`uniform_columns`: ``(low, high, width)``, floats (U[low, high) of shape (n, width), or (n,)
where width is None) or tuples of ``width`` floats (per column: an (n, width) array whose column j is U[low[j],
high[j]))."""


def _bounds_width(entry: ColumnBounds) -> int:
    """Columns one :data:`ColumnBounds` entry draws.

    Raises:
        ValueError: per-column bounds whose lengths differ from each other or from the width.
    """
    low, high, width = entry
    per_column = isinstance(low, tuple) or isinstance(high, tuple)
    if per_column and not (isinstance(low, tuple) and isinstance(high, tuple) and len(low) == len(high) == width):
        raise ValueError(f"per-column bounds need a low and a high of {width} entries each, got {low} and {high}")
    return 1 if width is None else int(width)


def _column_bounds(bounds: tuple[ColumnBounds, ...]) -> tuple[list[int], np.ndarray, np.ndarray]:
    """The widths of the arrays ``bounds`` describes, and every column's low and high (float64, in order)."""
    widths = [_bounds_width(entry) for entry in bounds]
    table = np.concatenate(  # (columns, 2): a row (low, high) per column
        [
            np.broadcast_to(np.asarray(entry[:2], dtype=np.float64).T, (width, 2))
            for entry, width in zip(bounds, widths, strict=True)
        ]
    )
    return widths, table[:, 0], table[:, 1]


def _numpy_uniform(rng: np.random.Generator, n: int, entry: ColumnBounds) -> np.ndarray:
    """One array of :func:`uniform_columns` from numpy's generator; per-column bounds one (n,) call per column."""
    _bounds_width(entry)  # refuses per-column bounds of another width
    low, high, width = entry
    if isinstance(low, tuple):
        return np.stack([rng.uniform(lo, hi, size=n) for lo, hi in zip(low, high, strict=True)], axis=1)
    return rng.uniform(low, high, size=n if width is None else (n, width))


def uniform_columns(rng: Any, n: int, bounds: tuple[ColumnBounds, ...]) -> list[Any]:
    """Uniform draws for ``n`` environments, one array per ``(low, high, width)`` of ``bounds``
    (:data:`ColumnBounds`). numpy's generator draws them one call after another, as ``rng.uniform(low, high, size)``
    would (per-column bounds: one (n,) call per column, stacked), so its stream is unchanged; a :class:`TorchRandom`
    draws them all at once, one (n, columns) array scaled per column (three operations on a device, not three per
    array)."""
    if isinstance(rng, np.random.Generator):
        return [_numpy_uniform(rng, n, entry) for entry in bounds]
    return rng.uniform_columns(n, bounds)  # checks the bounds where it first meets them


def random_generator(seed: int | None, reference: Any) -> Any:
    """The environments' random generator for arrays of ``reference``'s kind: ``numpy.random.default_rng(seed)`` for
    numpy (the host's draws, unchanged), :class:`TorchRandom` on a tensor's device."""
    if namespace(reference) is np:
        return np.random.default_rng(seed)
    return TorchRandom(seed, reference.device)


def generator_state(rng: Any) -> Any:
    """The state of a generator of :func:`random_generator` (numpy's bit-generator dict, or the torch state)."""
    return rng.bit_generator.state if isinstance(rng, np.random.Generator) else rng.state


def set_generator_state(rng: Any, state: Any) -> None:
    """Restore a :func:`generator_state` into a generator of the same kind."""
    if isinstance(rng, np.random.Generator):
        rng.bit_generator.state = state
    else:
        rng.state = state
