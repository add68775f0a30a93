"""The two feasibility measures of seed 004 §VI, evaluated on a simulated crawl pose.

* :func:`fwp_factor`: the FWP feasibility factor s (eq. 24) of the pose
  (:func:`~margin_rl.stability.fwp.feasibility.fwp_feasibility` with the joint-torque limits the
  simulation uses, so a hindered joint counts), about the CoM, quasi-static (no CoM acceleration: the
  tests are slow).
* :func:`cwc_margin`: the "CWC margin" of §VI-B, eq. (24) on the V-description of the bounded contact
  wrench cone (:mod:`~margin_rl.planning.crawl.polytopes`, kind ``"cwc"``), centred on its vertex
  centroid as the paper centres the FWP.

Both take a :class:`~margin_rl.planning.crawl.polytopes.StanceSnapshot` (world frame, heading +x).
"""

from __future__ import annotations

import math

from margin_rl.planning.crawl.polytopes import StanceSnapshot, stance_polytope
from margin_rl.robot import Robot
from margin_rl.stability.analytic.contact_problem import contact_problem
from margin_rl.stability.fwp.factor import feasibility_factor
from margin_rl.stability.fwp.feasibility import fwp_feasibility


def fwp_factor(robot: Robot, snapshot: StanceSnapshot, n_faces: int = 4) -> float:
    """s of eq. (24) for the pose, in the FWP with ``snapshot.torque_limits``; NaN where the pose has no
    contact problem (unreachable feet, no foot down)."""
    return fwp_feasibility(robot, snapshot.lam(), n_faces=n_faces, torque_limits=snapshot.torque_limits).s


def cwc_margin(robot: Robot, snapshot: StanceSnapshot) -> float:
    """The CWC margin of §VI-B: eq. (24) on the bounded contact wrench cone's vertices (NaN if no problem)."""
    problem = contact_problem(robot, snapshot.lam()[None])[0]
    if problem.status not in ("ok", "infeasible"):
        return math.nan
    cwc = stance_polytope(robot, snapshot, "cwc", problem=problem)
    return float(feasibility_factor(cwc.polytope.vertices, problem.wrench, length_scale=cwc.polytope.length_scale).s)
