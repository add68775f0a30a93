"""Timing and reporting shared by the benchmarks: every speed benchmark (``benchmarks/speed/``) times and reports
with it; studies use its JSON helper.

::

    machine(), machine_line()   the machine: CPU model, cores (all / usable by this process), load average,
                                Python and library versions; as a dict (JSON records) or one line (reports)
    Summary, summarise()        median, quartiles (IQR), min and max of repeated measurements
    time_per_call()             seconds per call of a function: one value per round of ``calls`` calls
    durations()                 seconds of whole calls, repeated
    round_order(), interleave() side-by-side rounds: every round runs every variant once, in a fixed or an
                                alternating order (A B, B A, ...), so that the variants share the machine's state
    median_ratio()              median of per-round ratios of two variants measured in the same rounds
    markdown_table()            the lines of a Markdown table (markdown_header(), markdown_row(): the same piecewise,
                                for tables printed row by row while a long benchmark runs); print_table() prints it
    parser()                    the benchmarks' argparse opening (module docstring as help, ``--json``)
    write_record()              a JSON record: benchmark, command, settings, machine, results (json_ready(): any
                                result as plain JSON, NaN as null)

On a shared machine only figures measured side by side in one run compare: quote medians and ratios of one run.
Scripts import this module as ``benchmarks.harness`` after putting the repository root on ``sys.path``, so that
they run as ``python benchmarks/speed/<script>.py`` from the repository root.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")

LIBRARIES: tuple[str, ...] = ("numpy", "scipy", "mujoco", "torch", "clarabel", "pin", "casadi")
"""Distributions whose versions :func:`machine` reports by default (``pin`` is Pinocchio)."""


# ---------------------------------------------------------------------------------------------------------------------
# the machine
# ---------------------------------------------------------------------------------------------------------------------
def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what :mod:`platform` knows."""
    try:
        with open("/proc/cpuinfo") as fh:
            return next(line.split(":", 1)[1].strip() for line in fh if line.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


def usable_cores() -> int:
    """Cores this process may run on (its affinity, e.g. under ``taskset``)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def load_average() -> float:
    """The one-minute load average (NaN where the system has none)."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan


def library_versions(libraries: Sequence[str] = LIBRARIES) -> dict[str, str | None]:
    """Installed version of each distribution (None when it is not installed); nothing is imported."""
    found: dict[str, str | None] = {}
    for name in libraries:
        try:
            found[name] = version(name)
        except PackageNotFoundError:
            found[name] = None
    return found


def machine(libraries: Sequence[str] = LIBRARIES) -> dict[str, Any]:
    """The machine a measurement ran on, for a JSON record."""
    return {
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "usable_cores": usable_cores(),
        "load_average": load_average(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "versions": library_versions(libraries),
    }


def machine_line(libraries: Sequence[str] = LIBRARIES) -> str:
    """One line: CPU, cores, load average, Python and the installed ``libraries``' versions."""
    m = machine(libraries)
    usable = "" if m["usable_cores"] == m["cores"] else f" ({m['usable_cores']} usable)"
    versions = ", ".join(f"{name} {v}" for name, v in m["versions"].items() if v is not None)
    return (
        f"{m['cpu']}, {m['cores']} cores{usable}, load average {m['load_average']:.2f}; "
        f"Python {m['python']}, {versions}"
    )


# ---------------------------------------------------------------------------------------------------------------------
# repeated measurements
# ---------------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Summary:
    """Median, first and third quartile, min and max of ``n`` measurements."""

    median: float
    q1: float
    q3: float
    low: float
    high: float
    n: int

    @property
    def iqr(self) -> float:
        """Interquartile range q3 - q1."""
        return self.q3 - self.q1

    def as_dict(self) -> dict[str, float]:
        return {**asdict(self), "iqr": self.iqr}


def summarise(values: Iterable[float]) -> Summary:
    """:class:`Summary` of ``values`` (at least one)."""
    array = np.asarray(list(values), dtype=float)
    if array.size == 0:
        raise ValueError("summarise() needs at least one value")
    q1, median, q3 = np.percentile(array, [25, 50, 75])
    return Summary(float(median), float(q1), float(q3), float(array.min()), float(array.max()), int(array.size))


def time_per_call(fn: Callable[[], object], calls: int, rounds: int = 5) -> list[float]:
    """Seconds per call of ``fn``: ``rounds`` values, each the mean over ``calls`` consecutive calls."""
    per_round = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        per_round.append((time.perf_counter() - t0) / calls)
    return per_round


def durations(fn: Callable[[], object], repeats: int) -> list[float]:
    """Seconds of ``repeats`` whole calls of ``fn``, one after the other."""
    seconds = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        seconds.append(time.perf_counter() - t0)
    return seconds


def round_order(names: Sequence[str], index: int, alternate: bool = True) -> list[str]:
    """``names`` in order, or reversed on odd ``index`` when ``alternate`` (A B, B A, ...: no variant always runs
    second, on a warm cache)."""
    return list(reversed(names)) if alternate and index % 2 else list(names)


def interleave(runners: Mapping[str, Callable[[int], T]], rounds: int, alternate: bool = False) -> dict[str, list[T]]:
    """Run every runner once per round, ``rounds`` times (each called with the round's index): name -> its results
    in round order. ``alternate``: reverse the order on odd rounds (:func:`round_order`)."""
    results: dict[str, list[T]] = {name: [] for name in runners}
    for index in range(rounds):
        for name in round_order(list(runners), index, alternate):
            results[name].append(runners[name](index))
    return results


def median_ratio(numerators: Sequence[float], denominators: Sequence[float]) -> float:
    """Median over rounds of numerator / denominator (both measured in the same rounds)."""
    return float(np.median(np.asarray(numerators, dtype=float) / np.asarray(denominators, dtype=float)))


# ---------------------------------------------------------------------------------------------------------------------
# reports
# ---------------------------------------------------------------------------------------------------------------------
_RULES = {"": "---", "l": ":---", "r": "---:", "c": ":---:"}


def markdown_row(cells: Sequence[object]) -> str:
    """One row of a Markdown table."""
    return "| " + " | ".join(str(cell) for cell in cells) + " |"


def markdown_header(headers: Sequence[str], align: Sequence[str] = ()) -> list[str]:
    """The two header lines of a Markdown table; ``align``: per column ``""`` (default), ``"l"``, ``"r"`` or
    ``"c"``."""
    rules = [_RULES[align[i]] if i < len(align) else _RULES[""] for i in range(len(headers))]
    return [markdown_row(headers), "|" + "|".join(rules) + "|"]


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[object]], align: Sequence[str] = ()) -> list[str]:
    """Lines of a Markdown table (see :func:`markdown_header` for ``align``)."""
    return markdown_header(headers, align) + [markdown_row(row) for row in rows]


