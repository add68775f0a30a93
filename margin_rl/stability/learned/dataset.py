"""Analytic-margin datasets: states labelled with m_a, in resumable shards.

States are drawn from a named distribution (``--distribution``): ``table_i``, seed 000's Table I (the
default), or ``locomotion``, Table I widened to the states walking policies visit
(:data:`margin_rl.stability.analytic.sampling.LOCOMOTION`); the manifest records which.

Command line::

    python -m margin_rl.stability.learned.dataset generate --robot anymal_c --n 1000000 --out data/anymal_c
        [--workers 2]
    python -m margin_rl.stability.learned.dataset generate ... --ray auto          # the same tasks on a Ray cluster
    python -m margin_rl.stability.learned.dataset summary data/anymal_c
    python -m margin_rl.stability.learned.dataset pack data/anymal_c --out labels.npz    # labels only, ~16 B each
    python -m margin_rl.stability.learned.dataset unpack labels.npz --out data/anymal_c  # states redrawn, checked

``pack`` / ``unpack`` move a dataset labelled on another machine through a narrow channel: the labels travel, the
states (188 bytes a sample) are drawn again from the manifest's seeds and checked against each shard's checksum.

Layout of a dataset directory::

    manifest.json        robot, sampler version, distribution, seed, package version, analytic settings (with the
                         labelling path that made the labels: "batched" or "per_state"), shard size
    shard_00000.npz      lam (k, 47) float32, margin (k,) float32 [m] (NaN unless ok),
                         status (k,) int8 (index into STATUSES), n_lps (k,) int16, seconds (k,) float32,
                         extended (k,) float32 [m] the extended margin m_x (NaN only for unreachable feet
                         or a solver error), load_fraction (k,) float32 alpha*, source (k,) int8 (index
                         into margin_rl.stability.analytic.extended.SOURCES); format 1 shards have no m_x columns

A network is trained on one target (:func:`load_dataset`): ``"analytic"`` (m_a, the ``ok`` samples) or
``"extended"`` (m_x, every sample that has one: :mod:`margin_rl.stability.analytic.extended`).

Every shard is an independent task with its own seed (``SeedSequence(seed, spawn_key=(shard,))``), so
the dataset does not depend on the number of workers or on the order shards finish. A shard is
written to a temporary file and renamed into place, so a killed run loses at most the shards in
flight; rerunning the same command skips finished shards. A directory made with other settings is
refused rather than mixed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import multiprocessing
import os
import shlex
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np
from tqdm import tqdm

from margin_rl.atomic import atomic_savez, atomic_write, atomic_write_text
from margin_rl.provenance import sha256_file
from margin_rl.robot import available_robots
from margin_rl.stability.analytic.extended import (
    DEFAULT_BISECTION_STEPS,
    DEFAULT_LOAD_PENALTY,
    check_extended_settings,
    extended_margin_batch,
)
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM
from margin_rl.stability.analytic.margin import (
    LABELLING_PATHS,
    STATUSES,
    AnalyticSettings,
    worker_robot,
)
from margin_rl.stability.analytic.sampling import DISTRIBUTIONS, SAMPLER_VERSION, sample_around_states, sample_states

T = TypeVar("T")
R = TypeVar("R")

DISTRIBUTION_NAMES: tuple[str, ...] = (*DISTRIBUTIONS, "rollouts")
"""State distributions of a dataset: the named samplers, and "rollouts" (around recorded states)."""

MANIFEST = "manifest.json"
FORMAT_VERSION = 2  # 2: shards carry the extended margin m_x (extended, load_fraction, source)

TARGETS: tuple[str, ...] = ("analytic", "extended")
"""What a network learns from a dataset: m_a on ok samples, or m_x on every sample that has one."""


class DatasetError(ValueError):
    """A dataset directory or request that cannot be used as asked."""


@dataclass(frozen=True)
class DatasetSpec:
    """What defines a dataset; two runs with equal specs produce identical shards."""

    robot: str
    n: int
    shard_size: int
    seed: int
    settings: AnalyticSettings
    distribution: str = "table_i"  # a name of DISTRIBUTION_NAMES
    states: str | None = None  # "rollouts": the recorded lambdas (npz, key "lam") the states are drawn around
    states_sha256: str | None = None  # of that file, so that a dataset names exactly what it was drawn from
    load_penalty: float = DEFAULT_LOAD_PENALTY  # kappa of the extended margin [m]
    bisection_steps: int = DEFAULT_BISECTION_STEPS  # halvings for alpha* of the extended margin

    def __post_init__(self) -> None:
        try:  # the extended margin's own check, as a DatasetError
            check_extended_settings(self.load_penalty, self.bisection_steps, penalty_name="load_penalty")
        except ValueError as exc:
            raise DatasetError(str(exc)) from None
        if self.distribution not in DISTRIBUTION_NAMES:
            raise DatasetError(f"distribution must be one of {list(DISTRIBUTION_NAMES)}, got {self.distribution!r}")
        if (self.distribution == "rollouts") != (self.states is not None):
            raise DatasetError(
                "distribution 'rollouts' needs --states FILE.npz (recorded lambdas, e.g. from "
                "benchmarks/studies/bench_locomotion_distribution.py --states), and only it takes one"
            )

    @property
    def n_shards(self) -> int:
        return -(-self.n // self.shard_size)

    def shard_length(self, index: int) -> int:
        return min(self.shard_size, self.n - index * self.shard_size)

    def command(self, out: str | Path) -> str:
        """The command line that generates this dataset into ``out``."""
        friction = self.settings.friction
        friction_arg = friction if isinstance(friction, str) else f"{friction[0]}:{friction[1]}"
        return (
            f"python -m margin_rl.stability.learned.dataset generate --robot {self.robot} --n {self.n} "
            f"--out {shlex.quote(str(out))} --seed {self.seed} --shard-size {self.shard_size} "
            f"--friction {friction_arg} --focus-tol {self.settings.focus_tol} --labelling {self.settings.labelling} "
            f"--distribution {self.distribution}"
            + (f" --states {shlex.quote(self.states)}" if self.states else "")
            + f" --load-penalty {self.load_penalty} --bisection-steps {self.bisection_steps}"
        )

    def identity(self) -> dict[str, object]:
        """The fields that must match to resume or extend a directory (n may grow)."""
        return {
            "format_version": FORMAT_VERSION,
            "robot": self.robot,
            "sampler_version": SAMPLER_VERSION,
            "distribution": self.distribution,
            **({"states_sha256": self.states_sha256} if self.states else {}),
            "seed": self.seed,
            "shard_size": self.shard_size,
            "analytic_settings": self.settings.as_dict(),
            "extended_margin": {"load_penalty": self.load_penalty, "bisection_steps": self.bisection_steps},
        }


def shard_path(out: Path, index: int) -> Path:
    return out / f"shard_{index:05d}.npz"


def shard_states(spec: DatasetSpec, index: int) -> np.ndarray:
    """The states (k, 47) of shard ``index``: drawn from its own seed, so any machine can draw them again."""
    robot = worker_robot(spec.robot)
    seed = np.random.SeedSequence(spec.seed, spawn_key=(index,))
    if spec.distribution == "rollouts":
        with np.load(spec.states) as recorded:
            return sample_around_states(robot, recorded["lam"], spec.shard_length(index), seed=seed)
    return sample_states(robot, spec.shard_length(index), seed=seed, table=DISTRIBUTIONS[spec.distribution])


def make_shard(spec: DatasetSpec, index: int, out: Path) -> dict[str, int]:
    """Sample, label and write shard ``index``; returns its status counts. Runs in a worker."""
    robot = worker_robot(spec.robot)
    lams = shard_states(spec, index)
    labels = extended_margin_batch(
        robot, lams, spec.settings, workers=1, penalty=spec.load_penalty, bisection_steps=spec.bisection_steps
    )
    analytic = labels.analytic
    atomic_savez(
        shard_path(out, index),
        lam=lams.astype(np.float32),
        margin=analytic.margin.astype(np.float32),
        status=analytic.status,
        n_lps=analytic.n_lps,
        seconds=analytic.seconds.astype(np.float32),
        extended=labels.margin.astype(np.float32),
        load_fraction=labels.load_fraction.astype(np.float32),
        source=labels.source,
    )
    return analytic.counts()


def _shard_is_complete(path: Path, length: int) -> bool:
    if not path.is_file():
        return False
    try:
        with np.load(path) as data:
            return data["lam"].shape == (length, LAMBDA_DIM) and data["status"].shape == (length,)
    except Exception:  # a truncated or foreign file: regenerate it
        return False


def _prepare(spec: DatasetSpec, out: Path, command: str) -> list[int]:
    """Create or check the manifest; return the shards still to do."""
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / MANIFEST
    identity = spec.identity()
    if manifest_path.is_file():
        old = json.loads(manifest_path.read_text())
        if isinstance(old.get("analytic_settings"), dict):
            # Manifests written before the labelling path was recorded name none: theirs was per state.
            old["analytic_settings"] = AnalyticSettings.from_dict(old["analytic_settings"]).as_dict()
        old.setdefault("distribution", "table_i")  # manifests from before distributions were named
        mismatched = [k for k, v in identity.items() if old.get(k) != v]
        if mismatched:
            details = "; ".join(f"{k}: {old.get(k)!r} there, {identity[k]!r} asked" for k in mismatched)
            hint = ""
            old_path = (old.get("analytic_settings") or {}).get("labelling")
            if mismatched == ["analytic_settings"] and old_path != spec.settings.labelling:
                hint = f" (to resume it with the path that labelled it, pass --labelling {old_path})"
            raise DatasetError(f"{out} holds a dataset with other settings ({details}){hint}; use another --out")
        if spec.n < old.get("n", 0):
            # A smaller n would rewrite its last shard shorter and orphan the rest.
            raise DatasetError(f"{out} already holds n={old['n']} samples; ask for at least that many to resume")
        # A larger n extends the dataset: a partial last shard is regenerated at full length from its
        # own seed, and new shards are added.
    # Lazy: the version is defined by the top-level package, which imports every layer (envs too).
    from margin_rl import __version__

    manifest = {
        **identity,
        "n": spec.n,
        "n_shards": spec.n_shards,
        "package_version": __version__,
        "statuses": list(STATUSES),
        "fields": {
            "lam": f"(k, {LAMBDA_DIM}) float32, layout margin_rl.stability.LAMBDA_FIELDS",
            "margin": "(k,) float32 analytic margin m_a [m], NaN unless status is ok",
            "status": "(k,) int8 index into statuses",
            "n_lps": "(k,) int16 conic programs solved",
            "seconds": "(k,) float32 wall time of the analytic margin",
            "extended": "(k,) float32 extended margin m_x [m] (margin_rl.stability.analytic.extended), NaN where none",
            "load_fraction": "(k,) float32 alpha*: the supportable fraction of the dynamic load (NaN: fallback)",
            "source": "(k,) int8 index into margin_rl.stability.analytic.extended.SOURCES",
        },
        "command": command,
    }
    atomic_write_text(manifest_path, json.dumps(manifest, indent=2) + "\n")
    return [i for i in range(spec.n_shards) if not _shard_is_complete(shard_path(out, i), spec.shard_length(i))]


def _unordered(function: Callable[[T], R], tasks: Sequence[T], workers: int) -> Iterator[R]:
    """``function`` over ``tasks`` in this process (``workers == 1``) or a fork pool; results as they finish.

    Closing the iterator (an error in the consumer or a task) ends the pool and its tasks in flight.
    """
    if workers == 1:
        yield from map(function, tasks)
        return
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        # imap_unordered: a shard's result arrives as soon as it is written, whatever the order.
        yield from pool.imap_unordered(function, tasks)


def _local_tasks(spec: DatasetSpec, todo: Sequence[int], out: Path, workers: int) -> Iterator[tuple[int, dict]]:
    return _unordered(_make_shard_star, [(spec, i, out) for i in todo], workers)


def _make_shard_star(args: tuple[DatasetSpec, int, Path]) -> tuple[int, dict[str, int]]:
    spec, index, out = args
    return index, make_shard(spec, index, out)


def _ray_tasks(spec: DatasetSpec, todo: Sequence[int], out: Path, address: str) -> Iterator[tuple[int, dict]]:
    try:
        import ray  # lazy: an optional dependency (margin_rl[ray]), needed only with --ray
    except ImportError as exc:
        raise DatasetError("--ray needs Ray: pip install 'margin_rl[ray]'") from exc
    started = not ray.is_initialized()
    if started:
        ray.init(address=None if address == "local" else address, ignore_reinit_error=True, log_to_driver=False)
    try:
        remote = ray.remote(_make_shard_star)
        # Shards are written by the workers to `out`, which must be a shared path on a real cluster.
        pending = {remote.remote((spec, i, out)): i for i in todo}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                pending.pop(ref)
                yield ray.get(ref)
    finally:
        if started:
            ray.shutdown()


def generate(
    spec: DatasetSpec,
    out: str | Path,
    workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = True,
    command: str = "",
) -> dict[str, int]:
    """Generate (or finish) a dataset; returns the status counts of the shards made in this call."""
    out = Path(out)
    if spec.robot not in available_robots():
        raise DatasetError(f"unknown robot {spec.robot!r}; available robots: {', '.join(available_robots())}")
    if spec.n <= 0 or spec.shard_size <= 0:
        raise DatasetError(f"n and shard size must be positive, got n={spec.n}, shard size={spec.shard_size}")
    todo = _prepare(spec, out, command or spec.command(out))
    workers = (os.cpu_count() or 1) if workers is None else workers
    if workers < 1:
        raise DatasetError(f"workers must be >= 1, got {workers}")
    total_todo = sum(spec.shard_length(i) for i in todo)
    counts = dict.fromkeys(STATUSES, 0)
    skipped = spec.n_shards - len(todo)
    if not todo:
        _log(progress, f"{out}: all {spec.n_shards} shards already present")
        return counts
    _log(progress, f"{out}: {len(todo)} shards to make ({total_todo} samples), {skipped} already present")
    tasks: Iterable[tuple[int, dict]] = (
        _ray_tasks(spec, todo, out, ray_address) if ray_address else _local_tasks(spec, todo, out, workers)
    )
    bar = _progress_bar(total_todo, progress)
    for index, shard_counts in tasks:
        for k, v in shard_counts.items():
            counts[k] += v
        bar.update(spec.shard_length(index))
        bar.set_postfix(ok=f"{counts['ok'] / max(1, sum(counts.values())):.0%}")
    bar.close()
    _log(progress, "status counts: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    return counts


def _progress_bar(total: int, enabled: bool):
    return tqdm(total=total, unit="sample", unit_scale=True, smoothing=0.05, disable=not enabled, file=sys.stderr)


def _log(enabled: bool, message: str) -> None:
    if enabled:
        print(message, file=sys.stderr, flush=True)


LABEL_FIELDS: tuple[str, ...] = ("margin", "status", "n_lps", "seconds", "extended", "load_fraction", "source")
"""The per-sample columns of a shard other than ``lam``: what a label pack carries."""

STATE_TOLERANCE = 1e-5
"""Largest |row sum| difference of a re-drawn shard's states accepted when its checksum differs (float32 rounding
of another machine's numpy or CPU); a re-drawn state that differs more is refused."""


