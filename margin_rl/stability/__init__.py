"""Stability layer: the analytic stability margin of seed 000 §III, the learned one (§IV) and the FWP factor.

Four sub-packages, importing downwards only (each one's docstring has its map)::

    geometry   robot-agnostic: the contact problem, polygons, iterative projection, the Feasible Region, ICP
    analytic   lambda (eq. 4) and the analytic margin of a robot's state; the extended margin m_x; samplers
    fwp        seed 004's Feasible Wrench Polytope and its feasibility factor s
    learned    the learned margin: network, weights, datasets, training, the paper's evaluation protocol

``geometry`` never imports ``margin_rl.robot``; ``analytic`` builds on it for a robot; ``fwp`` and ``learned``
build on both. The names below are the layer's public face.
"""

from margin_rl.stability.analytic.extended import ExtendedMargins, extended_margin, extended_margin_batch
from margin_rl.stability.analytic.lambda_state import (
    LAMBDA_DIM,
    LAMBDA_FIELDS,
    LAMBDA_SLICES,
    StabilityState,
    from_lambda,
    lambda_names,
)
from margin_rl.stability.analytic.margin import (
    STATUSES,
    AnalyticMarginResult,
    AnalyticSettings,
    BatchMargins,
    analytic_margin,
    analytic_margin_batch,
)
from margin_rl.stability.analytic.sampling import SAMPLER_VERSION, TableI, sample_states
from margin_rl.stability.fwp.feasibility import FWPFeasibility, fwp_feasibility
from margin_rl.stability.fwp.polytope import feasible_wrench_polytope
from margin_rl.stability.geometry.contact import CentroidalLoad, ContactSet, LegLimits
from margin_rl.stability.geometry.icp import capture_point, stability_margin
from margin_rl.stability.geometry.region import FeasibleRegion, RegionSettings, feasible_region, solve_region
from margin_rl.stability.learned.model import LearnedMargin

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