def print_table(headers: Sequence[str], rows: Iterable[Sequence[object]], align: Sequence[str] = ()) -> None:
    """Print :func:`markdown_table` (flushed, so that tables show while a long benchmark runs)."""
    print("\n".join(markdown_table(headers, rows, align)), flush=True)


def parser(doc: str | None, first_paragraph: bool = False) -> argparse.ArgumentParser:
    """An argument parser with ``doc`` (a module docstring; only its first paragraph when ``first_paragraph``) as
    the help text, and ``--json PATH``: write the results with the machine description there (:func:`write_record`)."""
    text = (doc or "").split("\n\n")[0] if first_paragraph else doc
    result = argparse.ArgumentParser(description=text, formatter_class=argparse.RawDescriptionHelpFormatter)
    result.add_argument(
        "--json", type=Path, default=None, help="also write the results, settings and machine here (JSON record)"
    )
    return result


def json_ready(value: Any) -> Any:
    """JSON-ready copy: NaN and inf become null, numpy scalars and arrays plain numbers and lists, paths strings."""
    if isinstance(value, Mapping):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist())
    if isinstance(value, Summary):
        return json_ready(value.as_dict())
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value


def run_policies(parser: argparse.ArgumentParser, runs: Iterable[str | Path]) -> dict[str, Path]:
    """The policy of each of ``runs`` by the name it was given: a run folder's ``final_model.pt``, or a policy file
    itself; a missing one stops with a usage error naming it."""
    policies = {}
    for run in runs:
        path = Path(run) / "final_model.pt" if Path(run).is_dir() else Path(run)
        if not path.is_file():
            parser.error(f"{run}: no policy at {path} (a finished run's folder, or a policy file)")
        policies[str(run)] = path
    return policies


def write_record(
    path: Path | None, benchmark: str, args: argparse.Namespace | Mapping[str, Any], results: Any
) -> Path | None:
    """Write a JSON record (benchmark name, command line, settings, :func:`machine`, ``results``) to ``path``;
    nothing when ``path`` is None. Returns the path written."""
    if path is None:
        return None
    settings = vars(args) if isinstance(args, argparse.Namespace) else dict(args)
    record = {
        "benchmark": benchmark,
        "command": "python " + " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]]),
        "settings": settings,
        "machine": machine(),
        "results": results,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(json_ready(record), indent=1) + "\n")
    print(f"json: {path}")
    return path
