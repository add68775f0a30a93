"""The crawl executed in MuJoCo on the robot's MJCF, with real joint torques and their limits.

:class:`CrawlSimulation` owns one MuJoCo model and data of the robot on flat ground (the scene file),
optionally with a carried load (a constant downward force on the base body, at its CoM), a hindered
joint (one actuator's force range reduced; the planners and the controller are told) and rough ground
(:class:`~margin_rl.planning.crawl.terrain.TileTerrain`: level tiles at random heights). It runs crawl
steps (:meth:`CrawlSimulation.crawl_step`: plan the base motion, move the base, swing a leg) and holds a
pose while a test pushes (:meth:`CrawlSimulation.hold`). Every control step is recorded in a
:class:`Trace`: time, CoM, planned CoM, joint torques asked of the servos and whether any was at its
limit, the feet's normal forces, the stance flags and the external force.

Frames: world W (z up, the crawl heads +x); SI units.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from margin_rl.planning.crawl.controller import ControllerGains, QuasiStaticController
from margin_rl.planning.crawl.gait import LEGS, CrawlGait, leg_index, next_foothold, swing_leg
from margin_rl.planning.crawl.planners import BaseMotionPlan, BaseMotionTask, CrawlPlanner
from margin_rl.planning.crawl.polytopes import StanceSnapshot
from margin_rl.planning.crawl.terrain import TileTerrain
from margin_rl.robot import Robot
from margin_rl.robot.mjcf_names import (
    BASE_ANGULAR_VELOCITY_QVEL,
    BASE_BODY,
    BASE_POSITION_QPOS,
    COM_VELOCITY_SENSOR,
    FLOOR_GEOM,
    JOINT_QPOS,
    JOINT_QVEL,
    STANDING_KEYFRAME,
    foot_geom,
)

FloatArray = NDArray[np.float64]

#: A joint's servo counts as at its torque limit when the torque it asks for reaches this fraction of the
#: actuator's force range (MuJoCo clips at the range; 0.999 absorbs rounding).
LIMIT_FRACTION = 0.999

#: Seconds over which a foot's normal force is ramped up after touchdown and down before lift-off (the
#: controller's force distribution otherwise moves the load between legs in one step, a torque transient).
LOAD_RAMP = 0.15

#: MuJoCo no-slip iterations (``opt.noslip_iterations``) of the crawl's model.
NOSLIP_ITERATIONS = 10


@dataclass(frozen=True)
class HinderedJoint:
    """One joint whose torque limit is reduced (seed 004 §VI-C): ``leg`` and joint ``index`` (0 HAA, 1 HFE,
    2 KFE), limit scaled by ``fraction`` of the robot's."""

    leg: str
    index: int
    fraction: float

    def __post_init__(self) -> None:
        leg_index(self.leg)
        if self.index not in (0, 1, 2):
            raise ValueError(f"HinderedJoint.index must be 0 (HAA), 1 (HFE) or 2 (KFE), got {self.index!r}")
        if not (0 < self.fraction <= 1):
            raise ValueError(f"HinderedJoint.fraction must be in (0, 1], got {self.fraction!r}")


@dataclass
class Trace:
    """Per-control-step record of a simulation (lists while running; :meth:`arrays` for analysis)."""

    time: list[float] = field(default_factory=list)
    com: list[FloatArray] = field(default_factory=list)
    com_des: list[FloatArray] = field(default_factory=list)
    torque: list[FloatArray] = field(default_factory=list)  # (12,) the servos' unclipped torques [N m]
    at_limit: list[NDArray[np.bool_]] = field(default_factory=list)  # (12,)
    normal_force: list[FloatArray] = field(default_factory=list)  # (4,) [N]
    stance: list[NDArray[np.bool_]] = field(default_factory=list)  # (4,)
    ext_force: list[FloatArray] = field(default_factory=list)  # (3,) test disturbance on the base [N]
    distributed: list[bool] = field(default_factory=list)
    phase: list[str] = field(default_factory=list)  # "base_motion", "swing:<leg>", "hold"
    qpos: list[FloatArray] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.asarray(values) for name, values in vars(self).items()}


