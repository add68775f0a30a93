r"""Resumable, sharded generation of the aSLIP state-action data set (paper §III).

Layout of an output directory::

    manifest.json        generation config (seed, shard size, model parameters, step size)
    shard_00000.npz ...  z (m, 4) = [y, xdot, alpha, delta_L]; status (m,) int8 (0 = valid);
                         next_apex (m, 3) = [dx, y1, xdot1] (NaN where invalid)
    margin.npz           margin (n,): oriented distance b of every sample (eq. 5)

Every file is written atomically (temporary file in the same directory, ``fsync``, then
``os.replace``), so an interrupted run leaves only complete files, and a rerun skips every
shard that is already present and well-formed.  Shard ``i`` draws its samples from
``SeedSequence(seed, spawn_key=(i,))``, so it is identical whatever ``n`` or ``--workers``
is; growing ``--n`` with the same seed and shard size extends a data set.

Margins are computed for *all* samples against trees built from all samples.  For a valid
sample :math:`b = d_{V^c}` only queries the invalid tree (and vice versa), which does not
contain the sample, so this is exactly the paper's "fresh sample" construction, just with
every sample also contributing to the trees.

CLI::

    python -m margin_rl.slip.dataset --out DIR --n 1000000 --shard-size 100000 --seed 0 --workers 2
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
import time
import zipfile
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from margin_rl.atomic import atomic_savez, atomic_write_bytes
from margin_rl.slip.dynamics import SlipParams, Status
from margin_rl.slip.margin import FailureMargin, label_samples, sample_box

__all__ = [
    "DatasetConfig",
    "GenerationSummary",
    "SlipDataset",
    "compute_margins",
    "generate_dataset",
    "load_dataset",
    "main",
]

FORMAT_VERSION = 1
_SHARD_KEYS = ("z", "status", "next_apex")


@dataclass(frozen=True)
class DatasetConfig:
    """What determines the samples; ``n`` may grow between runs, the rest may not change."""

    n: int
    shard_size: int = 100_000
    seed: int = 0
    dt: float = 0.01
    params: SlipParams = dataclasses.field(default_factory=SlipParams)

    def __post_init__(self) -> None:
        if self.n <= 0:
            raise ValueError(f"n must be positive; got {self.n}")
        if self.shard_size <= 0:
            raise ValueError(f"shard_size must be positive; got {self.shard_size}")
        if self.seed < 0:
            raise ValueError(f"seed must be non-negative; got {self.seed}")
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be positive; got {self.dt}")

    @property
    def n_shards(self) -> int:
        return -(-self.n // self.shard_size)

    def shard_len(self, index: int) -> int:
        """Number of samples in shard ``index``."""
        if not 0 <= index < self.n_shards:
            raise ValueError(f"shard index {index} out of range [0, {self.n_shards})")
        return min(self.shard_size, self.n - index * self.shard_size)

    def identity(self) -> dict[str, Any]:
        """The fields that fix the content of each shard (everything but ``n``)."""
        return {
            "format_version": FORMAT_VERSION,
            "shard_size": self.shard_size,
            "seed": self.seed,
            "dt": self.dt,
            "params": dataclasses.asdict(self.params),
        }


@dataclass(frozen=True)
class GenerationSummary:
    """What a call to :func:`generate_dataset` did."""

    out: Path
    n: int
    n_shards: int
    generated: tuple[int, ...]
    skipped: tuple[int, ...]
    seconds: float
    margin_recomputed: bool


@dataclass(frozen=True)
class SlipDataset:
    """All samples of a generated data set, concatenated in shard order."""

    z: NDArray[np.float64]
    status: NDArray[np.int8]
    next_apex: NDArray[np.float64]
    margin: NDArray[np.float64] | None

    @property
    def valid(self) -> NDArray[np.bool_]:
        return self.status == Status.OK

    def __len__(self) -> int:
        return int(self.z.shape[0])


# ---------------------------------------------------------------------------- atomic files


# ---------------------------------------------------------------------------- shards


def _shard_path(out: Path, index: int) -> Path:
    return out / f"shard_{index:05d}.npz"


def _generate_shard(config: DatasetConfig, index: int, out: Path) -> int:
    """Simulate shard ``index`` and write it atomically; returns its index."""
    rng = np.random.default_rng(np.random.SeedSequence(config.seed, spawn_key=(index,)))
    z = sample_box(config.shard_len(index), rng)
    res = label_samples(z, config.params, dt=config.dt)
    atomic_savez(
        _shard_path(out, index),
        z=z,
        status=res.status,
        next_apex=res.next_apex,
        shard_index=np.array(index),
        seed=np.array(config.seed),
    )
    return index


def _shard_ok(config: DatasetConfig, index: int, out: Path) -> bool:
    """True when the shard file exists, loads without pickle and has the expected content."""
    path = _shard_path(out, index)
    if not path.is_file():
        return False
    try:
        with np.load(path, allow_pickle=False) as data:
            m = config.shard_len(index)
            return (
                all(k in data.files for k in _SHARD_KEYS)
                and data["z"].shape == (m, 4)
                and data["status"].shape == (m,)
                and data["next_apex"].shape == (m, 3)
                and int(data["shard_index"]) == index
                and int(data["seed"]) == config.seed
            )
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # truncated: regenerate
        return False


def _read_manifest(out: Path) -> dict[str, Any] | None:
    path = out / "manifest.json"
    if not path.is_file():
        return None
    return json.loads(path.read_text())


def _shards_digest(config: DatasetConfig, out: Path) -> str:
    """Hash of all shard files, to tell whether ``margin.npz`` is stale."""
    h = hashlib.sha256()
    for i in range(config.n_shards):
        h.update(_shard_path(out, i).read_bytes())
    return h.hexdigest()


def generate_dataset(
    out: Path | str,
    config: DatasetConfig,
    *,
    workers: int = 1,
    margins: bool = True,
    log: bool = False,
) -> GenerationSummary:
    """Generate (or finish generating) the data set described by ``config`` in ``out``.

    Raises
    ------
    ValueError
        If ``out`` already holds a data set made with a different seed, shard size, step
        size or model parameters (mixing them would silently corrupt the sampling).
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1; got {workers}")
    t0 = time.perf_counter()
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest = _read_manifest(out_dir)
    if manifest is not None and manifest.get("identity") != config.identity():
        raise ValueError(
            f"{out_dir} holds a data set with a different configuration "
            f"({manifest.get('identity')}); choose another --out"
        )
    atomic_write_bytes(
        out_dir / "manifest.json",
        json.dumps({"identity": config.identity(), "n": config.n, "n_shards": config.n_shards}, indent=2).encode(),
    )

    todo = [i for i in range(config.n_shards) if not _shard_ok(config, i, out_dir)]
    skipped = tuple(i for i in range(config.n_shards) if i not in set(todo))
    if todo and workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for i in pool.map(_generate_shard, [config] * len(todo), todo, [out_dir] * len(todo)):
                if log:
                    print(f"shard {i} written", file=sys.stderr)
    else:
        for i in todo:
            _generate_shard(config, i, out_dir)
            if log:
                print(f"shard {i} written", file=sys.stderr)

    recomputed = False
    if margins:
        recomputed = compute_margins(out_dir, config, workers=workers)
    return GenerationSummary(
        out=out_dir,
        n=config.n,
        n_shards=config.n_shards,
        generated=tuple(todo),
        skipped=skipped,
        seconds=time.perf_counter() - t0,
        margin_recomputed=recomputed,
    )


