"""The robot layer: ANYmal B and C from one MJCF each, in MuJoCo and Pinocchio.

``load_robot("anymal_b" | "anymal_c")`` parses ``assets/anymal/<name>.xml`` twice, with MuJoCo
(``mujoco.MjModel.from_xml_path``) and with Pinocchio (``pinocchio.buildModelFromMJCF``), and exposes the
facts every other layer needs by name: leg and joint order, joint/torque/velocity limits, PD gains,
feet, total mass, the ``standing`` keyframe, analytic leg inverse kinematics, 3x3 leg Jacobians and
per-leg bias torques. No physical number is typed in Python: they are all read from the MJCF.

Modules (every public name is re-exported here)::

    model        Robot, load_robot, load_robot_from_xml, available_robots, the MJCF checks, standing ctrl
    kinematics   closed-form leg kinematics, the analytic IK and its tables (Robot's kinematics methods)
    dynamics     Pinocchio: leg Jacobians, bias torques, centroidal momentum rate (Robot's dynamics methods)
    mjcf_names   the names the environments read the MJCF by (bodies, sensors, keyframe, floor, qpos/qvel slices)
    cli          margin-rl-robots / python -m margin_rl: the robots' report

Conventions
-----------
* Legs ``LF, RF, LH, RH``; each leg has joints ``<leg>_HAA, <leg>_HFE, <leg>_KFE`` (the actuator and qpos
  order of the MJCF), bodies ``<leg>_HIP, <leg>_THIGH, <leg>_SHANK`` and a site ``<leg>_FOOT`` at the
  centre of the foot sphere. "Foot position" always means that site.
* Base frame B: x forward, y left, z up, origin at the base body origin. Foot positions handed to the
  kinematics are expressed in B relative to that origin [m].
* Quaternions are (w, x, y, z) at this API, as in MuJoCo. Pinocchio's (x, y, z, w) order stays inside.
"""

from __future__ import annotations

from margin_rl.robot import mjcf_names
from margin_rl.robot.cli import format_report, main
from margin_rl.robot.dynamics import RigidBodyDynamics
from margin_rl.robot.kinematics import (
    IKSolution,
    LegGeometry,
    UnreachableFootError,
    leg_forward_kinematics,
    leg_frames,
    leg_inverse_kinematics,
    quat_wxyz_to_matrix,
)
from margin_rl.robot.model import (
    LEG_JOINTS,
    LEGS,
    STANDING_KEYFRAME,
    Robot,
    RobotModelError,
    assets_dir,
    available_robots,
    load_robot,
    load_robot_from_xml,
    robot_xml_path,
    scene_xml_path,
    standing_equilibrium_ctrl,
)

__all__ = [
    "LEGS",
    "LEG_JOINTS",
    "STANDING_KEYFRAME",
    "IKSolution",
    "LegGeometry",
    "RigidBodyDynamics",
    "Robot",
    "RobotModelError",
    "UnreachableFootError",
    "assets_dir",
    "available_robots",
    "format_report",
    "leg_forward_kinematics",
    "leg_frames",
    "leg_inverse_kinematics",
    "load_robot",
    "load_robot_from_xml",
    "main",
    "mjcf_names",
    "quat_wxyz_to_matrix",
    "robot_xml_path",
    "scene_xml_path",
    "standing_equilibrium_ctrl",
]
