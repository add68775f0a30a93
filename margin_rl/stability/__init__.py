"""Stability layer: the analytic stability margin of seed 000 §III (and, later, the learned one).

Robot-agnostic core::

    feasible_region(feet, normals, stance, mu, mass, jacobians, torque_limits, ...)  -> FeasibleRegion
    capture_point(com_xy, com_vel_xy, com_height, g)                                  -> ICP, eq. (5)
    stability_margin(region, point)                                                   -> eq. (7)

Robot layer (lambda in R^47, eq. 4)::

    LAMBDA_FIELDS, StabilityState, from_lambda       one declaration of lambda's layout
    sample_states(robot, n, seed)                    the Table I sampler
    analytic_margin(robot, lam)                      lambda -> IK -> region -> ICP -> m_a
    analytic_margin_batch(robot_name, lams)          the same over local processes
    LearnedMargin.load(robot)                        the learned margin (value, gradient, torch, ONNX)
    evaluation.evaluate(robot_name, model)           the learned margin judged by the paper's protocol
    fwp_feasibility(robot, lam)                      the feasible-wrench-polytope factor s (seed 004)
"""

from margin_rl.stability.analytic import (
    STATUSES,
    AnalyticMarginResult,
    AnalyticSettings,
    BatchMargins,
    analytic_margin,
    analytic_margin_batch,
)
from margin_rl.stability.fwp import FWPFeasibility, feasible_wrench_polytope, fwp_feasibility
from margin_rl.stability.icp import capture_point, stability_margin
from margin_rl.stability.lambda_state import (
    LAMBDA_DIM,
    LAMBDA_FIELDS,
    LAMBDA_SLICES,
    StabilityState,
    from_lambda,
    lambda_names,
)
from margin_rl.stability.learned import LearnedMargin
from margin_rl.stability.region import FeasibleRegion, feasible_region
from margin_rl.stability.sampling import SAMPLER_VERSION, TableI, sample_states

__all__ = [
    "LAMBDA_DIM",
    "LAMBDA_FIELDS",
    "LAMBDA_SLICES",
    "SAMPLER_VERSION",
    "STATUSES",
    "AnalyticMarginResult",
    "AnalyticSettings",
    "BatchMargins",
    "FWPFeasibility",
    "FeasibleRegion",
    "LearnedMargin",
    "StabilityState",
    "TableI",
    "analytic_margin",
    "analytic_margin_batch",
    "capture_point",
    "feasible_region",
    "feasible_wrench_polytope",
    "from_lambda",
    "fwp_feasibility",
    "lambda_names",
    "sample_states",
    "stability_margin",
]
