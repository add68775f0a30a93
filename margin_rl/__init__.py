"""margin_rl: legged-robot reinforcement learning with a learned stability margin.

Layers, with imports in one direction only::

    margin_rl.robot      ANYmal B/C: MuJoCo + Pinocchio models from one MJCF each, the MJCF names
    margin_rl.stability  geometry (robot-agnostic region, ICP), analytic (lambda, m_a, m_x), fwp (seed 004's
                         polytope and factor), learned (the network, its data, training and evaluation)
    margin_rl.slip       seed 001's actuated SLIP hopper, failure margin and footstep planner
    margin_rl.planning   seed 000's trajectory optimisation with the learned margin as a constraint
    margin_rl.envs       Gymnasium environments (never import SB3 or rsl-rl)
    margin_rl.train      PPO: backends (rsl-rl, SB3), artifacts, analysis, commands

Base modules below every layer: ``atomic`` (atomic writes), ``network`` (dense networks as numpy, torch and
CasADi from one set of folded weights), ``provenance``, ``plotting``, ``registration``.

``import margin_rl`` loads the robot layer and registers the Gymnasium ids (:mod:`margin_rl.registration`)
without importing the environments; ``tests/test_layers.py`` fails on an import against this order.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from margin_rl.registration import register_all
from margin_rl.robot import Robot, available_robots, load_robot

# The Gymnasium ids, by name only: Gymnasium imports margin_rl.envs when an environment is made.
register_all()

try:
    __version__ = version("margin_rl")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["Robot", "__version__", "available_robots", "load_robot"]
