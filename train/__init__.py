"""Training, comparison and evaluation of margin_rl, installed as ``margin_rl.train``.

PPO is never re-implemented here: rsl-rl's ``OnPolicyRunner`` and Stable-Baselines3's ``PPO`` do the learning,
on thin adapters over the one batched simulation :class:`margin_rl.envs.core.AnymalCore`. One environment path:
the batched ANYmal ids; any other id is refused with an error naming them. Other Gymnasium environments (e.g. the
SLIP hopper ``margin_rl/SLIPHopper-v0``) are trained with plain Stable-Baselines3, as
``examples/train_slip_hopper.py`` in the repository shows.

Map (each sub-package imports only the rows above it)::

    environments, config, metrics, runs   the foundation: the one environment interface (batched ANYmal ids),
                                          PPO settings, episode metrics and their logs, run directories and
                                          checkpoints
    backends/    rsl, sb3: each learner's vector-environment adapter and its training loop
    artifacts/   policies (load any saved policy), bundle (policies shipped with a card in bundled/)
    analysis/    episodes (the one evaluation runner), significance (Welch and bootstrap), media (plots, video)
    commands/    the command lines: train, evaluate, compare, push_recovery, and their shared options

Commands: ``python -m margin_rl.train <command> --help`` (or ``margin-rl-<command>``), command being
``train``, ``evaluate``, ``compare`` or ``push-recovery``.

:func:`make_sb3_env` and :func:`make_rsl_env` give plain SB3 / rsl-rl a vector environment of an ANYmal id.
Importing this package imports neither torch nor the RL libraries: the two factories load their backend
module on first access (PEP 562).
"""

from __future__ import annotations

import importlib
import os
from typing import Any

# rsl-rl imports GitPython, which fails to import without a git executable unless this is set; every
# margin_rl.train module is imported after this package, so this one line covers them all.
os.environ.setdefault("GIT_PYTHON_REFRESH", "quiet")

_LAZY = {"make_sb3_env": "margin_rl.train.backends.sb3", "make_rsl_env": "margin_rl.train.backends.rsl"}

__all__ = ["make_rsl_env", "make_sb3_env"]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
