"""``margin-rl-robots`` / ``python -m margin_rl``: a report of the shipped robots."""

from __future__ import annotations

import argparse

from margin_rl.robot.model import Robot, available_robots, load_robot, standing_equilibrium_ctrl


def format_report(robot: Robot) -> str:
    """Human-readable summary: mass, standing height, joint and torque limits, standing feet."""
    s = robot.summary()
    lines = [
        f"{robot.name}: {s['total_mass_kg']:.3f} kg, standing base height {s['standing_height_m']:.4f} m, "
        f"foot radius {s['foot_radius_m']:.3f} m, PD kp {robot.kp[0]:g} N m/rad, kd {robot.kd[0]:g} N m s/rad",
        f"  {'joint':<8} {'lower':>8} {'upper':>8} {'|tau|max':>9} {'|qd|max':>8} {'standing':>9}",
    ]
    for i, jn in enumerate(robot.joint_names):
        lines.append(
            f"  {jn:<8} {robot.joint_lower[i]:>8.3f} {robot.joint_upper[i]:>8.3f} {robot.torque_limits[i]:>9.1f}"
            f" {robot.velocity_limits[i]:>8.1f} {robot.standing_joint_pos[i]:>9.3f}"
        )
    lines.append("  feet at the standing pose (base frame) [m]:")
    for leg, p in s["standing_feet_base_frame_m"].items():  # type: ignore[union-attr]
        lines.append(f"    {leg}: x {p[0]:+.4f}  y {p[1]:+.4f}  z {p[2]:+.4f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Print a short report of the shipped robots (``margin-rl-robots``)."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("robots", nargs="*", help=f"robot names (default: all of {', '.join(available_robots())})")
    parser.add_argument(
        "--keyframe", action="store_true", help="print the equilibrium 'standing' keyframe ctrl for the MJCF"
    )
    args = parser.parse_args(argv)
    for name in args.robots or available_robots():
        robot = load_robot(name)
        if args.keyframe:
            ctrl = standing_equilibrium_ctrl(robot)
            print(
                f"{name} standing ctrl: "
                + "  ".join(" ".join(f"{c:.4f}" for c in ctrl[i : i + 3]) for i in range(0, 12, 3))
            )
        else:
            print(format_report(robot))
            print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
