"""margin_rl: legged-robot reinforcement learning with a learned stability margin.

Layers, with imports in one direction only::

    margin_rl.robot      ANYmal B/C: MuJoCo + Pinocchio models from one MJCF each
    margin_rl.stability  analytic feasible region, capture point and margin; learned margin
    margin_rl.envs       Gymnasium environments (never import SB3 or rsl-rl)
    margin_rl.train      PPO training, comparison and evaluation (SB3, rsl-rl)
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from margin_rl import envs as _envs  # noqa: F401 - registers the Gymnasium ids
from margin_rl.robot import Robot, available_robots, load_robot

try:
    __version__ = version("margin_rl")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["Robot", "__version__", "available_robots", "load_robot"]