@dataclass(frozen=True)
class LabelPack:
    """What :func:`pack_labels` wrote or :func:`unpack_labels` restored."""

    path: Path
    first_shard: int
    shards: int
    samples: int
    exact_shards: int = 0  # unpack: shards whose re-drawn states are bit-identical to the labelled ones
    max_row_sum_deviation: float = 0.0  # unpack: largest |row sum| difference over the other shards


def spec_from_manifest(manifest: dict, n: int, states: str | None = None) -> DatasetSpec:
    """The :class:`DatasetSpec` of a manifest, with ``n`` samples (``states``: the rollouts' file on this machine)."""
    extended = manifest.get("extended_margin", {})
    return DatasetSpec(
        robot=manifest["robot"],
        n=n,
        shard_size=manifest["shard_size"],
        seed=manifest["seed"],
        settings=AnalyticSettings.from_dict(manifest["analytic_settings"]),
        distribution=manifest.get("distribution", "table_i"),
        states=states,
        states_sha256=sha256_file(states) if states else None,
        load_penalty=extended.get("load_penalty", DEFAULT_LOAD_PENALTY),
        bisection_steps=extended.get("bisection_steps", DEFAULT_BISECTION_STEPS),
    )


def _row_sums(lam: np.ndarray) -> np.ndarray:
    return lam.astype(np.float64).sum(axis=1).astype(np.float32)


