"""Which environments a reset writes, and how (:class:`ResetRows`): by index on the host, by mask on a device."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from margin_rl.arrays import ALL_ROWS, rows_of, write_where


@dataclass(frozen=True)
class ResetRows:
    """The environments a reset writes, and how: given ids (their rows computed and written by index: the host's
    resets, and any reset asked for), or a mask (every row computed, written in place where the mask holds: a
    device step's autoreset, with no host read and the same work and random draws every step)."""

    select: Any  # what reads the rows: the ids, or ALL_ROWS
    count: int  # rows computed (and random draws per quantity)
    mask: Any = None  # (N,) bool where written; None: the ids
    mask_rows: Any = None  # the mask as (N, 1), over the rows of a 2-D array (a view, made once per reset)

    @classmethod
    def at(cls, ids: Any) -> ResetRows:
        return cls(ids, int(ids.shape[0]))

    @classmethod
    def where(cls, mask: Any) -> ResetRows:
        return cls(ALL_ROWS, int(mask.shape[0]), mask, mask[:, None])

    @property
    def physics_rows(self) -> Any:
        """What the physics' reset takes: the ids, or the mask."""
        return self.select if self.mask is None else self.mask

    @property
    def forward_rows(self) -> Any:
        """What the physics' forward pass takes: the ids, or None (every simulation)."""
        return self.select if self.mask is None else None

    def of(self, array: Any) -> Any:
        """The rows of ``array`` the reset computes: ``array[ids]``, or by mask the whole array itself."""
        return rows_of(array, self.select)

    def write(self, target: Any, values: Any) -> None:
        """``target[rows] = values``, in place (``values``: ``count`` rows, or a scalar)."""
        if self.mask is None:
            target[self.select] = values
            return
        write_where(target, self.mask if target.ndim == 1 else self.mask_rows, values)
