"""Seed 004 §VI-A: a crawl stopped in a triple stance, then pushed until a limit is reached.

The pose: the robot crawls two steps (LH, LF swing) with a planner, plans the base motion before the
RH swing with the same planner, lifts RH and holds it up, so LF, RF and LH carry the robot (the
paper's triple stance, LF the watched leg). Two tests from that pose, each with the FWP factor s of the
simulated pose sampled along (:func:`~margin_rl.planning.crawl.evaluation.fwp_factor`):

* :func:`displacement_test` (the horizontal displacement test): the CoM reference moves sideways away
  from LF (-y) at 5 cm/s. LF unloads when the CoM crosses the RF-LH diagonal; the unilateral
  constraint (a foot cannot pull) then bounds the FWP, so s reaches 0 there. Reported: the
  displacement at which the simulated LF normal force reaches zero and the one at which s does.
* :func:`vertical_disturbance_test`: a downward force on the base origin grows linearly to
  ``max_force``; the controller knows it (see the controller module). Reported: the force at which
  the first servo asks for its torque limit, the joint, LF's knee torque along the way, and the force
  at which s reaches 0.

Both zero crossings of s are linear interpolations between samples (every 5 mm and every 10 N by
default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from margin_rl.planning.crawl.evaluation import fwp_factor
from margin_rl.planning.crawl.gait import CrawlGait, leg_index
from margin_rl.planning.crawl.planners import BaseMotionPlan, CrawlPlanner
from margin_rl.planning.crawl.simulation import CrawlSimulation
from margin_rl.robot import Robot

FloatArray = NDArray[np.float64]

TESTED_SWING = "RH"
"""The leg held up in the tested triple stance (LF, RF and LH on the ground)."""

WATCHED_LEG = "LF"
"""The stance leg whose load and knee torque the tests report (the paper's)."""


def triple_stance(
    robot: Robot, gait: CrawlGait, planner: CrawlPlanner, load_kg: float = 0.0
) -> tuple[CrawlSimulation, BaseMotionPlan]:
    """Crawl two steps with ``planner``, plan and run the base motion before the RH swing, lift RH and hold.

    Returns the simulation, held in the triple stance, and the plan that placed the CoM there.
    """
    sim = CrawlSimulation(robot, gait, load_kg=load_kg)
    for step in range(2):
        sim.crawl_step(step, planner)
    plan = planner.plan(sim.task(TESTED_SWING))
    sim.base_motion(plan)
    sim.lift_and_hold(TESTED_SWING)
    sim.hold(0.5)
    return sim, plan


def _zero_crossing(x: np.ndarray, s: np.ndarray) -> float:
    """First x where s goes from positive to <= 0 (linear interpolation); NaN if it never does."""
    below = np.flatnonzero(s <= 0.0)
    if below.size == 0 or below[0] == 0:
        return math.nan if below.size == 0 else float(x[0])
    k = below[0]
    return float(x[k - 1] + (x[k] - x[k - 1]) * s[k - 1] / (s[k - 1] - s[k]))


@dataclass(frozen=True)
class DisplacementTest:
    """The horizontal displacement test (sampled every ``sample_shift`` of CoM reference)."""

    shift: FloatArray  # (n,) displacement of the CoM reference [m]
    com_shift: FloatArray  # (n,) measured CoM displacement along the test direction [m]
    watched_normal_force: FloatArray  # (n,) LF normal force [N]
    s: FloatArray  # (n,) FWP factor of the simulated pose
    unload_shift: float  # reference displacement at which LF's normal force reached zero [m] (NaN: never)
    s_zero_shift: float  # reference displacement at which s reached zero [m] (NaN: never)
    s_start: float  # s of the held pose


def displacement_test(
    sim: CrawlSimulation, max_shift: float = 0.5, speed: float = 0.05, sample_shift: float = 0.005
) -> DisplacementTest:
    """Move the CoM reference along -y from the held pose until LF unloads (or ``max_shift`` [m])."""
    watched = leg_index(WATCHED_LEG)
    start = sim.com_des.copy()
    direction = np.array([0.0, -1.0, 0.0])
    com0 = sim.com()
    shifts, com_shifts, forces, factors = [], [], [], []
    n_samples = round(max_shift / sample_shift)
    unloaded_for = 0
    for k in range(n_samples + 1):
        shift = k * sample_shift
        shifts.append(shift)
        com_shifts.append(float((sim.com() - com0) @ direction))
        forces.append(float(sim.normal_forces()[watched]))
        factors.append(fwp_factor(sim.robot, sim.snapshot()))
        unloaded_for = unloaded_for + 1 if forces[-1] <= 0.0 else 0
        if unloaded_for >= 2 and factors[-1] < 0:
            break

        def reference(t: float, base: float = shift) -> tuple[FloatArray, FloatArray, FloatArray]:
            return start + (base + speed * t) * direction, speed * direction, np.zeros(3)

        sim.hold(sample_shift / speed, com_reference=reference)
        sim.com_des = start + (shift + sample_shift) * direction
    shift_a, force_a, s_a = np.array(shifts), np.array(forces), np.array(factors)
    return DisplacementTest(
        shift_a, np.array(com_shifts), force_a, s_a, _zero_crossing(shift_a, force_a), _zero_crossing(shift_a, s_a),
        float(s_a[0]),
    )  # fmt: skip


@dataclass(frozen=True)
class VerticalDisturbanceTest:
    """The vertical disturbance test (sampled every ``sample_force``)."""

    force: FloatArray  # (n,) magnitude of the downward force at the samples [N]
    watched_knee_torque: FloatArray  # (n,) LF knee torque asked of the servo [N m]
    max_torque_ratio: FloatArray  # (n,) the largest |torque| / limit over the joints
    s: FloatArray  # (n,) FWP factor of the simulated pose with the force
    limit_force: float  # force at the first control step with a servo at its limit [N] (NaN: never)
    limit_joint: str  # that joint's name ("" if none)
    distribution_limit_force: float  # force at which the controller's QP first found no force distribution
    # within the torque limits [N] (NaN: never): the simulated counterpart of s = 0
    s_zero_force: float  # force at which s reached zero [N] (NaN: never)
    s_start: float  # s of the held pose without the force


def vertical_disturbance_test(
    sim: CrawlSimulation, max_force: float = 1500.0, rate: float = 100.0, sample_force: float = 10.0
) -> VerticalDisturbanceTest:
    """Press the base origin down with a force growing at ``rate`` [N/s] to ``max_force`` [N], from the held
    pose; stops once a servo has been at its limit and s < 0."""
    watched_knee = 3 * leg_index(WATCHED_LEG) + 2
    limits = sim.model.actuator_forcerange[:, 1]
    forces, knee, ratios, factors = [], [], [], []
    limit_force, limit_joint, qp_limit = math.nan, "", math.nan
    n_samples = round(max_force / sample_force)
    for k in range(n_samples + 1):
        magnitude = k * sample_force
        n0 = len(sim.trace.time)

        def push(t: float, base: float = magnitude) -> FloatArray:
            return np.array([0.0, 0.0, -min(base + rate * t, max_force)])

        sim.hold(sample_force / rate, push=push)
        trace = sim.trace
        torque = np.asarray(trace.torque[n0:])
        at_limit = np.asarray(trace.at_limit[n0:])
        if math.isnan(limit_force) and at_limit.any():
            first = int(np.flatnonzero(at_limit.any(axis=1))[0])
            limit_force = float(-trace.ext_force[n0 + first][2])
            limit_joint = sim.robot.joint_names[int(np.flatnonzero(at_limit[first])[0])]
        undistributed = ~np.asarray(trace.distributed[n0:], dtype=bool)
        if math.isnan(qp_limit) and undistributed.any():
            qp_limit = float(-trace.ext_force[n0 + int(np.flatnonzero(undistributed)[0])][2])
        forces.append(magnitude)
        knee.append(float(torque[0, watched_knee]))
        ratios.append(float(np.max(np.abs(torque[0]) / limits)))
        factors.append(fwp_factor(sim.robot, sim.snapshot(disturbance=np.array([0.0, 0.0, -magnitude]))))
        if not math.isnan(limit_force) and factors[-1] < 0:
            break
    force_a, s_a = np.array(forces), np.array(factors)
    return VerticalDisturbanceTest(
        force_a, np.array(knee), np.array(ratios), s_a, limit_force, limit_joint, qp_limit,
        _zero_crossing(force_a, s_a),
        float(s_a[0]),
    )  # fmt: skip