def _lam_checksum(lam: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(lam, dtype=np.float32).tobytes()).hexdigest()


def pack_labels(dataset: str | Path, out: str | Path, first_shard: int = 0, max_shards: int | None = None) -> LabelPack:
    """Write the labels of a dataset's complete shards, without their states, to one compressed ``.npz``.

    A shard's states cost 188 bytes a sample and its labels about 20: where a dataset is labelled on a machine
    whose results come back through a narrow channel, only the labels travel, and :func:`unpack_labels` draws
    the states again from the manifest's seeds (:func:`shard_states`). Each shard's state checksum and every
    state's row sum travel too, so that unpacking proves it drew the states that were labelled.

    The pack holds the consecutive complete shards from ``first_shard`` (at most ``max_shards``); a shard in
    flight or missing ends it, so a run stopped at any moment packs what it finished.
    """
    dataset, out = Path(dataset), Path(out)
    manifest_path = dataset / MANIFEST
    if not manifest_path.is_file():
        raise DatasetError(f"{dataset} is not a margin_rl dataset (no {MANIFEST})")
    manifest = json.loads(manifest_path.read_text())
    if manifest.get("format_version") != FORMAT_VERSION:
        raise DatasetError(f"{dataset}: only format {FORMAT_VERSION} datasets can be packed")
    size, total = manifest["shard_size"], manifest["n"]
    if first_shard < 0 or (max_shards is not None and max_shards < 1):
        raise DatasetError(f"first_shard must be >= 0 and max_shards >= 1, got {first_shard}, {max_shards}")
    columns: dict[str, list[np.ndarray]] = {name: [] for name in (*LABEL_FIELDS, "row_sum")}
    checksums: list[str] = []
    index = first_shard
    while index * size < total and (max_shards is None or len(checksums) < max_shards):
        length = min(size, total - index * size)
        if not _shard_is_complete(shard_path(dataset, index), length):
            break
        with np.load(shard_path(dataset, index)) as data:
            for name in LABEL_FIELDS:
                columns[name].append(data[name])
            columns["row_sum"].append(_row_sums(data["lam"]))
            checksums.append(_lam_checksum(data["lam"]))
        index += 1
    if not checksums:
        raise DatasetError(f"{dataset}: shard {first_shard} is not complete; nothing to pack")
    atomic_write(
        out,
        lambda f: np.savez_compressed(
            f,
            manifest=np.array(json.dumps(manifest)),
            first_shard=np.array(first_shard),
            lam_sha256=np.array(checksums),
            **{name: np.concatenate(parts) for name, parts in columns.items()},
        ),
    )
    samples = sum(len(part) for part in columns["margin"])
    return LabelPack(path=out, first_shard=first_shard, shards=len(checksums), samples=samples)


