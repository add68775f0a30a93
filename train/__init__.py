"""Training, comparison and evaluation entry points of margin_rl, installed as ``margin_rl.train``.

PPO is never re-implemented here: rsl-rl's ``OnPolicyRunner`` and Stable-Baselines3's ``PPO`` do the learning,
on thin adapters over the one batched simulation :class:`margin_rl.envs.core.AnymalCore` (ANYmal ids), or,
for any other registered Gymnasium id (e.g. ``margin_rl/SLIPHopper-v0``), SB3 over ``gymnasium.make``.

Command-line entry points (``python -m margin_rl.train.<name> --help``):

* :mod:`~margin_rl.train.train`: one PPO run (``--backend rsl|sb3``), TensorBoard, checkpoints, ``--resume``;
* :mod:`~margin_rl.train.compare`: margin weight 0 vs > 0 over seeds, Fig. 9-style plot, table (PNG, MD, JSON);
  ``--bundle`` ships the policies with a card, ``--bundled`` evaluates shipped ones (the README's main job);
* :mod:`~margin_rl.train.evaluate`: deterministic episodes of a saved policy (SB3 zip, rsl-rl checkpoint,
  TorchScript): metrics JSON, plots, optional MP4.

Map: :mod:`~margin_rl.train.environments` (the environment interface, chosen once per id: batched ANYmal or
generic Gymnasium), :mod:`~margin_rl.train.sb3_backend` and :mod:`~margin_rl.train.rsl_backend` (each backend's
vector-environment adapter and learner), :mod:`~margin_rl.train.episodes` (the one episode runner and recorder
of evaluations), :mod:`~margin_rl.train.media` (plots, video), :mod:`~margin_rl.train.metrics` (episode
metrics), :mod:`~margin_rl.train.cli` (options and defaults shared by the three commands),
:mod:`~margin_rl.train.config` (PPO settings), :mod:`~margin_rl.train.runs` (run directories),
:mod:`~margin_rl.train.policies` (saved policies), :mod:`~margin_rl.train.bundle` (policy bundles).
:mod:`~margin_rl.train.adapters` only re-exports moved names, with a DeprecationWarning.

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

_LAZY = {"make_sb3_env": "margin_rl.train.sb3_backend", "make_rsl_env": "margin_rl.train.rsl_backend"}

__all__ = ["make_rsl_env", "make_sb3_env"]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