class CrawlSimulation:
    """The robot in MuJoCo, driven by :class:`QuasiStaticController` (see the module docstring)."""

    def __init__(
        self,
        robot: Robot,
        gait: CrawlGait,
        load_kg: float = 0.0,
        hindered: HinderedJoint | None = None,
        gains: ControllerGains | None = None,
        terrain: TileTerrain | None = None,
    ) -> None:
        if not (np.isfinite(load_kg) and load_kg >= 0):
            raise ValueError(f"load_kg must be >= 0, got {load_kg!r}")
        self.robot, self.gait, self.load_kg, self.hindered = robot, gait, float(load_kg), hindered
        self.terrain = terrain
        if terrain is None:
            self.model = mujoco.MjModel.from_xml_path(str(robot.scene_path))
        else:
            spec = mujoco.MjSpec.from_file(str(robot.scene_path))
            terrain.add_to(spec, friction=float(spec.geom(FLOOR_GEOM).friction[0]))
            self.model = spec.compile()
        # MuJoCo's soft friction lets a foot creep under a steady tangential force (~2 cm/s at 50 N);
        # the no-slip pass makes static friction hold, as a statically stable crawl assumes.
        self.model.opt.noslip_iterations = NOSLIP_ITERATIONS
        self.data = mujoco.MjData(self.model)
        self.torque_limits = np.asarray(robot.torque_limits, dtype=float).reshape(4, 3).copy()
        if hindered is not None:
            j = 3 * leg_index(hindered.leg) + hindered.index
            self.torque_limits.reshape(12)[j] *= hindered.fraction
            self.model.actuator_forcerange[j] = self.torque_limits.reshape(12)[j] * np.array([-1.0, 1.0])
        self.mu = float(self.model.geom(FLOOR_GEOM).friction[0])
        self.controller = QuasiStaticController(robot, self.torque_limits, self.mu, gains)
        self._base = self.model.body(BASE_BODY).id
        self._feet_sites = [self.model.site(name).id for name in robot.foot_names]
        self._feet_geoms = [self.model.geom(foot_geom(leg)).id for leg in LEGS]
        self._com_vel_adr = self.model.sensor(COM_VELOCITY_SENSOR).adr[0]
        self._shanks = [self.model.geom_bodyid[g] for g in self._feet_geoms]
        self._leg_dofs = [self.model.jnt_dofadr[self.model.actuator_trnid[3 * i : 3 * i + 3, 0]] for i in range(4)]
        self._kp = np.asarray(robot.kp, dtype=float)
        self._kd = np.asarray(robot.kd, dtype=float)
        self.reset()

    # ----------------------------------------------------------------- state
    def reset(self) -> None:
        """The standing keyframe, settled for 1 s under the controller."""
        mujoco.mj_resetDataKeyframe(self.model, self.data, self.model.key(STANDING_KEYFRAME).id)
        mujoco.mj_forward(self.model, self.data)
        self.trace = Trace()
        self.plans: list[BaseMotionPlan] = []
        self.time = 0.0
        self.steps_taken = np.zeros(4, dtype=int)
        self.feet_des = self.feet()
        self.footholds = self.feet()
        self._ramp: tuple[int, bool, float] | None = None  # (leg, loading, start time within the run)
        self._full_load = (self.robot.total_mass + self.load_kg) * self.robot.gravity
        self.stance = np.ones(4, dtype=bool)
        self.com_des = self.com()
        self.run(1.0, self._still, phase="settle")

    def com(self) -> FloatArray:
        """(3,) the robot's CoM [m, W] (MuJoCo's subtree CoM of the base, what the ``com`` sensor reads)."""
        return self.data.subtree_com[self._base].copy()

    def com_vel(self) -> FloatArray:
        return self.data.sensordata[self._com_vel_adr : self._com_vel_adr + 3].copy()

    def feet(self) -> FloatArray:
        """(4, 3) foot-sphere centres [m, W]."""
        return self.data.site_xpos[self._feet_sites].copy()

    def rotation(self) -> FloatArray:
        return self.data.xmat[self._base].reshape(3, 3).copy()

    def external_wrench(self, disturbance: np.ndarray | None = None) -> tuple[FloatArray, FloatArray]:
        """The external wrench on the robot: the carried load at the base body's CoM and a test's
        ``disturbance`` (3,) [N] at the base origin; force (3,) [N] and moment (3,) about the robot's CoM [N m]."""
        load = np.array([0.0, 0.0, -self.load_kg * self.robot.gravity])
        push = np.zeros(3) if disturbance is None else np.asarray(disturbance, dtype=float)
        com = self.com()
        moment = np.cross(self.data.xipos[self._base] - com, load) + np.cross(self.data.xpos[self._base] - com, push)
        return load + push, moment

    def normal_forces(self) -> FloatArray:
        """(4,) normal contact force on each foot [N] (MuJoCo's contact solution)."""
        out = np.zeros(4)
        wrench = np.zeros(6)
        for i in range(self.data.ncon):
            contact = self.data.contact[i]
            for leg, geom in enumerate(self._feet_geoms):
                if geom in (contact.geom1, contact.geom2):
                    mujoco.mj_contactForce(self.model, self.data, i, wrench)
                    out[leg] += wrench[0] * abs(contact.frame[2])  # normal component, projected on z
        return out

    def _still(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The CoM reference of a held pose: ``com_des`` at rest."""
        return self.com_des, np.zeros(3), np.zeros(3)

    def normal_caps(self, t: float) -> FloatArray:
        """(4,) normal-force bounds [N] at time ``t`` of the current run (the load ramps, :data:`LOAD_RAMP`)."""
        caps = np.full(4, np.inf)
        if self._ramp is not None:
            leg, up, start = self._ramp
            fraction = np.clip((t - start) / LOAD_RAMP, 0.0, 1.0)
            caps[leg] = self._full_load * (fraction if up else 1.0 - fraction)
        return caps

    def contact_points(self) -> FloatArray:
        """(4, 3) the lowest point of each foot sphere (where the ground force acts on flat ground) [m, W]."""
        return self.feet() - np.array([0.0, 0.0, self.robot.foot_radius])

    def contact_jacobians(self, points: np.ndarray) -> FloatArray:
        """(4, 3, 3) Jacobians of the contact points, moving with each shank, w.r.t. the leg's three joints."""
        jacp = np.zeros((3, self.model.nv))
        out = np.zeros((4, 3, 3))
        for leg in range(4):
            mujoco.mj_jac(self.model, self.data, jacp, None, points[leg], self._shanks[leg])
            out[leg] = jacp[:, self._leg_dofs[leg]]
        return out

    # ----------------------------------------------------------------- stepping
    def _apply(self, disturbance: np.ndarray) -> None:
        """Write the load and the ``disturbance`` into the base's ``xfrc_applied`` (MuJoCo applies it at the
        body's CoM, so the disturbance, meant for the base origin, brings its moment)."""
        load = np.array([0.0, 0.0, -self.load_kg * self.robot.gravity])
        self.data.xfrc_applied[self._base, :3] = load + disturbance
        self.data.xfrc_applied[self._base, 3:] = np.cross(
            self.data.xpos[self._base] - self.data.xipos[self._base], disturbance
        )

    def run(
        self,
        duration: float,
        com_reference: Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]],
        phase: str,
        push: Callable[[float], np.ndarray] | None = None,
        stop: Callable[[], bool] | None = None,
    ) -> None:
        """Run for ``duration`` [s] tracking ``com_reference(t) -> (com, vel, acc)``; ``push(t)`` is a test force on
        the base origin [N] (known to the controller), ``stop()`` ends the run early."""
        dt = self.model.opt.timestep
        steps = round(duration / dt)
        for k in range(steps):
            t = k * dt
            com_des, vel_des, acc_des = com_reference(t)
            disturbance = np.zeros(3) if push is None else np.asarray(push(t), dtype=float)
            com = self.com()
            ext_f, ext_t = self.external_wrench(disturbance)  # the controller is told it
            self._apply(disturbance)
            # Stance feet stay where they are (a sphere rolls a little as its shank turns).
            self.feet_des[self.stance] = self.feet()[self.stance]
            rotation = self.rotation()
            ang_vel = rotation @ self.data.qvel[BASE_ANGULAR_VELOCITY_QVEL]
            q = self.data.qpos[JOINT_QPOS].copy()
            points = self.contact_points()
            bias = np.stack([self.data.qfrc_bias[dofs] for dofs in self._leg_dofs])
            cmd = self.controller.command(
                q, rotation, com, self.com_vel(), ang_vel, self.data.qpos[BASE_POSITION_QPOS].copy(), points,
                self.contact_jacobians(points), bias, self.feet_des, self.stance, com_des, vel_des, acc_des, ext_f,
                ext_t, self.normal_caps(t),
            )  # fmt: skip
            self.data.ctrl[:] = cmd.ctrl
            asked = self._kp * (cmd.ctrl - q) - self._kd * self.data.qvel[JOINT_QVEL]
            limit = self.model.actuator_forcerange[:, 1]
            tr = self.trace
            tr.time.append(self.time)
            tr.com.append(com)
            tr.com_des.append(np.asarray(com_des, dtype=float).copy())
            tr.torque.append(asked)
            tr.at_limit.append(np.abs(asked) >= LIMIT_FRACTION * limit)
            tr.normal_force.append(self.normal_forces())
            tr.stance.append(self.stance.copy())
            tr.ext_force.append(disturbance)
            tr.distributed.append(cmd.distributed)
            tr.phase.append(phase)
            tr.qpos.append(self.data.qpos.copy())
            mujoco.mj_step(self.model, self.data)
            self.time += dt
            if stop is not None and stop():
                break

    # ----------------------------------------------------------------- the crawl
    def task(self, swing: str) -> BaseMotionTask:
        """The base-motion task of the step before ``swing`` lifts, from the desired CoM and the measured feet."""
        load_f, load_t = self.external_wrench()
        return BaseMotionTask(
            com_start=self.com_des.copy(), feet=self.feet(), swing=swing, normals=np.tile([0.0, 0.0, 1.0], (4, 1)),
            mu=self.mu, ext_force=load_f, ext_torque=load_t, torque_limits=self.torque_limits,
            foothold=self.upcoming_foothold(swing),
        )  # fmt: skip

    def upcoming_foothold(self, leg: str) -> FloatArray:
        """Where ``leg`` lands on its next step (:func:`next_foothold`), from its planned foothold, not the
        measured touchdown, so that landing errors do not accumulate."""
        i = leg_index(leg)
        target = next_foothold(self.footholds[i], self.gait.stride, self.steps_taken[i] == 0, self.footholds[i, 2])
        if self.terrain is not None:  # the foot-sphere centre on the tile under the foothold
            target[2] = self.terrain.height(target[0], target[1]) + self.robot.foot_radius
        return target

    def snapshot(self, disturbance: np.ndarray | None = None, stance: np.ndarray | None = None) -> StanceSnapshot:
        """The current pose as a :class:`StanceSnapshot`: measured CoM and feet, the stance (or ``stance`` (4,)),
        the load and a test's ``disturbance`` (3,) [N] at the base origin as the external wrench."""
        force, torque = self.external_wrench(disturbance)
        feet_down = self.stance if stance is None else np.asarray(stance, dtype=bool)
        return StanceSnapshot(
            self.com(), self.feet(), feet_down.copy(), np.tile([0.0, 0.0, 1.0], (4, 1)), self.mu, force, torque,
            self.torque_limits.copy(),
        )  # fmt: skip

    def replayed_snapshot(self, qpos: np.ndarray, stance: np.ndarray) -> StanceSnapshot:
        """The :class:`StanceSnapshot` of a recorded state (``qpos`` (19,), ``stance`` (4,)), with the load.

        Sets the simulation's state to ``qpos`` (positions only): use it on a finished run.
        """
        self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)
        return self.snapshot(stance=stance)

    def base_offset(self) -> FloatArray:
        """(3,) the base origin relative to the CoM [m, W] (where the tests push)."""
        return self.data.xpos[self._base] - self.com()

    def base_motion(self, plan: BaseMotionPlan) -> None:
        self.plans.append(plan)
        self.run(plan.duration, plan.com_at, phase="base_motion")
        self.com_des = plan.end_com

    def swing(self, leg: str) -> None:
        """Lift ``leg``, move it to its foothold (:func:`next_foothold`) along a raised-cosine arc, put it down."""
        i = leg_index(leg)
        self._ramp = (i, False, 0.0)
        self.run(LOAD_RAMP, self._still, phase=f"unload:{leg}")
        start = self.feet_des[i].copy()
        target = self.upcoming_foothold(leg)
        self.footholds[i] = target
        self.steps_taken[i] += 1
        duration = self.gait.swing_duration
        self._ramp = None
        self.stance = np.ones(4, dtype=bool)
        self.stance[i] = False

        def reference(t: float) -> tuple[np.ndarray, np.ndarray]:
            # Up, across (done at 80 % of the swing), down: the foot reaches its foothold before it lands.
            s = min(t / duration, 1.0)
            blend = 0.5 - 0.5 * np.cos(np.pi * min(s / 0.8, 1.0))
            self.feet_des[i] = start + blend * (target - start)
            self.feet_des[i, 2] += self.gait.step_height * np.sin(np.pi * s)
            return self._still(t)

        self.run(duration, reference, phase=f"swing:{leg}")
        self.feet_des[i] = target
        self.stance[:] = True
        self._ramp = (i, True, 0.0)
        self.run(LOAD_RAMP, self._still, phase="touchdown")
        self._ramp = None
        self.feet_des = self.feet()

    def crawl_step(self, step: int, planner: CrawlPlanner, lift: bool = True) -> BaseMotionPlan:
        """One crawl step: plan and run the base motion before ``swing_leg(step)``, then swing it (or, with
        ``lift=False``, stop before the swing)."""
        leg = swing_leg(step)
        plan = planner.plan(self.task(leg))
        self.base_motion(plan)
        if lift:
            self.swing(leg)
        return plan

    def lift_and_hold(self, leg: str, height: float = 0.08, duration: float = 0.6) -> None:
        """Unload ``leg``, lift it straight up by ``height`` and keep it there (a triple stance to test)."""
        i = leg_index(leg)
        self._ramp = (i, False, 0.0)
        self.run(LOAD_RAMP, self._still, phase=f"unload:{leg}")
        self._ramp = None
        start = self.feet_des[i].copy()
        self.stance[i] = False

        def reference(t: float) -> tuple[np.ndarray, np.ndarray]:
            s = min(t / duration, 1.0)
            self.feet_des[i] = start + np.array([0.0, 0.0, height * (0.5 - 0.5 * np.cos(np.pi * s))])
            return self._still(t)

        self.run(duration, reference, phase=f"swing:{leg}")

    def hold(
        self,
        duration: float,
        com_reference: Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
        push: Callable[[float], np.ndarray] | None = None,
        stop: Callable[[], bool] | None = None,
    ) -> None:
        """Hold the current stance for ``duration`` [s] (optionally moving the CoM or pushing the base)."""
        reference = com_reference or self._still
        self.run(duration, reference, phase="hold", push=push, stop=stop)