def unpack_labels(
    pack: str | Path, out: str | Path, states: str | Path | None = None, workers: int = 1, progress: bool = True
) -> LabelPack:
    """Restore the shards of a :func:`pack_labels` file into the dataset directory ``out``, drawing their states.

    The dataset's manifest is the packed one with ``n`` covering the packed shards, so the directory is what
    ``generate`` would have written here (its command is recorded); packs of one dataset unpack into the same
    directory in the order of their shards. A ``rollouts`` dataset needs ``states``, the recorded states it was
    drawn around (the same file: its checksum is compared). A re-drawn shard must match its checksum, or, where
    another machine's floating point rounds differently, every state's row sum within :data:`STATE_TOLERANCE`;
    otherwise the shard is refused (nothing is written for it) with the deviation it found.
    """
    pack, out = Path(pack), Path(out)
    with np.load(pack) as data:
        manifest = json.loads(str(data["manifest"]))
        first = int(data["first_shard"])
        checksums = [str(c) for c in data["lam_sha256"]]
        columns = {name: data[name] for name in (*LABEL_FIELDS, "row_sum")}
    size = manifest["shard_size"]
    n = min(manifest["n"], (first + len(checksums)) * size)
    existing = Path(out) / MANIFEST
    if existing.is_file():  # a later pack of the same dataset was restored first: keep its larger n
        n = max(n, int(json.loads(existing.read_text()).get("n", 0)))
    spec = spec_from_manifest(manifest, n, str(states) if states is not None else None)
    if spec.states_sha256 != manifest.get("states_sha256"):
        raise DatasetError(
            f"{pack} was drawn around states with sha256 {manifest.get('states_sha256')}; "
            f"{states} has {spec.states_sha256}: pass the recorded states file it was labelled from"
        )
    todo = set(_prepare(spec, Path(out), spec.command(out)))
    offsets = np.cumsum([0] + [spec.shard_length(first + k) for k in range(len(checksums))])
    tasks = [
        (
            spec,
            first + k,
            Path(out),
            checksums[k],
            {name: col[offsets[k] : offsets[k + 1]] for name, col in columns.items()},
        )
        for k in range(len(checksums))
        if first + k in todo
    ]
    exact, deviation = 0, 0.0
    bar = _progress_bar(int(offsets[-1]), progress)
    try:
        for is_exact, shard_deviation, length in _unordered(_restore_shard, tasks, workers):
            exact += is_exact
            deviation = max(deviation, shard_deviation)
            bar.update(length)
    finally:
        bar.close()
    return LabelPack(
        path=Path(out),
        first_shard=first,
        shards=len(checksums),
        samples=int(offsets[-1]),
        exact_shards=exact + len(checksums) - len(tasks),
        max_row_sum_deviation=deviation,
    )


