"""Atomic writes: complete files or none, readable permissions, nothing left behind on failure."""

from __future__ import annotations

import stat
from pathlib import Path

import numpy as np
import pytest

from margin_rl.atomic import atomic_savez, atomic_write, atomic_write_text


def test_writes_complete_files_with_shared_permissions(tmp_path: Path) -> None:
    text = atomic_write_text(tmp_path / "sub" / "a.json", '{"x": 1}\n')
    assert text.read_text() == '{"x": 1}\n'
    assert stat.S_IMODE(text.stat().st_mode) == 0o644
    arrays = atomic_savez(tmp_path / "b.npz", lam=np.arange(3.0))
    with np.load(arrays) as data:
        np.testing.assert_array_equal(data["lam"], [0.0, 1.0, 2.0])
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a.json", "b.npz", "sub"]


def test_a_failing_writer_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    target = atomic_write_text(tmp_path / "c.txt", "old")

    def explode(f: object) -> None:
        f.write(b"partial")  # type: ignore[attr-defined]
        raise RuntimeError("killed mid-write")

    with pytest.raises(RuntimeError, match="mid-write"):
        atomic_write(target, explode)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["c.txt"]
