"""Trajectory optimisation with the learned stability margin as a constraint (seed 000 §IV-B, §V-B).

A layer above :mod:`margin_rl.stability` (nothing below depends on it)::

    model = planning_robot(load_robot("anymal_c"))              # planning pose, range of motion
    margin = LearnedMargin.load("anymal_c")                      # planning_weights("anymal_c")
    scenario = get_scenario("side_step")                         # flat, side_step, course, env_rough
    result = run_course(model, scenario, WALK, PlannerConfig(), margin)   # replan at 1 Hz, T = 3 s
    check = check_course(result, model.robot, margin)            # analytic margin, IK reachability
    check.summary()

One horizon: ``TrajectoryProblem(model, height_map, gait, t0, config, margin).solve(initial, target,
footholds)`` -> :class:`Plan`. CLI: ``python -m margin_rl.planning --scenario side_step --robot anymal_c
--out results/to``.

Modules: ``terrain`` (B-spline height maps), ``scenarios``, ``gait``, ``schedule`` (event-based
footholds), ``robot_model`` (planning pose, range of motion), ``lambda_map`` (lambda of a base state,
CasADi), ``mlp`` (the network as CasADi), ``analytic_fd`` (analytic margin + finite differences, for the
benchmark), ``problem`` (eq. 9 and IPOPT), ``receding``, ``checks``, ``figures``, ``video``, ``experiment``.
"""

from margin_rl.planning.checks import CourseCheck, check_course, lateral_com_offset, plan_lambda
from margin_rl.planning.gait import GAITS, TROT, WALK, Gait, contact_flags, get_gait
from margin_rl.planning.mlp import planning_weights
from margin_rl.planning.problem import BaseState, Plan, PlannerConfig, TrajectoryProblem
from margin_rl.planning.receding import CourseResult, run_course
from margin_rl.planning.robot_model import PlanningRobot, planning_robot, range_of_motion_reachable
from margin_rl.planning.scenarios import SCENARIOS, Scenario, get_scenario
from margin_rl.planning.terrain import HeightMap, flat_map

__all__ = [
    "GAITS",
    "SCENARIOS",
    "TROT",
    "WALK",
    "BaseState",
    "CourseCheck",
    "CourseResult",
    "Gait",
    "HeightMap",
    "Plan",
    "PlannerConfig",
    "PlanningRobot",
    "Scenario",
    "TrajectoryProblem",
    "check_course",
    "contact_flags",
    "flat_map",
    "get_gait",
    "get_scenario",
    "lateral_com_offset",
    "plan_lambda",
    "planning_robot",
    "planning_weights",
    "range_of_motion_reachable",
    "run_course",
]