def _first_shard_of_pack(path: str | Path) -> int:
    with np.load(path) as data:
        if "first_shard" not in data:
            raise DatasetError(f"{path} is not a label pack (made by `dataset pack`)")
        return int(data["first_shard"])


def _restore_shard(task: tuple[DatasetSpec, int, Path, str, dict[str, np.ndarray]]) -> tuple[bool, float, int]:
    spec, index, out, checksum, labels = task
    lam = shard_states(spec, index).astype(np.float32)
    exact = _lam_checksum(lam) == checksum
    deviation = 0.0
    if not exact:
        deviation = (
            float(np.max(np.abs(_row_sums(lam) - labels["row_sum"]))) if len(lam) == len(labels["row_sum"]) else np.inf
        )
        if not deviation <= STATE_TOLERANCE:
            raise DatasetError(
                f"shard {index}: the states drawn here differ from the labelled ones (row sums by up to "
                f"{deviation:.3g}, tolerance {STATE_TOLERANCE}); unpack with the package version that labelled it"
            )
    atomic_savez(shard_path(out, index), lam=lam, **{name: labels[name] for name in LABEL_FIELDS})
    return exact, deviation, len(lam)


@dataclass(frozen=True)
class Dataset:
    """The samples of a dataset directory that have the requested target, plus what was excluded."""

    lam: np.ndarray  # (N, 47) float32
    margin: np.ndarray  # (N,) float32 [m]: m_a ("analytic") or m_x ("extended")
    counts: dict[str, int]  # status counts over all loaded shards
    manifest: dict[str, object]
    target: str = "analytic"
    analytic: np.ndarray | None = None  # (N,) float32 m_a of the returned samples (NaN where not ok)


