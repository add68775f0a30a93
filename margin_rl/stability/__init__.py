"""Stability layer: the analytic stability margin of seed 000 §III, the learned one (§IV) and the FWP factor.

Robot-agnostic core (arrays in, arrays out; never imports margin_rl.robot)::

    contact          the contact problem both criteria share: ContactSet, LegLimits, CentroidalLoad, the input
                     checks, tangent bases, the gravito-inertial wrench, the Clarabel settings and statuses
    polygon          planar convex polygons: caps, hull, area, half-spaces (eq. 6)
    projection       iterative_projection: one loop of Alg. 1, stopping on the area or on a focus point's bracket
    region           feasible_region(...) / solve_region(contacts, legs, load) -> FeasibleRegion (conic program)
    icp              capture_point (eq. 5), stability_margin (eq. 7)
    wrench_polytope  feasible_wrench_polytope(...) -> FeasibleWrenchPolytope: bounded friction cones, Minkowski sum
    wrench_lp        the FWP's small Clarabel programs: gauge and polar support (eq. 24), residuals, cone depth

Robot layer (lambda in R^47, eq. 4)::

    lambda_state     LAMBDA_FIELDS, StabilityState, from_lambda: one declaration of lambda's layout
    sampling         sample_states(robot, n, seed, table): the Table I sampler; LOCOMOTION, Table I widened to
                     the states walking policies visit (DISTRIBUTIONS by name)
    analytic         analytic_margin(robot, lam): lambda -> IK -> region -> ICP -> m_a (and a batch version)
    extended         extended_margin(robot, lam): m_x, m_a continued to states without a Feasible Region (relaxed
                     dynamic load with a penalty; the ICP's distance to the support hull)
    contact_batch    the contact problems of many states at once (batched IK, wrenches): the labelling path
    region_batch     the region's conic programs on one fixed sparsity structure per stance, updated per state
    fwp              fwp_feasibility(robot, lam): the feasible-wrench-polytope factor s (seed 004)
    dataset          states labelled with m_a and m_x, in resumable shards (python -m margin_rl.stability.dataset)
    mlp_weights      the learned margin's architecture, weights and their files (no torch)
    features         cheap physics features of lambda (ICP, load-shifted support polygon, friction terms), exact
                     Jacobians, numpy and torch: the inputs of the "physics" architecture
    learned          LearnedMargin.load(robot): value, gradient, torch module, ONNX
    margin_mlp       the network as a torch module (training, differentiable use)
    training         fit the learned margin on a dataset; evaluation: the paper's protocol; figures
"""

from margin_rl.stability.analytic import (
    STATUSES,
    AnalyticMarginResult,
    AnalyticSettings,
    BatchMargins,
    analytic_margin,
    analytic_margin_batch,
)
from margin_rl.stability.contact import CentroidalLoad, ContactSet, LegLimits
from margin_rl.stability.extended import ExtendedMargins, extended_margin, extended_margin_batch
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
from margin_rl.stability.region import FeasibleRegion, RegionSettings, feasible_region, solve_region
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
