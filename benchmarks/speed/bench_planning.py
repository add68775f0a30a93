"""Speed of the seed 000 §V-B walk problem: learned margin (CasADi, exact gradient) vs analytic margin +
finite differences, side by side in one process.

    taskset -c 0 .venv/bin/python benchmarks/speed/bench_planning.py --repeats 3 --analytic-iterations 8 [--json PATH]

The problem: ANYmal C (or --robot), walk gait, T = 3 s, dT = 0.2 s, from standing at rest to a target
0.45 m ahead at the walk's speed, on the ``course`` map at its start (flat there) or --scenario.
Rows: IPOPT iterations, total solve time and time per iteration (medians over repeats), with IPOPT's
exact Hessian (the default, ``PlannerConfig(hessian="exact")``, assembled by the chain rule; and the same matrix
from CasADi's own second derivatives, ``TrajectoryProblem(..., chain_rule_hessian=False)``) and with its
quasi-Newton one; the analytic
variant (quasi-Newton: finite differences give first derivatives only) is capped at --analytic-iterations
iterations (each takes about a second), so only its time per iteration compares; a row without any margin
constraint shows the rest of the problem's cost.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import numpy as np

from benchmarks.harness import durations, interleave, machine_line, parser, print_table, write_record
from margin_rl.planning import (
    WALK,
    BaseState,
    PlannerConfig,
    TrajectoryProblem,
    get_scenario,
    planning_robot,
    planning_weights,
)
from margin_rl.robot import load_robot
from margin_rl.stability import LearnedMargin


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--robot", default="anymal_c")
    args_parser.add_argument("--scenario", default="course")
    args_parser.add_argument("--repeats", type=int, default=3)
    args_parser.add_argument("--analytic-iterations", type=int, default=8)
    args_parser.add_argument(
        "--also-weights",
        action="append",
        default=[],
        help="other learned-margin weights (bundled name or .npz) for an extra exact-Hessian row each, "
        "e.g. anymal_c_table_i",
    )
    args = args_parser.parse_args()

    robot = load_robot(args.robot)
    model = planning_robot(robot)
    margin = LearnedMargin.load(planning_weights(args.robot))
    hm = get_scenario(args.scenario).height_map
    h = model.nominal_com_height
    initial = BaseState([0.0, 0.0, h], np.zeros(3), np.zeros(3), np.zeros(3))
    target = BaseState([0.45, 0.0, h], np.zeros(3), [WALK.speed, 0.0, 0.0], np.zeros(3))
    xy = model.nominal_feet_com[:, :2]
    footholds = np.column_stack([xy, hm.height(xy)])

    exact = "learned, exact Hessian by the chain rule (the default)"
    analytic = "analytic + finite differences (quasi-Newton)"
    variants = {
        "learned, quasi-Newton (L-BFGS)": PlannerConfig(hessian="quasi-newton"),
        exact: PlannerConfig(hessian="exact"),
        "learned, exact Hessian by CasADi (block Hessians through its graph)": PlannerConfig(hessian="exact"),
        analytic: PlannerConfig(margin="analytic_fd", hessian="quasi-newton", max_iter=args.analytic_iterations),
        "no margin constraint (quasi-Newton)": PlannerConfig(margin="none", hessian="quasi-newton"),
    }
    weights = dict.fromkeys(variants, margin)
    for other in args.also_weights:
        name = f"learned ({other}), exact Hessian by the chain rule"
        variants[name], weights[name] = PlannerConfig(hessian="exact"), LearnedMargin.load(other)
    problems = {}
    for name, config in variants.items():
        tic = time.perf_counter()
        chain_rule = "by CasADi" not in name
        problems[name] = TrajectoryProblem(model, hm, WALK, 0.0, config, weights[name], chain_rule_hessian=chain_rule)
        problems[name].build_seconds = time.perf_counter() - tic

    def runner(problem: TrajectoryProblem):
        def run(_round: int) -> tuple[int, float, str]:
            plan = problem.solve(initial, target, footholds)
            return plan.iterations, plan.solve_seconds, plan.status

        return run

    # interleaved: the rows share the machine's state
    rows = interleave({name: runner(problem) for name, problem in problems.items()}, args.repeats)

    # Cost of one margin value + gradient at the 16 nodes, outside IPOPT.
    import casadi as ca

    learned_problem = problems[exact]
    plan = learned_problem.solve(initial, target, footholds)
    lams = learned_problem.plan_lambdas(plan)
    from margin_rl.planning.analytic_fd import analytic_margin_function
    from margin_rl.planning.mlp import margin_function

    n = len(lams)
    lam_sym = ca.MX.sym("lam", 47, n)
    f_learned = margin_function(margin, n)
    g_learned = ca.Function("g_learned", [lam_sym], [f_learned(lam_sym), ca.jacobian(f_learned(lam_sym), lam_sym)])
    single = ca.MX.sym("lam", 47)
    f_analytic = analytic_margin_function(robot, 2e-3)
    g_analytic = ca.Function("g_analytic", [single], [f_analytic(single), ca.jacobian(f_analytic(single), single)])
    t_learned = durations(lambda: g_learned(lams.T), 20)
    tic = time.perf_counter()
    for lam in lams:
        g_analytic(lam)
    t_analytic = time.perf_counter() - tic

    print(machine_line())
    print(
        f"problem: {args.robot}, walk, {args.scenario}, T = 3.0 s, dT = 0.2 s: "
        f"{learned_problem.n_decision} variables, {learned_problem.n_constraints} constraints "
        f"({learned_problem.schedule.n_nodes} margin constraints), {len(learned_problem.schedule.slots)} footholds; "
        f"learned margin {planning_weights(args.robot)} ({margin.card.get('sha256', '?')[:12]})"
    )
    summary, table = {}, []
    for name, values in rows.items():
        iters = np.array([v[0] for v in values])
        secs = np.array([v[1] for v in values])
        per = 1000 * secs / np.maximum(iters, 1)
        statuses = sorted({v[2] for v in values})
        table.append(
            (name, f"{problems[name].build_seconds:.2f}", f"{np.median(iters):.0f}", f"{np.median(secs):.3f}",
             f"{np.median(per):.1f}", ", ".join(statuses))
        )  # fmt: skip
        summary[name] = {"iterations": iters.tolist(), "seconds": secs.tolist(), "ms_per_iteration": per.tolist()}
    print_table(
        ("variant", "build s", "iterations (median)", "total s (median)", "ms / iteration (median)", "status"), table
    )
    ratio = np.median(summary[analytic]["ms_per_iteration"]) / np.median(summary[exact]["ms_per_iteration"])
    print(f"per-iteration ratio analytic+FD / learned: {ratio:.0f}x")
    print(
        f"margin value + gradient at all {n} nodes: learned {1000 * np.median(t_learned):.2f} ms, "
        f"analytic + forward differences {1000 * t_analytic:.0f} ms ({t_analytic / np.median(t_learned):.0f}x)"
    )
    node_seconds = {"learned_median": float(np.median(t_learned)), "analytic_forward_differences": t_analytic}
    write_record(
        args.json, "planning", args, {"variants": summary, "margin_value_and_gradient_all_nodes_s": node_seconds}
    )


if __name__ == "__main__":
    main()
