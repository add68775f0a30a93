"""Receding-horizon planning along a course (seed 000 §V-B): replan every second over a 3 s horizon.

The robot is assumed to track each plan exactly for one replanning period (a kinematic playback, no
simulator in the loop): the next horizon starts from the plan's state at t + period, with the legs on
the footholds they stand on then (or, for a leg in the air, the one it lifted off from), and is
warm-started from the previous plan. Problems are cached by gait phase, so each distinct horizon
structure is built once per run.

Target of each horizon: the point ``gait.speed * T`` ahead of the current progress along the course
(capped at the goal), moving at the gait's speed (zero at the goal), its height the terrain's mean
under the nominal feet plus the nominal CoM height, its pitch following the terrain between the front
and hind feet (capped at 0.15 rad), roll and yaw zero.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from margin_rl.planning.gait import Gait
from margin_rl.planning.problem import BaseState, Plan, PlannerConfig, TrajectoryProblem
from margin_rl.planning.robot_model import PlanningRobot
from margin_rl.planning.scenarios import Scenario

GOAL_TOLERANCE = 0.15  # [m] a course counts as finished when its last plan starts this close to the goal


@dataclass(frozen=True, eq=False)
class CourseResult:
    """The plans of one receding-horizon run; plan i is executed over [t_i, t_i + period]."""

    scenario: Scenario
    gait: Gait
    config: PlannerConfig
    robot: str
    period: float  # [s]
    plans: tuple[Plan, ...]
    build_seconds: float  # problem construction, all phases [s]
    reached_goal: bool  # the last plan starts within GOAL_TOLERANCE of the goal
    distance_to_goal: float  # [m] horizontal, from the base at the last plan's start to the goal

    @property
    def duration(self) -> float:
        return len(self.plans) * self.period

    def plan_at(self, t: float) -> Plan:
        """The plan executed at time t."""
        i = int(min(max(np.floor(t / self.period + 1e-9), 0), len(self.plans) - 1))
        return self.plans[i]

    def solver_summary(self) -> dict[str, float]:
        iters = np.array([p.iterations for p in self.plans])
        secs = np.array([p.solve_seconds for p in self.plans])
        return {
            "plans": len(self.plans),
            "succeeded": int(sum(p.success for p in self.plans)),
            "iterations_median": float(np.median(iters)),
            "iterations_first": int(iters[0]),
            "solve_seconds_median": float(np.median(secs)),
            "ms_per_iteration_median": float(np.median(1000 * secs / np.maximum(iters, 1))),
        }


def start_state(model: PlanningRobot, scenario: Scenario) -> tuple[BaseState, np.ndarray]:
    """Standing at the scenario's start: (base state, (4, 3) contact points under the nominal feet)."""
    sx, sy = scenario.start_xy
    feet_xy = np.array([sx, sy]) + model.nominal_feet_com[:, 0:2]
    feet = np.column_stack([feet_xy, scenario.height_map.height(feet_xy)])
    z = float(feet[:, 2].mean()) + model.nominal_com_height
    return BaseState([sx, sy, z], np.zeros(3), np.zeros(3), np.zeros(3)), feet


def course_target(model: PlanningRobot, scenario: Scenario, gait: Gait, progress: float, horizon: float) -> BaseState:
    """The target state of a horizon that starts ``progress`` metres along the course."""
    start, goal = np.array(scenario.start_xy), np.array(scenario.goal_xy)
    length = scenario.course_length
    direction = (goal - start) / length
    distance = min(progress + gait.speed * horizon, length)
    xy = start + direction * distance
    yaw = float(np.arctan2(direction[1], direction[0]))
    rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    feet_xy = xy + model.nominal_feet_com[:, 0:2] @ rot.T
    h = scenario.height_map.height(feet_xy)
    front, hind = h[:2].mean(), h[2:].mean()
    span = float(np.linalg.norm(feet_xy[0] - feet_xy[2]))
    pitch = float(np.clip(-np.arctan2(front - hind, span), -0.15, 0.15))
    speed = gait.speed if distance < length - 1e-9 else 0.0
    z = float(h.mean()) + model.nominal_com_height
    return BaseState([xy[0], xy[1], z], [0.0, pitch, yaw], [*(speed * direction), 0.0], np.zeros(3))


def run_course(
    model: PlanningRobot,
    scenario: Scenario,
    gait: Gait,
    config: PlannerConfig,
    margin_model: object | None = None,
    period: float = 1.0,
    extra_time: float = 3.0,
    max_plans: int | None = None,
) -> CourseResult:
    """Plan the course with a horizon replanned every ``period`` s until the goal is reached and
    ``extra_time`` s have passed (the robot keeps stepping in place there), or ``max_plans`` plans.

    Raises:
        ValueError: a period that is not positive or longer than the horizon.
    """
    if not (0 < period <= config.horizon):
        raise ValueError(f"period must lie in (0, horizon={config.horizon}] s, got {period!r}")
    start = np.array(scenario.start_xy)
    direction = (np.array(scenario.goal_xy) - start) / scenario.course_length
    n_plans = int(np.ceil((scenario.course_length / max(gait.speed, 1e-9) + extra_time) / period))
    if max_plans is not None:
        n_plans = min(n_plans, int(max_plans))
    state, footholds = start_state(model, scenario)
    problems: dict[tuple, TrajectoryProblem] = {}
    build = 0.0
    plans: list[Plan] = []
    previous: Plan | None = None
    for i in range(n_plans):
        t0 = i * period
        progress = float((state.position[:2] - start) @ direction)
        target = course_target(model, scenario, gait, progress, config.horizon)
        key = (round(t0 % gait.period, 6),)
        if key not in problems:
            tic = time.perf_counter()
            problems[key] = TrajectoryProblem(model, scenario.height_map, gait, t0, config, margin_model)
            build += time.perf_counter() - tic
        problem = problems[key]
        if abs(problem.schedule.t0 - t0) > 1e-9:  # same phase, other time: shift the cached schedule
            problem = _retimed(problem, t0)
        plan = problem.solve(state, target, footholds, previous)
        plans.append(plan)
        previous = plan
        state = plan.state_at(t0 + period)
        footholds = plan.current_footholds(t0 + period)
    distance = float(np.linalg.norm(plans[-1].state_at(plans[-1].t0).position[:2] - np.array(scenario.goal_xy)))
    return CourseResult(
        scenario, gait, config, model.name, period, tuple(plans), build, distance < GOAL_TOLERANCE, distance
    )


def _retimed(problem: TrajectoryProblem, t0: float) -> TrajectoryProblem:
    """The cached problem of the same gait phase, presented at another absolute start time.

    The NLP depends on t0 only through the gait phase (the terrain and targets are inputs), so the
    solver is shared; only the schedule's absolute times move.
    """
    import copy
    from dataclasses import replace

    from margin_rl.planning.gait import Swing
    from margin_rl.planning.schedule import FootholdSlot

    shift = t0 - problem.schedule.t0
    sched = problem.schedule
    moved = replace(
        sched,
        t0=t0,
        node_times=sched.node_times + shift,
        swings=tuple(tuple(Swing(s.leg, s.liftoff + shift, s.touchdown + shift) for s in leg) for leg in sched.swings),
        slots=tuple(FootholdSlot(s.leg, s.touchdown + shift, s.stance_end + shift) for s in sched.slots),
    )
    clone = copy.copy(problem)
    clone.schedule = moved
    return clone
