"""The margin kinds an ANYmal environment can put in its reward, declared once.

``EnvConfig.margin`` names one of :data:`MARGIN_KINDS`; the core builds its batch margin function with
:func:`make_margin_function`, and the training and evaluation CLIs offer the same names. Every kind maps
lambda (N, 47) to a margin (N,) in its own unit; states for which a per-state criterion has no value get
``floor``, the lower end of the environment's clip.

The analytic kind is the extended margin m_x (:mod:`margin_rl.stability.analytic.extended`): m_a where the Feasible
Region exists, and where it does not (no equilibrium, no contact) the margin of the relaxed load minus a
penalty, or the ICP's distance to the support hull, so the reward keeps a slope there instead of the floor.
Only unreachable feet, a solver error or an invalid lambda get the floor. The bundled learned weights (v2 and
later) are trained on m_x too (their card's ``dataset.target``); weights trained on m_a alone extrapolate there.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from array_api_compat import device as device_of
from threadpoolctl import ThreadpoolController

from margin_rl.arrays import namespace
from margin_rl.envs.backends import PHYSICS_BACKENDS
from margin_rl.robot import Robot
from margin_rl.stability.learned.model import LearnedMargin

MarginFunction = Callable[[Any], Any]
"""lambda (N, 47) -> margin (N,): numpy arrays for every kind; torch tensors (on their device) for the batched kinds
(:attr:`MarginKind.batched`), which answer in the same kind."""


def check_margin_kind(name: object) -> str:
    """``name`` if it is a margin kind, else a ValueError naming the kinds."""
    if not isinstance(name, str) or name not in MARGIN_KINDS:
        raise ValueError(f"margin must be one of {sorted(MARGIN_KINDS)}, got {name!r}")
    return name


def _per_state(criterion: Callable[[np.ndarray], float], floor: float) -> MarginFunction:
    """A batch function from a per-state criterion; ``floor`` where it raises ValueError or is not finite."""

    def evaluate(lam: np.ndarray) -> np.ndarray:
        values = np.empty(len(lam))
        for i, x in enumerate(lam):
            try:
                values[i] = criterion(x)
            except ValueError:  # e.g. a diverged simulation's lambda
                values[i] = np.nan
        return np.where(np.isfinite(values), values, floor)

    return evaluate


def _no_margin(robot: Robot, weights: str | None, floor: float) -> MarginFunction:
    def zero(lam: Any) -> Any:
        xp = namespace(lam)
        return xp.zeros(lam.shape[0], dtype=xp.float64, device=device_of(lam))

    return zero


def _learned_margin(robot: Robot, weights: str | None, floor: float) -> MarginFunction:
    """The one network of the robot's weights: its numpy form on the host, its torch form (float32, like the numpy
    batch path) on a tensor's device, built there on first use."""
    model = LearnedMargin.load(weights or robot.name)
    # OpenBLAS threads even these small GEMMs; on a few cores they collide with MuJoCo's thread
    # pool (measured 4x slower env steps), so the margin runs on one BLAS thread (~16 us to switch).
    blas = ThreadpoolController()
    modules: dict[str, Any] = {}

    def learned(lam: Any) -> Any:
        if namespace(lam) is np:
            with blas.limit(limits=1, user_api="blas"):
                return np.asarray(model(lam))
        import torch  # a tensor: torch is loaded already

        key = str(lam.device)
        if key not in modules:
            modules[key] = model.torch_module(torch.float32).to(lam.device).eval()
        with torch.no_grad():
            return modules[key](lam.to(torch.float32)).to(torch.float64)

    return learned


def _analytic_margin(robot: Robot, weights: str | None, floor: float) -> MarginFunction:
    """m_x of the whole batch in one call (one contact problem, one solver per stance structure)."""
    # Loaded here, not with the module: the LP solvers (Clarabel) are not needed by the learned margin's path.
    from margin_rl.stability.analytic.extended import extended_margin_batch

    def analytic(lam: np.ndarray) -> np.ndarray:
        # A diverged simulation's lambda (non-finite) gets the floor; the env builds every other field
        # valid (0/1 contacts, unit gravity axis, mu > 0), so one call rates the rest of the batch.
        finite = np.all(np.isfinite(lam), axis=1)
        values = np.full(len(lam), np.nan)
        if finite.any():
            values[finite] = extended_margin_batch(robot, lam[finite], workers=1).margin
        return np.where(np.isfinite(values), values, floor)

    return analytic


def _fwp_factor(robot: Robot, weights: str | None, floor: float) -> MarginFunction:
    from margin_rl.stability.fwp.feasibility import fwp_feasibility  # the LP solvers, loaded only for this kind

    return _per_state(lambda x: fwp_feasibility(robot, x).s, floor)


@dataclass(frozen=True)
class MarginKind:
    """One margin kind: what it is, its unit, and how its batch function is built."""

    name: str
    description: str
    unit: str
    build: Callable[[Robot, str | None, float], MarginFunction]
    batched: bool  # one array computation for the whole batch (what a GPU backend can run), not LPs per env


MARGIN_KINDS: dict[str, MarginKind] = {
    kind.name: kind
    for kind in (
        MarginKind(
            "learned",
            "the learned margin MLP of seed 000 §IV (batched, ~10 us per env step)",
            "m",
            _learned_margin,
            True,
        ),
        MarginKind(
            "analytic",
            "the analytic margin of seed 000 §III, extended to states without a Feasible Region "
            "(margin_rl.stability.analytic.extended; per env, ~2-15 ms per env step: validation)",
            "m",
            _analytic_margin,
            False,
        ),
        MarginKind(
            "fwp",
            "the feasible-wrench-polytope feasibility factor s of seed 004 (per env, ~4-12 ms per env step)",
            "dimensionless (s <= 1, a relative depth in the wrench polytope)",
            _fwp_factor,
            False,
        ),
        MarginKind("none", "no margin: the term is zero", "-", _no_margin, True),
    )
}
"""Margin kinds by name (``EnvConfig.margin``, ``--margin``)."""


def make_margin_function(kind: str, robot: Robot, weights: str | None, floor: float) -> MarginFunction:
    """The batch margin function of ``kind`` for ``robot``.

    ``weights``: learned-margin weights (.npz with its card) or None for the robot's bundled ones (only
    used by ``"learned"``); ``floor``: the value of states that a per-state criterion cannot rate.
    """
    return MARGIN_KINDS[check_margin_kind(kind)].build(robot, weights, floor)


def check_margin_runs_on(kind: str, physics: str) -> None:
    """ValueError where margin kind ``kind`` cannot run beside backend ``physics`` (the LP kinds solve on the
    CPU, per environment: beside Warp they would undo what it is for)."""
    if physics != PHYSICS_BACKENDS[0] and not MARGIN_KINDS[kind].batched:
        usable = [name for name, k in MARGIN_KINDS.items() if k.batched]
        raise ValueError(
            f"margin={kind!r} solves linear programs on the CPU, one environment at a time, and is not offered with "
            f"physics={physics!r}; use margin={usable[0]!r} (the learned margin, seed 000 §IV), another of {usable}, "
            f"or physics={PHYSICS_BACKENDS[0]!r}"
        )
