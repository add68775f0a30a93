"""Stability layer: the analytic stability margin of seed 000 §III, the learned one (§IV) and the FWP factor.

Four sub-packages, importing downwards only (each one's docstring has its map)::

    geometry   robot-agnostic: the contact problem, polygons, iterative projection, the Feasible Region, ICP
    analytic   lambda (eq. 4) and the analytic margin of a robot's state; the extended margin m_x; samplers
    fwp        seed 004's Feasible Wrench Polytope and its feasibility factor s
    learned    the learned margin: network, weights, datasets, training, the paper's evaluation protocol

``geometry`` never imports ``margin_rl.robot``; ``analytic`` builds on it for a robot; ``fwp`` and ``learned``
build on both. The names below are the layer's public face.
"""

import importlib
from typing import Any

# lambda's layout and the learned margin load with the package (numpy only); the names below need the conic
# solvers (Clarabel) and load on first use, so that the environments and the learned margin's training path
# import no LP solver.
from margin_rl.stability.analytic.lambda_state import (
    LAMBDA_DIM,
    LAMBDA_FIELDS,
    LAMBDA_SLICES,
    StabilityState,
    from_lambda,
    lambda_names,
)
from margin_rl.stability.learned.model import LearnedMargin

_ON_FIRST_USE: dict[str, str] = {
    **dict.fromkeys(("ExtendedMargins", "extended_margin", "extended_margin_batch"), "analytic.extended"),
    **dict.fromkeys(
        ("STATUSES", "AnalyticMarginResult", "AnalyticSettings", "BatchMargins", "analytic_margin",
         "analytic_margin_batch"),
        "analytic.margin",
    ),
    **dict.fromkeys(("SAMPLER_VERSION", "TableI", "sample_states"), "analytic.sampling"),
    **dict.fromkeys(("FWPFeasibility", "fwp_feasibility"), "fwp.feasibility"),
    "feasible_wrench_polytope": "fwp.polytope",
    **dict.fromkeys(("CentroidalLoad", "ContactSet", "LegLimits"), "geometry.contact"),
    **dict.fromkeys(("capture_point", "stability_margin"), "geometry.icp"),
    **dict.fromkeys(("FeasibleRegion", "RegionSettings", "feasible_region", "solve_region"), "geometry.region"),
}  # fmt: skip
"""Public names loaded on first use (PEP 562), by the sub-module that defines them."""


def __getattr__(name: str) -> Any:
    if name not in _ON_FIRST_USE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_ON_FIRST_USE[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_ON_FIRST_USE})


__all__ = [
    "LAMBDA_DIM",
    "LAMBDA_FIELDS",
    "LAMBDA_SLICES",
    "SAMPLER_VERSION",
    "STATUSES",
    "AnalyticMarginResult",
    "AnalyticSettings",
    "BatchMargins",
    "CentroidalLoad",
    "ContactSet",
    "ExtendedMargins",
    "FWPFeasibility",
    "FeasibleRegion",
    "LearnedMargin",
    "LegLimits",
    "RegionSettings",
    "StabilityState",
    "TableI",
    "analytic_margin",
    "analytic_margin_batch",
    "capture_point",
    "extended_margin",
    "extended_margin_batch",
    "feasible_region",
    "feasible_wrench_polytope",
    "from_lambda",
    "fwp_feasibility",
    "lambda_names",
    "sample_states",
    "solve_region",
    "stability_margin",
]
