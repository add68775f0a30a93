"""margin_rl: legged-robot reinforcement learning with a learned stability margin.

Layers, with imports in one direction only::

    margin_rl.robot      ANYmal B/C: MuJoCo + Pinocchio models from one MJCF each
    margin_rl.stability  analytic feasible region, capture point and margin; learned margin
    margin_rl.slip       seed 001's actuated SLIP hopper, failure margin and footstep planner
    margin_rl.planning   seed 000's trajectory optimisation with the learned margin as a constraint
    margin_rl.envs       Gymnasium environments (never import SB3 or rsl-rl)
    margin_rl.train      PPO training, comparison and evaluation (SB3, rsl-rl)

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
