"""Seed 004's Feasible Wrench Polytope criterion: the polytope, its linear programs and the feasibility factor.

::

    polytope     feasible_wrench_polytope(...): bounded friction cones, actuation polytopes, Minkowski sum (frame H)
    programs     the criterion's small Clarabel programs: gauge and polar support (eq. 24), residuals, cone depth
    feasibility  fwp_feasibility(robot, lam) -> FWPFeasibility: the factor s of a lambda state

``polytope`` and ``programs`` are robot-agnostic; ``feasibility`` builds the contact problem of a robot's state
with :mod:`margin_rl.stability.analytic`.
"""

from margin_rl.stability.fwp.feasibility import FWPFeasibility, feasible_wrench_polytope, fwp_feasibility

__all__ = ["FWPFeasibility", "feasible_wrench_polytope", "fwp_feasibility"]