_Arrays = tuple[NDArray[np.float64], NDArray[np.int8], NDArray[np.float64]]


def _load_shards(out: Path, n_shards: int) -> _Arrays:
    zs, ss, ns = [], [], []
    for i in range(n_shards):
        with np.load(_shard_path(out, i), allow_pickle=False) as data:
            zs.append(data["z"])
            ss.append(data["status"])
            ns.append(data["next_apex"])
    return np.concatenate(zs), np.concatenate(ss), np.concatenate(ns)


def compute_margins(out: Path | str, config: DatasetConfig, *, workers: int = 1) -> bool:
    """Write ``margin.npz`` (oriented distance of every sample) unless it is up to date.

    Returns True when it was (re)computed.
    """
    out_dir = Path(out)
    digest = _shards_digest(config, out_dir)
    path = out_dir / "margin.npz"
    if path.is_file():
        try:
            with np.load(path, allow_pickle=False) as data:
                if str(data["shards_sha256"]) == digest:
                    return False
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            pass
    z, status, _ = _load_shards(out_dir, config.n_shards)
    valid = status == Status.OK
    fm = FailureMargin.from_samples(z, valid)
    margin = fm.oriented_distance(z, valid, workers=workers)
    atomic_savez(path, margin=margin, shards_sha256=np.array(digest))
    return True


def load_dataset(out: Path | str) -> SlipDataset:
    """Load a generated data set (shards plus margins, if computed)."""
    out_dir = Path(out)
    manifest = _read_manifest(out_dir)
    if manifest is None:
        raise ValueError(f"{out_dir} has no manifest.json: not a data set directory")
    z, status, nxt = _load_shards(out_dir, int(manifest["n_shards"]))
    margin = None
    mpath = out_dir / "margin.npz"
    if mpath.is_file():
        with np.load(mpath, allow_pickle=False) as data:
            margin = np.asarray(data["margin"])
        if margin.shape != (z.shape[0],):
            margin = None  # stale: computed for another n
    return SlipDataset(z=z, status=status, next_apex=nxt, margin=margin)


# ---------------------------------------------------------------------------- CLI


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python -m margin_rl.slip.dataset", description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="output directory")
    ap.add_argument("--n", type=int, required=True, help="total number of state-action samples")
    ap.add_argument("--shard-size", type=int, default=100_000, help="samples per shard file")
    ap.add_argument("--seed", type=int, default=0, help="root seed")
    ap.add_argument("--workers", type=int, default=1, help="worker processes")
    ap.add_argument("--dt", type=float, default=0.01, help="stance RK4 step")
    ap.add_argument("--no-margin", action="store_true", help="skip the k-d tree margin stage")
    return ap.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry point; prints a JSON summary on stdout."""
    args = _parse(argv)
    config = DatasetConfig(n=args.n, shard_size=args.shard_size, seed=args.seed, dt=args.dt)
    summary = generate_dataset(args.out, config, workers=args.workers, margins=not args.no_margin, log=True)
    data = load_dataset(args.out)
    report = {
        "out": str(summary.out),
        "n": summary.n,
        "n_shards": summary.n_shards,
        "generated_shards": len(summary.generated),
        "skipped_shards": len(summary.skipped),
        "margin_recomputed": summary.margin_recomputed,
        "seconds": round(summary.seconds, 2),
        "valid_fraction": float(data.valid.mean()),
        "status_counts": {s.name: int(np.sum(data.status == s)) for s in Status},
    }
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
