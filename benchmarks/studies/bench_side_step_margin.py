"""Study: where the analytic margin of the side-step stance (seed 000 Fig. 7) is largest, as the CoM moves sideways.

Usage:
    python benchmarks/studies/bench_side_step_margin.py [--robot anymal_c] [--step 0.18] [--span 0.25]
        [--resolution 0.01] [--com-acc-z 0] [--json PATH]

Seed 000 reports that on a side step (the ground under the left feet higher than under the right) the planner
moves the CoM toward the more extended legs. Whether the analytic margin of this model asks for that is a
property of the stance, not of the planner, so this study measures it directly. The stance is the planner's
(``margin_rl.planning.planning_robot``: the standing keyframe crouched by 12 cm, level base), with the left feet
(y > 0) ``--step`` higher than the right ones, split evenly about the flat stance's foot height (left legs
flexed by step/2, right legs extended by step/2). The CoM is moved horizontally by (dx, dy) on a grid over
[-span, span]^2 (lambda's feet, which are relative to the CoM, move the other way), at rest (the ICP is the
CoM; ``--com-acc-z`` adds a vertical CoM acceleration, loading the legs as a walk's stance does), and the
analytic margin m_a is evaluated for the four-foot stance and each three-foot stance of a walk
(one foot in swing), on the side step and on flat ground; the best grid point is refined on a grid five times
finer around it. Printed per stance: where m_a is largest on each ground and the lateral difference (the
side-step effect: positive = toward the higher, flexed legs; negative = toward the lower, extended legs), and
m_a at the flat optimum and at the side step's own. States without a margin (unreachable feet: the CoM far
from the stance) are counted and left out.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import numpy as np

from benchmarks.harness import machine_line, parser, print_table, write_record
from margin_rl import load_robot
from margin_rl.planning import planning_robot
from margin_rl.stability import analytic_margin
from margin_rl.stability.analytic.sampling import standing_state

LEFT = np.array([True, False, True, False])  # LF, RF, LH, RH: the legs on the higher ground (y > 0)
STANCES: dict[str, np.ndarray] = {
    "all four": np.ones(4, dtype=bool),
    **{f"{leg} swings": np.arange(4) != i for i, leg in enumerate(("LF", "RF", "LH", "RH"))},
}


def stance_feet(robot_name: str, step: float) -> np.ndarray:
    """(4, 3) foot-sphere centres relative to the CoM [m] of the planner's stance on a side step of ``step``."""
    feet = planning_robot(load_robot(robot_name)).nominal_feet_com.copy()
    feet[LEFT, 2] += step / 2
    feet[~LEFT, 2] -= step / 2
    return feet


def margins_at(
    robot_name: str, feet: np.ndarray, stance: np.ndarray, points: np.ndarray, com_acc_z: float = 0.0
) -> tuple[np.ndarray, int]:
    """m_a [m] (NaN unless "ok") with the CoM moved to each horizontal point (K, 2) [m], and how many had none."""
    robot = load_robot(robot_name)
    margins = np.full(len(points), np.nan)
    acc = np.array([0.0, 0.0, com_acc_z])
    for k, (dx, dy) in enumerate(points):
        shifted = feet - np.array([dx, dy, 0.0])
        lam = standing_state(robot, feet=shifted, contacts=stance.astype(float), com_acc=acc)
        margins[k] = analytic_margin(robot, lam).margin
    return margins, int(np.sum(~np.isfinite(margins)))


def grid(centre: np.ndarray, half: float, resolution: float) -> np.ndarray:
    """(K, 2) points of a square grid of ``resolution`` over ``centre`` +- ``half``."""
    axis = np.round(np.arange(-half, half + resolution / 2, resolution), 10)
    return centre + np.stack(np.meshgrid(axis, axis, indexing="ij"), axis=-1).reshape(-1, 2)


def best_point(
    robot_name: str, feet: np.ndarray, stance: np.ndarray, span: float, resolution: float, com_acc_z: float
) -> dict:
    """Where m_a is largest: a grid over +-span, then a grid 5x finer around its best point."""
    coarse = grid(np.zeros(2), span, resolution)
    margins, missing = margins_at(robot_name, feet, stance, coarse, com_acc_z)
    found = {"point_m": [float("nan")] * 2, "margin_m": float("nan"), "no_margin": missing, "points": len(coarse)}
    if np.isfinite(margins).any():
        fine = grid(coarse[int(np.nanargmax(margins))], resolution, resolution / 5)
        fine_margins, _ = margins_at(robot_name, feet, stance, fine, com_acc_z)
        k = int(np.nanargmax(fine_margins))
        found |= {"point_m": fine[k].tolist(), "margin_m": float(fine_margins[k])}
    return found


def main() -> int:
    ap = parser(__doc__)
    ap.add_argument("--robot", default="anymal_c", choices=("anymal_b", "anymal_c"))
    ap.add_argument("--step", type=float, default=0.18, help="height of the side step [m] (seed 000 Fig. 7: 0.18)")
    ap.add_argument("--span", type=float, default=0.25, help="largest CoM offset along x and y [m]")
    ap.add_argument("--resolution", type=float, default=0.01, help="grid spacing [m] (refined 5x near the best)")
    ap.add_argument("--com-acc-z", type=float, default=0.0, help="vertical CoM acceleration [m/s^2] (load)")
    args = ap.parse_args()
    if not (0 < args.resolution <= args.span) or args.step < 0:
        ap.error("need 0 < --resolution <= --span and --step >= 0")
    grounds = {"flat": stance_feet(args.robot, 0.0), "side step": stance_feet(args.robot, args.step)}
    print(machine_line())
    print(
        f"{args.robot}: side step {args.step:.2f} m, CoM within +-{args.span:.2f} m, grid {args.resolution} m, "
        f"vertical CoM acceleration {args.com_acc_z:g} m/s^2"
    )
    rows, record = [], {}
    for name, stance in STANCES.items():
        found = {
            g: best_point(args.robot, feet, stance, args.span, args.resolution, args.com_acc_z)
            for g, feet in grounds.items()
        }
        flat, step = found["flat"], found["side step"]
        optimum = np.array([flat["point_m"]])
        at_flat_optimum, _ = margins_at(args.robot, grounds["side step"], stance, optimum, args.com_acc_z)
        rows.append(
            (
                name,
                "{:+.1f}, {:+.1f}".format(*(100 * np.array(flat["point_m"]))),
                "{:+.1f}, {:+.1f}".format(*(100 * np.array(step["point_m"]))),
                f"{100 * (step['point_m'][1] - flat['point_m'][1]):+.1f}",
                f"{100 * at_flat_optimum[0]:.1f}",
                f"{100 * step['margin_m']:.1f}",
                f"{step['no_margin']}/{step['points']}",
            )
        )
        record[name] = {**found, "side_step_margin_at_flat_optimum_m": float(at_flat_optimum[0])}
    print_table(
        ["stance", "best (dx, dy), flat [cm]", "best (dx, dy), side step [cm]", "side-step effect, y [cm]",
         "side step: m_a at the flat optimum [cm]", "side step: best m_a [cm]", "side step: no margin"],
        rows,
    )  # fmt: skip
    write_record(args.json, "bench_side_step_margin", args, record)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
