"""Seed 004's Feasible Wrench Polytope criterion: the polytope, its linear programs and the feasibility factor.

::

    polytope     feasible_wrench_polytope(...): bounded friction cones, actuation polytopes, Minkowski sum (frame H)
    programs     the criterion's small Clarabel programs: gauge and polar support (eq. 24), residuals, cone depth
    factor       the feasibility factor s (eq. 21-24) of a wrench in a polytope, the violated limits (eq. 17-20)
    feasibility  fwp_feasibility(robot, lam) -> FWPFeasibility: the factor s of a lambda state

``polytope``, ``programs`` and ``factor`` are robot-agnostic; ``feasibility`` builds the contact problem
of a robot's state with :mod:`margin_rl.stability.analytic`.
"""

from margin_rl.stability.fwp.feasibility import FWPFeasibility, fwp_feasibility
from margin_rl.stability.fwp.polytope import feasible_wrench_polytope

__all__ = ["FWPFeasibility", "feasible_wrench_polytope", "fwp_feasibility"]
