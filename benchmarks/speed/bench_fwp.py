"""Benchmark of the Feasible Wrench Polytope criterion (:mod:`margin_rl.stability.fwp.feasibility`) vs seed 004.

For 3 and 4 non-coplanar contacts of ANYmal C (feet at different heights, tilted terrain normals,
static state; ``--states`` random variations of that stance), prints a Markdown table with the vertex
counts and times of each step next to the paper's Table I/II (HyQ, i5-4440 @ 3.1 GHz, Politopix for
the V-description):

* ``B_i``: vertices of the bounded friction cones (eq. 10); ``tested``: candidate sums examined by
  the pruning; ``FWP vertices`` (paper: 436 and 1118) and the size of eq. (24) (paper: 437/1119
  variables, 7 constraints);
* ``V-descr.``: eq. (10)-(13) with pruning (paper: 0.15 s and 0.49 s); ``LP (24)``: eq. (24) as
  written on the pruned vertices (paper: 90 and 350 ms); ``its dual``: the same value from the dual
  program (what :func:`feasibility_factor` solves by default); ``summand LP``: the equivalent program
  on the summands, without vertices;
* ``end to end``: :func:`fwp_feasibility` from lambda (IK, Jacobians, bias torques, FWP, LP), with
  ``prune=False`` (default) and ``prune=True`` (the paper's pipeline). Target: < 50 ms.

Times are medians over states and ``--repeats`` [ms], wall clock on whatever else the machine runs
(the load average is printed): run it on a quiet machine for numbers to quote.

Usage::

    python benchmarks/speed/bench_fwp.py [--states 3] [--repeats 3] [--robot anymal_c] [--n-faces 4] [--json PATH]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import numpy as np

from benchmarks.harness import machine_line, markdown_header, markdown_row, parser, write_record
from margin_rl import load_robot
from margin_rl.robot import Robot
from margin_rl.stability.analytic.contact_problem import contact_problem
from margin_rl.stability.analytic.sampling import nominal_feet, standing_state
from margin_rl.stability.fwp.feasibility import (
    contact_problem_polytope,
    feasibility_factor,
    fwp_feasibility,
    minkowski_feasibility_factor,
)

PAPER = {  # Table I (LP) and Table II (Politopix V-description), HyQ
    3: {"vertices": 436, "variables": 437, "v_descr_ms": 150.0, "lp_ms": 90.0},
    4: {"vertices": 1118, "variables": 1119, "v_descr_ms": 490.0, "lp_ms": 350.0},
}
# Non-coplanar stance: foot heights [m] (LF, RF, LH, RH) and terrain normal tilts [rad] about x and y.
HEIGHTS = np.array([0.08, 0.03, 0.0, -0.05])
TILTS = np.array([[0.0, 0.2], [0.0, 0.0], [-0.15, 0.0], [0.1, 0.1]])


def normal(tilt_x: float, tilt_y: float) -> np.ndarray:
    n = np.array([np.sin(tilt_y) * np.cos(tilt_x), -np.sin(tilt_x), np.cos(tilt_x) * np.cos(tilt_y)])
    return n / np.linalg.norm(n)


def make_states(robot: Robot, n_contacts: int, n_states: int, seed: int) -> list[np.ndarray]:
    """The reference non-coplanar stance, then random variations (heights +-3 cm, tilts +-0.1 rad)."""
    rng = np.random.default_rng(seed + n_contacts)
    contacts = np.ones(4) if n_contacts == 4 else np.array([1.0, 1.0, 1.0, 0.0])
    lams = []
    while len(lams) < n_states:
        k = len(lams)
        heights = HEIGHTS + (rng.uniform(-0.03, 0.03, 4) if k else 0.0)
        tilts = TILTS + (rng.uniform(-0.1, 0.1, (4, 2)) if k else 0.0)
        feet = nominal_feet(robot) + np.column_stack([np.zeros((4, 2)), heights])
        lam = standing_state(robot, feet=feet, mu=0.7, contacts=contacts, normals=np.array([normal(*t) for t in tilts]))
        if contact_problem(robot, lam[None])[0].solvable:
            lams.append(lam)
    return lams


def measure(robot: Robot, lam: np.ndarray, n_faces: int) -> dict[str, Any]:
    """One pass over every step; times in ms."""
    problem = contact_problem(robot, lam[None])[0]  # one state: a batch of one
    assert problem.solvable
    fwp = contact_problem_polytope(problem, n_faces=n_faces)
    w = problem.wrench  # gravito-inertial wrench about the CoM
    on_vertices = feasibility_factor(fwp.vertices, w, center=fwp.center, length_scale=fwp.length_scale)
    primal = feasibility_factor(fwp.vertices, w, center=fwp.center, length_scale=fwp.length_scale, dual=False)
    on_summands = minkowski_feasibility_factor(fwp, w)
    assert abs(on_vertices.s - on_summands.s) < 1e-5 and abs(primal.s - on_summands.s) < 1e-5
    t0 = time.perf_counter()
    fast = fwp_feasibility(robot, lam, n_faces=n_faces)
    t1 = time.perf_counter()
    fwp_feasibility(robot, lam, n_faces=n_faces, prune=True)
    t2 = time.perf_counter()
    return {
        "b_i": fwp.contact_vertex_counts,
        "tested": fwp.n_candidates,
        "vertices": fwp.n_vertices,
        "variables": on_vertices.n_variables,
        "constraints": on_vertices.n_constraints,
        "v_descr": 1e3 * fwp.timings["total"],
        "lp": 1e3 * primal.solve_time,
        "lp_dual": 1e3 * on_vertices.solve_time,
        "summand_lp": 1e3 * on_summands.solve_time,
        "e2e_fast": 1e3 * (t1 - t0),
        "e2e_paper": 1e3 * (t2 - t1),
        "s": fast.s,
    }


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--states", type=int, default=3, help="stances per case (the first is the reference)")
    args_parser.add_argument("--repeats", type=int, default=3, help="timed passes per stance")
    args_parser.add_argument("--robot", default="anymal_c")
    args_parser.add_argument("--n-faces", type=int, default=4, help="faces of the linearised friction cones")
    args_parser.add_argument("--seed", type=int, default=0)
    args = args_parser.parse_args()

    robot = load_robot(args.robot)
    print(f"# FWP benchmark: {args.robot}, {args.n_faces}-face friction pyramids, static non-coplanar stances")
    print(machine_line())
    print(f"Medians over {args.states} stance(s) x {args.repeats} repeat(s) [ms]; paper values in parentheses.\n")
    header = ("contacts", "B_i vertices", "tested", "FWP vertices (paper)", "LP vars / rows (paper)",
              "V-descr. (paper)", "LP (24) (paper)", "its dual", "summand LP", "end to end, prune=False",
              "end to end, prune=True")  # fmt: skip
    print("\n".join(markdown_header(header)))
    record = {}
    for n_contacts in (3, 4):
        runs = []
        for lam in make_states(robot, n_contacts, args.states, args.seed):
            measure(robot, lam, args.n_faces)  # warm-up (imports, caches)
            runs.extend(measure(robot, lam, args.n_faces) for _ in range(args.repeats))
        ref, paper = runs[0], PAPER[n_contacts]

        def med(key: str, runs: list[dict[str, Any]] = runs) -> float:
            return float(np.median([r[key] for r in runs]))

        counts = sorted({r["vertices"] for r in runs})
        span = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
        print(
            markdown_row(
                (n_contacts, ", ".join(map(str, ref["b_i"])), ref["tested"], f"{span} ({paper['vertices']})",
                 f"{ref['variables']} / {ref['constraints']} ({paper['variables']} / 7)",
                 f"{med('v_descr'):.0f} ({paper['v_descr_ms']:.0f})", f"{med('lp'):.1f} ({paper['lp_ms']:.0f})",
                 f"{med('lp_dual'):.1f}", f"{med('summand_lp'):.1f}", f"{med('e2e_fast'):.1f}",
                 f"{med('e2e_paper'):.0f}")
            ),
            flush=True,
        )  # fmt: skip
        timed = ("v_descr", "lp", "lp_dual", "summand_lp", "e2e_fast", "e2e_paper")
        record[f"{n_contacts} contacts"] = {
            "b_i_vertices": ref["b_i"],
            "tested": ref["tested"],
            "fwp_vertices": counts,
            "lp_variables": ref["variables"],
            "lp_constraints": ref["constraints"],
            "median_ms": {key: med(key) for key in timed},
            "paper": paper,
        }
    print("\nB_i and tested: the reference stance; FWP vertices: range over the stances.")
    write_record(args.json, "fwp", args, record)


if __name__ == "__main__":
    main()
