"""One scenario end to end: plan the course, check it independently, contrast it, draw it, film it.

Plans made for a scenario:

* ``learned``: eq. (9) with the learned margin constraint (the planner);
* ``no_margin``: the same problem without the margin constraint (how often does it violate the
  analytic margin?);
* ``centroid`` (side step only): no margin constraint, CoM kept over the centroid of the feet, the
  simplified-model plan of seed 000 Fig. 7 (top), against which the CoM shift is measured.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from margin_rl.planning.checks import CourseCheck, check_course, lateral_com_offset
from margin_rl.planning.gait import get_gait
from margin_rl.planning.mlp import planning_weights
from margin_rl.planning.problem import PlannerConfig
from margin_rl.planning.receding import CourseResult, run_course
from margin_rl.planning.robot_model import planning_robot
from margin_rl.planning.scenarios import get_scenario
from margin_rl.robot import load_robot
from margin_rl.stability import LearnedMargin

CENTROID_WEIGHT = 50.0  # w_c of the centroid contrast plan [1/(m^2 s)]


def _on_step(check: CourseCheck, result: CourseResult) -> np.ndarray:
    """Samples whose CoM is past x = 1.5 m (all four feet on the side step)."""
    xs = np.array([result.plan_at(float(t)).base_at(float(t))[0][0] for t in check.times])
    return xs >= 1.5


def evaluate_scenario(
    robot_name: str,
    scenario_name: str,
    gait_name: str = "walk",
    out: str | Path | None = None,
    video: bool = True,
    contrast: bool = True,
    max_plans: int | None = None,
    config: PlannerConfig | None = None,
    weights: str | Path | None = None,
) -> dict[str, object]:
    """Run and check one scenario; write ``<out>/<robot>_<scenario>_<gait>.{json,png,mp4}`` if ``out``.

    ``weights``: the learned margin the plans are constrained by (a bundled name such as ``"anymal_c"``, or an
    ``.npz`` with its card); default :func:`~margin_rl.planning.mlp.planning_weights`. Returns the summary written
    to the JSON file.

    Raises:
        WeightsError: unknown or corrupted weights (the message lists the bundled ones).
    """
    robot = load_robot(robot_name)
    model = planning_robot(robot)
    weights = planning_weights(robot_name) if weights is None else weights
    margin_model = LearnedMargin.load(weights)
    scenario = get_scenario(scenario_name)
    gait = get_gait(gait_name)
    config = PlannerConfig() if config is None else config
    summary: dict[str, object] = {
        "robot": robot_name,
        "scenario": scenario_name,
        "gait": gait_name,
        "weights": {"name": str(weights), "sha256": margin_model.card.get("sha256")},
        "min_margin_m": gait.min_margin,
        "margin_bound_m": gait.min_margin + config.margin_backoff,
        "config": {k: v for k, v in asdict(config).items() if k != "ipopt_options"},
    }
    tic = time.perf_counter()
    result = run_course(model, scenario, gait, config, margin_model, max_plans=max_plans)
    check = check_course(result, robot, margin_model)
    summary["learned"] = {
        **result.solver_summary(),
        **check.summary(),
        "reached_goal": result.reached_goal,
        "distance_to_goal_m": result.distance_to_goal,
    }
    runs = {"learned": (result, check)}
    if contrast:
        plain = replace(config, margin="none")
        result_none = run_course(model, scenario, gait, plain, margin_model, max_plans=max_plans)
        check_none = check_course(result_none, robot, margin_model)
        summary["no_margin"] = {**result_none.solver_summary(), **check_none.summary()}
        runs["no_margin"] = (result_none, check_none)
        if scenario_name == "side_step":
            centred = replace(plain, weight_centroid=CENTROID_WEIGHT)
            result_c = run_course(model, scenario, gait, centred, margin_model, max_plans=max_plans)
            check_c = check_course(result_c, robot, margin_model)
            summary["centroid"] = {**result_c.solver_summary(), **check_c.summary()}
            runs["centroid"] = (result_c, check_c)
            summary["side_step_lateral_com_offset_m"] = {
                name: lateral_com_offset(c, _on_step(c, r)) for name, (r, c) in runs.items()
            }
    summary["wall_seconds"] = time.perf_counter() - tic
    if out is not None:
        from margin_rl.planning.figures import course_figure

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        stem = f"{robot_name}_{scenario_name}_{gait_name}"
        contrast_check = runs["no_margin"][1] if "no_margin" in runs else None
        summary["figure"] = str(course_figure(result, check, out / f"{stem}.png", contrast_check))
        if video:
            from margin_rl.planning.video import VideoUnavailableError, write_mp4

            try:
                summary["video"] = str(write_mp4(robot, result, out / f"{stem}.mp4"))
            except VideoUnavailableError as exc:
                summary["video"] = f"not written: {exc}"
        (out / f"{stem}.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    return summary
