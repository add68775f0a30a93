"""Old import paths of moved names: a module ``__getattr__`` (PEP 562) that warns and forwards.

Used by :mod:`margin_rl.train.adapters` (split into :mod:`~margin_rl.train.environments`,
:mod:`~margin_rl.train.sb3_backend`, :mod:`~margin_rl.train.rsl_backend` and :mod:`~margin_rl.train.metrics`)
and by the command modules for the helpers that moved to :mod:`~margin_rl.train.cli`,
:mod:`~margin_rl.train.episodes` and :mod:`~margin_rl.train.media`.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable, Mapping
from typing import Any


def moved(module: str, names: Mapping[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``module``: ``names[name]`` is the module that now holds ``name``; accessing
    it through ``module`` emits a DeprecationWarning naming the new place."""

    def getattr_moved(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        warnings.warn(
            f"{module}.{name} moved to {names[name]}.{name}; import it from there "
            f"(the old path will be removed in a later release)",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(importlib.import_module(names[name]), name)

    return getattr_moved