def load_dataset(path: str | Path, max_samples: int | None = None, target: str = "analytic") -> Dataset:
    """Load the samples of a dataset directory that have ``target`` (others are counted, not returned).

    ``target="analytic"``: the ``ok`` samples and m_a; ``"extended"``: every sample with a finite m_x
    (ok, infeasible and no-contact states alike), which needs a format-2 dataset.
    """
    if target not in TARGETS:
        raise DatasetError(f"target must be one of {list(TARGETS)}, got {target!r}")
    path = Path(path)
    manifest_path = path / MANIFEST
    if not manifest_path.is_file():
        raise DatasetError(f"{path} is not a margin_rl dataset (no {MANIFEST})")
    manifest = json.loads(manifest_path.read_text())
    lams, margins, analytic = [], [], []
    counts = dict.fromkeys(manifest.get("statuses", STATUSES), 0)
    n_loaded = 0
    for shard in sorted(path.glob("shard_*.npz")):
        with np.load(shard) as data:
            status = data["status"]
            for i, name in enumerate(STATUSES):
                counts[name] += int(np.sum(status == i))
            if target == "extended":
                if "extended" not in data:
                    raise DatasetError(
                        f"{shard} has no extended margin (a format-1 dataset): train it with target 'analytic', "
                        "or label a new dataset with this version"
                    )
                values = data["extended"]
                keep = np.isfinite(values)
            else:
                values = data["margin"]
                keep = status == STATUSES.index("ok")
            lams.append(data["lam"][keep])
            margins.append(values[keep])
            analytic.append(np.where(status == STATUSES.index("ok"), data["margin"], np.nan)[keep])
            n_loaded += int(keep.sum())
        if max_samples is not None and n_loaded >= max_samples:
            break
    if not lams:
        raise DatasetError(f"{path} has no shards yet")
    lam, margin, analytic_margin = np.concatenate(lams), np.concatenate(margins), np.concatenate(analytic)
    if max_samples is not None:
        lam, margin, analytic_margin = lam[:max_samples], margin[:max_samples], analytic_margin[:max_samples]
    return Dataset(lam=lam, margin=margin, counts=counts, manifest=manifest, target=target, analytic=analytic_margin)


