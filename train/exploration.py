"""The policy's exploration noise against the action range: a check for a runaway action std.

The ANYmal environments clip every action to [-1, 1] (``margin_rl.envs.core``; the Gymnasium action space is
``Box(-1, 1)``). PPO's Gaussian policy samples a = μ + σ ε, ε ~ N(0, 1), with a state-independent σ per
action. Once σ is well above the bound, most samples land on ±1, where the environment cannot tell a larger σ
from a smaller one, while the entropy bonus (``entropy_coef`` × Σ log σ in the loss) keeps paying for it: σ then
grows for as long as training runs, the stochastic policy PPO learns from acts like bang-bang noise around the
standing pose, and the deterministic policy that is evaluated (a = μ) is one the training rarely executed.
Penalties that make noise costly (action rate, torques, joint accelerations in legged_gym's reward, whose
actions are clipped at ±100 rather than ±1) hold σ down there; the paper's reward has none.

:class:`ExplorationMonitor` follows the mean σ over the training and reports, once, when more than half of the
samples of that σ would be clipped (σ > 1.48 × the bound); the rsl backend records the last mean σ in every
checkpoint (``infos["action_std"]``).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass

from margin_rl.envs.core import ACTION_BOUND


def clipped_fraction(std: float, bound: float = ACTION_BOUND) -> float:
    """Probability that a zero-mean Gaussian sample of standard deviation ``std`` lies outside [-bound, bound]:
    2 (1 − Φ(bound / std)) = erfc(bound / (std √2)). For a sample of any mean μ the clipped probability is at least
    this: a symmetric unimodal density puts the most mass into an interval centred on its mode, so this is a lower
    bound on the clipped share of a policy's sampled actions.

    Raises:
        ValueError: ``std`` not > 0 or ``bound`` not > 0.
    """
    if not (std > 0 and math.isfinite(std)):
        raise ValueError(f"std must be a finite number > 0, got {std!r}")
    if not (bound > 0 and math.isfinite(bound)):
        raise ValueError(f"bound must be a finite number > 0, got {bound!r}")
    return math.erfc(bound / (std * math.sqrt(2.0)))


CLIPPED_SHARE_LIMIT = 0.5
"""The monitor reports a mean σ whose zero-mean samples fall outside the bound more often than this: σ above
bound / Φ⁻¹(0.75) ≈ 1.48 × bound. (σ = 1, the usual initial value, clips 32 %.)"""


@dataclass(frozen=True)
class NoiseReport:
    """The first training iteration whose mean action std clipped more than :data:`CLIPPED_SHARE_LIMIT`."""

    env_steps: int
    mean_std: float
    clipped_fraction: float  # of zero-mean samples at that std

    def message(self) -> str:
        return (
            f"the policy's mean action-noise std is {self.mean_std:.2f} after {self.env_steps:,} environment steps, "
            f"against the action bound {ACTION_BOUND:g}: at least {self.clipped_fraction:.0%} of its sampled actions "
            "are clipped, so the entropy bonus raises the std at no cost and the trained (stochastic) policy drifts "
            "away from the deterministic one that is evaluated. Lower the entropy bonus (--ppo-option "
            "entropy_coef=0 for rsl, ent_coef for sb3) or add a term that makes action noise costly (action_rate, "
            "torques)"
        )


def print_warning(report: NoiseReport) -> None:
    """The monitors' default ``warn``: the report's message on stderr (training's progress bar is on stdout)."""
    print(f"warning: {report.message()}", file=sys.stderr, flush=True)


class ExplorationMonitor:
    """Tracks the mean action std per training iteration; calls ``warn`` once, at the first value whose samples
    are clipped more often than :data:`CLIPPED_SHARE_LIMIT` at ``bound``."""

    def __init__(self, warn: Callable[[NoiseReport], None] = print_warning, bound: float = ACTION_BOUND) -> None:
        if not (bound > 0 and math.isfinite(bound)):
            raise ValueError(f"bound must be a finite number > 0, got {bound!r}")
        self.warn = warn
        self.bound = bound
        self.last_mean_std: float | None = None
        self.report: NoiseReport | None = None

    def update(self, mean_std: float, env_steps: int) -> None:
        """Record this iteration's mean std (over the actions); warn at the first value that clips too often."""
        mean_std = float(mean_std)
        if not math.isfinite(mean_std) or mean_std < 0:
            raise ValueError(f"mean action std must be a finite number >= 0, got {mean_std!r}")
        self.last_mean_std = mean_std
        if self.report is None and mean_std > 0:
            share = clipped_fraction(mean_std, self.bound)
            if share > CLIPPED_SHARE_LIMIT:
                self.report = NoiseReport(int(env_steps), mean_std, share)
                self.warn(self.report)
