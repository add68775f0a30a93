"""Warp kernels compiled ahead of time, on a machine without a GPU, for the GPU that will run them.

MuJoCo Warp generates its kernels at run time, per model and options (a kernel factory per geometry pair, solver
size, tile shape), and Warp compiles each *module* (a set of kernels) at its first launch: minutes of a GPU machine's
time before its first step. This module records the modules an environment launches, by stepping it on Warp's CPU
device, and compiles each for a named GPU architecture into a kernel cache laid out as Warp's own
(``<cache>/<warp version>/<module id>/<module id>.sm90.cubin`` / ``.ptx`` beside its ``.meta``), which
``WARP_CACHE_PATH=<cache>`` points Warp at on the GPU machine, where those modules then load instead of compiling.

What a module is compiled with, and why both formats: a module's id hashes its kernels' code and its block size
(threads per block). A GPU launches a kernel with the block size its launch asks for, or 256 where it asks none
(Warp's CUDA default); on the CPU Warp launches every kernel with one thread per block, so the sizes asked for are
recorded where the launches are made (``wp.launch``, ``wp.launch_tiled``), before Warp resolves them. Warp loads a
``.ptx`` where the GPU's driver is at least as new as Warp's CUDA toolkit, a ``.cubin`` otherwise: which one a
machine takes is known only there, so both are written by default.

What cannot be compiled ahead here: kernels MuJoCo Warp builds only when it runs on a GPU (it picks some kernels and
block sizes by device: its solver's conditional graph loops, block sizes from the GPU's multiprocessor count), and
modules whose code needs the GPU's math libraries at compile time on a block size the CPU run used (a tile Cholesky
on one thread per block). They compile at their first launch on the GPU, as without a cache; the report lists what
failed and why.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

CUDA_DEFAULT_BLOCK_DIM = 256
"""Threads per block of a CUDA launch that asks for none (Warp's default)."""

FORMATS = ("cubin", "ptx")
"""The compiled forms Warp loads on a GPU: a ``.cubin`` for one architecture, or ``.ptx`` its driver compiles."""


@dataclass(frozen=True)
class ModuleVariant:
    """A Warp module as a GPU would launch it: the module, and the block size of its launches."""

    module: Any  # warp's Module
    block_dim: int


@dataclass(frozen=True)
class CompiledModule:
    """One module variant compiled ahead: its cache id, the files written, the seconds it took, or why it failed."""

    name: str
    block_dim: int
    identifier: str  # the cache folder's name: wp_<module>_<hash>
    files: tuple[str, ...]  # relative to the cache's folder of this Warp version
    seconds: float
    error: str | None = None


@dataclass(frozen=True)
class KernelCacheReport:
    """What :func:`compile_ahead` compiled into a kernel cache."""

    cache_dir: str
    arch: int | None  # the GPU architecture (90: sm_90, H100 and H200); None: Warp's CPU device
    formats: tuple[str, ...]
    modules: tuple[CompiledModule, ...]
    seconds: float
    kernels: int  # kernels in the modules compiled (a module compiled at two block sizes counted once)
    size_mib: float = field(default=0.0)  # the whole cache folder, this and earlier compiles

    @property
    def failed(self) -> tuple[CompiledModule, ...]:
        return tuple(m for m in self.modules if m.error is not None)

    def to_json(self) -> dict[str, Any]:
        report = asdict(self)
        report["failed"] = len(self.failed)
        return report


def _launch_block_dim(requested: Any) -> int:
    """The block size a GPU resolves a launch's request to (Warp's rule: none or <= 0 -> its default)."""
    return CUDA_DEFAULT_BLOCK_DIM if requested is None or int(requested) <= 0 else int(requested)


@contextmanager
def recording_launches() -> Iterator[list[ModuleVariant]]:
    """Record every Warp launch made within the block (eager, or recorded into a graph): its kernel's module and the
    block size a GPU would launch it with, each variant once, in launch order, in the list this yields, which is
    filled when the block ends."""
    import warp as wp
    import warp._src.context as context

    seen: dict[tuple[int, int], ModuleVariant] = {}
    launch, launch_tiled = context.launch, context.launch_tiled

    def note(kernel: Any, block_dim: int) -> None:
        seen.setdefault((id(kernel.module), block_dim), ModuleVariant(kernel.module, block_dim))

    inside_tiled = [False]  # launch_tiled forwards to launch with the size it resolved for the device (1 on a CPU)

    def recorded_launch(kernel: Any, dim: Any, *args: Any, block_dim: Any = None, **kwargs: Any) -> Any:
        if not inside_tiled[0]:
            note(kernel, _launch_block_dim(block_dim))
        return launch(kernel, dim, *args, block_dim=block_dim, **kwargs)

    def recorded_launch_tiled(*args: Any, **kwargs: Any) -> Any:
        note(args[0] if args else kwargs["kernel"], _launch_block_dim(kwargs.get("block_dim")))
        inside_tiled[0] = True
        try:
            return launch_tiled(*args, **kwargs)
        finally:
            inside_tiled[0] = False

    variants: list[ModuleVariant] = []
    context.launch, context.launch_tiled = recorded_launch, recorded_launch_tiled
    wp.launch, wp.launch_tiled = recorded_launch, recorded_launch_tiled
    try:
        yield variants
    finally:
        context.launch, context.launch_tiled = launch, launch_tiled
        wp.launch, wp.launch_tiled = launch, launch_tiled
        variants.extend(seen.values())


def record_launches(run: Callable[[], None]) -> list[ModuleVariant]:
    """The module variants ``run()`` launches (see :func:`recording_launches`)."""
    with recording_launches() as variants:
        run()
    return variants


@contextmanager
def counting_compiles() -> Iterator[list[tuple[str, float]]]:
    """Within the block, every Warp module compiled (not loaded from the kernel cache) adds (its name, the seconds
    its compile took) to the list this yields: how many modules a cache compiled ahead left to compile."""
    import warp._src.context as context

    compile_module = context.Module._compile
    compiled: list[tuple[str, float]] = []

    def counted(module: Any, *args: Any, **kwargs: Any) -> bool:
        began = time.perf_counter()
        done = compile_module(module, *args, **kwargs)
        if done:
            compiled.append((module.name, time.perf_counter() - began))
        return done

    context.Module._compile = counted
    try:
        yield compiled
    finally:
        context.Module._compile = compile_module


def compile_ahead(
    variants: list[ModuleVariant],
    cache_dir: str | os.PathLike[str],
    arch: int | None = 90,
    formats: tuple[str, ...] = FORMATS,
) -> KernelCacheReport:
    """Compile ``variants`` into the kernel cache ``cache_dir`` for GPU architecture ``arch`` (90: sm_90) in
    ``formats``, or, with ``arch`` None, for Warp's CPU device (one thread per block, as Warp launches there: how
    the cache is checked without a GPU). A module already in the cache is kept; one that fails to compile is
    reported, and the others go on.

    Raises:
        ValueError: an unknown format, or no format.
    """
    import warp as wp

    unknown = [f for f in formats if f not in FORMATS]
    if unknown or not formats:
        raise ValueError(f"formats must be some of {FORMATS}, got {formats}")
    wp.init()
    cache = Path(cache_dir) / wp.config.version  # where Warp looks under WARP_CACHE_PATH
    cache.mkdir(parents=True, exist_ok=True)
    cpu = wp.get_device("cpu") if arch is None else None
    targets = [(None, "o")] if arch is None else [(f == "ptx", f) for f in formats]
    unique = {(id(v.module), 1 if arch is None else v.block_dim): v.module for v in variants}
    compiled, start = [], time.perf_counter()
    for (_, block_dim), module in unique.items():
        began = time.perf_counter()
        module.get_module_hash(block_dim)  # resolves the options of this block size
        options, identifier = module.resolved_options[block_dim], module.get_module_identifier(block_dim)
        files, error = [], None
        for use_ptx, suffix in targets:
            try:
                module._compile(cpu, cache / identifier, output_arch=arch, use_ptx=use_ptx, options=options)
            except Exception as failure:  # reported per module; the others are still compiled
                error = f"{type(failure).__name__}: {str(failure).splitlines()[0][:300]}"
                break
            files += [str(p.relative_to(cache)) for p in (cache / identifier).glob(f"*.{suffix}")]
        seconds = time.perf_counter() - began
        compiled.append(CompiledModule(module.name, block_dim, identifier, tuple(sorted(files)), seconds, error))
    kernels = sum(len(module.kernels) for module in {id(m): m for m in unique.values()}.values())  # each module once
    size = sum(p.stat().st_size for p in cache.rglob("*") if p.is_file()) / 2**20
    return KernelCacheReport(
        str(cache_dir),
        arch,
        tuple(formats) if arch else ("o",),
        tuple(compiled),
        time.perf_counter() - start,
        kernels,
        size,
    )


def write_report(report: KernelCacheReport, name: str) -> Path:
    """The report as ``<cache>/kernels-<name>.json`` (what the cache holds for which environment, and what failed)."""
    path = Path(report.cache_dir) / f"kernels-{name}.json"
    path.write_text(json.dumps(report.to_json(), indent=1) + "\n")
    return path
