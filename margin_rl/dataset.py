"""Deprecated home of the analytic-margin datasets: use :mod:`margin_rl.stability.dataset`.

The dataset is part of the stability layer (as :mod:`margin_rl.slip.dataset` is of the SLIP one); this
module re-exports its public names and warns on import. ``python -m margin_rl.dataset ...`` still runs
the same command line.
"""

from __future__ import annotations

import warnings

from margin_rl.stability.dataset import (
    FORMAT_VERSION,
    MANIFEST,
    Dataset,
    DatasetError,
    DatasetSpec,
    generate,
    load_dataset,
    main,
    make_shard,
    shard_path,
)

__all__ = [
    "FORMAT_VERSION",
    "MANIFEST",
    "Dataset",
    "DatasetError",
    "DatasetSpec",
    "generate",
    "load_dataset",
    "main",
    "make_shard",
    "shard_path",
]

warnings.warn(
    "margin_rl.dataset is deprecated: import margin_rl.stability.dataset (python -m margin_rl.stability.dataset)",
    DeprecationWarning,
    stacklevel=2,
)

if __name__ == "__main__":
    raise SystemExit(main())
