"""Learned against analytic margin along whole planned courses, and how far each replan advances, per network.

    .venv/bin/python benchmarks/studies/bench_plan_margin_bias.py --robot anymal_b --scenario flat \\
        --weights anymal_b --weights anymal_b_table_i

For each weights file the course is planned (walk, the default exact Hessian, replanned every 1 s) and checked
(``margin_rl.planning.check_course``: the analytic margin every 50 ms of the executed trajectory). Printed per
network: the distance to the goal at the end, the mean and median of m_l − m_a where both exist (positive: the
network over-estimates the margin), the mean analytic margin, the median progress per replan along the course and
the smallest analytic margin at the plans' nodes.
"""

from __future__ import annotations

import argparse

import numpy as np

from margin_rl.planning import WALK, PlannerConfig, check_course, get_scenario, planning_robot, run_course
from margin_rl.robot import load_robot
from margin_rl.stability import LearnedMargin


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="anymal_b")
    parser.add_argument("--scenario", default="flat")
    parser.add_argument("--weights", action="append", required=True, help="bundled name or .npz (repeatable)")
    args = parser.parse_args()
    robot = load_robot(args.robot)
    model = planning_robot(robot)
    scenario = get_scenario(args.scenario)
    print(
        "| weights | distance to goal [m] | m_l − m_a mean / median [cm] | mean m_a [cm] | progress per replan [m] "
        "| min m_a at nodes [cm] |"
    )
    print("|---|---|---|---|---|---|")
    for name in args.weights:
        margin = LearnedMargin.load(name)
        result = run_course(model, scenario, WALK, PlannerConfig(), margin)
        check = check_course(result, robot, margin)
        both = np.isfinite(check.analytic) & np.isfinite(check.learned)
        bias = check.learned[both] - check.analytic[both]
        progress = np.diff([plan.base[0, 0] for plan in result.plans])
        print(
            f"| {name} | {result.distance_to_goal:.3f} | {100 * bias.mean():+.2f} / {100 * np.median(bias):+.2f} "
            f"| {100 * np.nanmean(check.analytic):.2f} | {np.median(progress):.3f} "
            f"| {100 * np.nanmin(check.analytic[check.at_node]):.2f} |"
        )


if __name__ == "__main__":
    main()
