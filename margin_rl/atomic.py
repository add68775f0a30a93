"""Atomic file writes: a reader or a killed writer never sees a partial file.

Every writer of datasets, weights, cards, checkpoints and run files goes through :func:`atomic_write`:
the content goes to a temporary file in the target's folder (same file system), is flushed and
fsync'ed, made readable by everyone (0644; ``mkstemp`` creates 0600) and moved into place with
``os.replace``. On any error the temporary file is removed and the target is untouched.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np


def atomic_write(path: str | Path, write: Callable[[BinaryIO], None]) -> Path:
    """Write ``path`` through ``write(file)`` (binary), atomically; creates missing parent folders."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o644)
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """``data`` to ``path``, atomically."""
    return atomic_write(path, lambda f: f.write(data))


def atomic_write_text(path: str | Path, text: str) -> Path:
    """UTF-8 ``text`` to ``path``, atomically."""
    return atomic_write_bytes(path, text.encode())


def atomic_savez(path: str | Path, **arrays: Any) -> Path:
    """:func:`numpy.savez` (no pickled objects) to ``path``, atomically.

    Writing to a file object keeps numpy from appending ``.npz`` to the temporary name.
    """
    return atomic_write(path, lambda f: np.savez(f, **arrays))
