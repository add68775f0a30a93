"""Seed 004's online CoM trajectory optimisation for a statically stable crawl, and its experiments (§V, §VI).

A layer beside the seed 000 planner (:mod:`margin_rl.planning`), on the FWP of
:mod:`margin_rl.stability.fwp`::

    robot, gait = load_robot("anymal_c"), CrawlGait()
    planner = make_planner("fwp", robot, gait)              # or "heuristic", "cwc"; same interface
    sim = CrawlSimulation(robot, gait, load_kg=20.0)         # MuJoCo, quasi-static controller, real torque limits
    for step in range(12):
        plan = sim.crawl_step(step, planner)                 # plan the base motion, move, swing the next leg
    plan.duration, plan.com_xy, plan.solve_seconds, sim.trace.arrays()["at_limit"]

CLI: ``python -m margin_rl.planning.crawl --robot anymal_c --out DIR`` (``DIR/crawl.json``, figures, MP4).

Modules: ``gait`` (phases, footholds, support triangles, the legs' workspace box), ``polytopes`` (a
stance's FWP or bounded CWC and the pseudo-inverse cost of eq. 27-28), ``planners`` (heuristic, CWC and
FWP planners of eq. 25-28), ``controller`` (the quasi-static whole-body controller), ``simulation`` (the
crawl in MuJoCo), ``evaluation`` (s and the CWC margin of a simulated pose), ``stance_tests`` (§VI-A),
``experiments`` (§VI on one robot, ``crawl.json``), ``figures``, ``video``.
"""

from margin_rl.planning.crawl.gait import LEGS, SWING_ORDER, CrawlGait
from margin_rl.planning.crawl.planners import (
    PLANNER_NAMES,
    BaseMotionPlan,
    BaseMotionTask,
    CrawlPlanner,
    HeuristicPlanner,
    WrenchPolytopePlanner,
    make_planner,
)
from margin_rl.planning.crawl.polytopes import StancePolytope, StanceSnapshot, stance_polytope
from margin_rl.planning.crawl.simulation import CrawlSimulation, HinderedJoint

__all__ = [
    "LEGS",
    "PLANNER_NAMES",
    "SWING_ORDER",
    "BaseMotionPlan",
    "BaseMotionTask",
    "CrawlGait",
    "CrawlPlanner",
    "CrawlSimulation",
    "HeuristicPlanner",
    "HinderedJoint",
    "StancePolytope",
    "StanceSnapshot",
    "WrenchPolytopePlanner",
    "make_planner",
    "stance_polytope",
]