def _parse_friction(text: str) -> str | tuple[str, int]:
    if text == "cone":
        return "cone"
    if text.startswith("pyramid:"):
        return ("pyramid", int(text.split(":", 1)[1]))
    raise argparse.ArgumentTypeError(f"friction must be 'cone' or 'pyramid:K', got {text!r}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m margin_rl.stability.learned.dataset", description=__doc__.split("\n\n")[0]
    )
    sub = parser.add_subparsers(dest="command", required=True)
    gen = sub.add_parser("generate", help="generate or resume a dataset")
    gen.add_argument("--robot", required=True, choices=available_robots())
    gen.add_argument("--n", type=int, required=True, help="number of samples")
    gen.add_argument("--out", required=True, help="dataset directory")
    gen.add_argument("--seed", type=int, default=0)
    gen.add_argument("--shard-size", type=int, default=5000)
    gen.add_argument("--workers", type=int, default=None, help="local processes (default: all cores)")
    gen.add_argument("--ray", default=None, metavar="ADDRESS", help="run on Ray: 'auto', 'local' or an address")
    gen.add_argument("--friction", type=_parse_friction, default="cone", help="'cone' or 'pyramid:K'")
    gen.add_argument("--focus-tol", type=float, default=AnalyticSettings().focus_tol, help="margin bracket [m]")
    gen.add_argument(
        "--labelling",
        choices=LABELLING_PATHS,
        default=AnalyticSettings().labelling,
        help="labelling path: 'batched' (states together, re-used solver structure) or 'per_state' (the reference)",
    )
    gen.add_argument(
        "--distribution",
        choices=DISTRIBUTION_NAMES,
        default="table_i",
        help="state distribution: 'table_i' (seed 000's Table I), 'locomotion' (Table I widened to walking-policy "
        "states) or 'rollouts' (around the recorded states of --states)",
    )
    gen.add_argument("--states", default=None, help="'rollouts': npz of recorded lambdas (key 'lam')")
    gen.add_argument(
        "--load-penalty", type=float, default=DEFAULT_LOAD_PENALTY, help="kappa of the extended margin m_x [m]"
    )
    gen.add_argument(
        "--bisection-steps", type=int, default=DEFAULT_BISECTION_STEPS, help="halvings for m_x's load fraction"
    )
    gen.add_argument("--quiet", action="store_true")
    summ = sub.add_parser("summary", help="print the manifest and status counts of a dataset")
    summ.add_argument("path")
    pk = sub.add_parser("pack", help="the labels of a dataset's complete shards, without their states, in one file")
    pk.add_argument("path", help="dataset directory")
    pk.add_argument("--out", required=True, help="pack file (.npz)")
    pk.add_argument("--first-shard", type=int, default=0)
    pk.add_argument("--max-shards", type=int, default=None, help="split a large dataset into several packs")
    up = sub.add_parser("unpack", help="restore a pack's shards, drawing their states again from the seeds")
    up.add_argument("pack", nargs="+", help="pack files of one dataset (restored in the order of their shards)")
    up.add_argument("--out", required=True, help="dataset directory")
    up.add_argument("--states", default=None, help="'rollouts': the recorded states file the dataset was drawn around")
    up.add_argument("--workers", type=int, default=1)
    up.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)

    if args.command in ("pack", "unpack"):
        try:
            if args.command == "pack":
                packed = pack_labels(args.path, args.out, first_shard=args.first_shard, max_shards=args.max_shards)
                print(
                    f"{packed.path}: shards {packed.first_shard}-{packed.first_shard + packed.shards - 1}, "
                    f"{packed.samples} samples"
                )
                return 0
            missing = [f for f in args.pack if not Path(f).is_file()]
            if missing:
                raise DatasetError(f"no such pack file: {', '.join(missing)}")
            order = sorted(args.pack, key=_first_shard_of_pack)
            for pack in order:
                restored = unpack_labels(
                    pack, args.out, states=args.states, workers=args.workers, progress=not args.quiet
                )
                print(
                    f"{pack} -> {restored.path}: {restored.shards} shards, {restored.samples} samples, "
                    f"{restored.exact_shards} drawn bit-identically, largest row-sum deviation "
                    f"{restored.max_row_sum_deviation:.2g}"
                )
        except DatasetError as exc:
            parser.error(str(exc))
        return 0

    if args.command == "summary":
        ds = load_dataset(args.path)
        print(json.dumps({k: v for k, v in ds.manifest.items() if k != "fields"}, indent=2))
        total = sum(ds.counts.values())
        print(f"{total} samples: " + ", ".join(f"{k} {v} ({v / max(total, 1):.1%})" for k, v in ds.counts.items()))
        if len(ds.margin):
            m = ds.margin
            print(f"ok margins [m]: mean {m.mean():.4f}, std {m.std():.4f}, stable (m >= 0) {np.mean(m >= 0):.1%}")
        return 0

    spec = DatasetSpec(
        robot=args.robot,
        n=args.n,
        shard_size=args.shard_size,
        seed=args.seed,
        settings=AnalyticSettings(friction=args.friction, focus_tol=args.focus_tol, labelling=args.labelling),
        distribution=args.distribution,
        states=args.states,
        states_sha256=sha256_file(args.states) if args.states else None,
        load_penalty=args.load_penalty,
        bisection_steps=args.bisection_steps,
    )
    arguments = " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]))
    command = f"python -m margin_rl.stability.learned.dataset {arguments}"
    try:
        generate(spec, args.out, workers=args.workers, ray_address=args.ray, progress=not args.quiet, command=command)
    except DatasetError as exc:
        parser.error(str(exc))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
