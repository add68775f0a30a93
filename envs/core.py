"""The batched ANYmal simulation behind every environment adapter (single, vector, SB3, rsl-rl).

One :class:`AnymalCore` steps ``num_envs`` MuJoCo simulations with ``mujoco.batch.Batch`` on a native
thread pool, evaluates the stability margin once per batch per step, and autoresets finished
environments in the same step (their last observation is returned separately).

:meth:`AnymalCore.step` runs these stages, each a method of its own, once per policy step:

1. ``_actuate``: action a in [-1, 1]^12 (clipped; NaN raises) -> position-servo targets
   ctrl = ctrl_standing + s a (ctrl_standing: the keyframe's equilibrium targets, so a = 0 holds the
   standing pose); pushes written to the base (xfrc_applied);
2. ``_simulate``: ``decimation`` physics steps at the MJCF timestep, and the divergence check
   (:meth:`_invalid_state` before and after the step, and a clock that did not advance);
3. ``_measure``: the world-frame state (:class:`SimulationState`) from the batch's arrays;
4. ``_estimate_accelerations``: CoM, base angular and joint accelerations by finite differences over
   the policy step (20 ms: the mean acceleration over the step, exact on average), the first two
   smoothed by an exponential filter (``EnvConfig.acceleration_filter``, 0.5 by default);
5. ``_stability``: lambda (seed 000 eq. 4, :mod:`margin_rl.envs.stability_input`) and the margin of the
   configured kind (:mod:`margin_rl.envs.margin_kinds`), clipped to :data:`MARGIN_CLIP` (states the
   kind cannot rate get the lower clip); a push enters lambda as f_ext;
6. ``_track_air_time``: touchdowns and the air time of each foot;
7. rewards (:mod:`margin_rl.envs.rewards`), ``_terminations`` (base or thigh contact, height or tilt
   bounds, a diverged simulation) and truncation at the episode length, ``_info``;
8. observations and the same-step autoreset of finished environments.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import batch as mj_batch

from margin_rl.envs.config import EnvConfig, RandomizationConfig
from margin_rl.envs.margin_kinds import make_margin_function
from margin_rl.envs.observations import (
    FOOT_HEIGHT_OFFSETS,
    POLICY_OBSERVATIONS,
    PRIVILEGED_OBSERVATIONS,
    assemble,
)
from margin_rl.envs.rewards import compute_rewards
from margin_rl.envs.scene import build_model
from margin_rl.envs.stability_input import (
    heading_rotation,
    lambda_from_simulation,
    stability_state_from_simulation,
    stance_width,
)
from margin_rl.envs.terrain import flat_terrain, rough_terrain
from margin_rl.robot import load_robot, quat_wxyz_to_matrix
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, StabilityState

__all__ = [
    "MARGIN_CLIP",
    "AnymalCore",
    "SimulationState",
    "StepOutput",
    "heading_rotation",
    "lambda_from_simulation",
]

MARGIN_CLIP: tuple[float, float] = (-0.5, 0.5)
"""Range [m] the margin term is clipped to (the learned model extrapolates outside its data)."""

DIVERGED_SPEED = 1e3
"""A generalised velocity above this (m/s, rad/s) marks a simulation as diverged."""


def check_finite_outputs(config: EnvConfig, reward: np.ndarray | float, *observations: np.ndarray) -> None:
    """FloatingPointError if a reward or an observation is NaN or inf.

    The core keeps diverged simulations finite (and flags them in ``info["diverged"]``); what is left is a
    setting so large that float arithmetic overflows, which no agent should train on. Checked in the core, so
    every adapter (Gymnasium, SB3, rsl-rl) gets the same error.
    """
    bad_observation = not all(np.all(np.isfinite(o)) for o in observations)
    if not bad_observation and np.all(np.isfinite(reward)):
        return
    rnd = config.randomization
    raise FloatingPointError(
        f"the {'observation' if bad_observation else 'reward'} is not finite: an EnvConfig value is too large for "
        f"float arithmetic (margin_weight={config.margin_weight}, alive_bonus={config.alive_bonus}, "
        f"randomization.observation_noise={rnd.observation_noise}, reset_velocity_noise={rnd.reset_velocity_noise}); "
        "use values of the order of the defaults"
    )


def _usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the platform reports one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows: no affinity API
        return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class SimulationState:
    """World-frame state of some environments, read from the batch's arrays (N leading)."""

    base_pos: np.ndarray  # (N, 3) [m]
    base_rot: np.ndarray  # (N, 3, 3) R_WB
    lin_vel_world: np.ndarray  # (N, 3) base linear velocity [m/s]
    ang_vel_body: np.ndarray  # (N, 3) base angular velocity, base frame [rad/s]
    ang_vel_world: np.ndarray  # (N, 3) [rad/s]
    joint_pos: np.ndarray  # (N, 12) [rad]
    joint_vel: np.ndarray  # (N, 12) [rad/s]
    com: np.ndarray  # (N, 3) whole-body CoM [m]
    com_vel: np.ndarray  # (N, 3) [m/s]
    feet: np.ndarray  # (N, 4, 3) foot-sphere centres [m]
    contacts: np.ndarray  # (N, 4) bool, foot-terrain contact
    base_contact: np.ndarray  # (N,) bool
    thigh_contacts: np.ndarray  # (N, 4) bool
    knees: np.ndarray  # (N, 4, 3) knee (KFE joint) positions [m]

    def finite(self) -> SimulationState:
        """The same state with every non-finite float replaced by 0 (a diverged step's bookkeeping)."""
        changes = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value.dtype.kind == "f":
                changes[f.name] = np.where(np.isfinite(value), value, 0.0)
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Accelerations:
    """Finite-difference accelerations over the policy step (world frame).

    ``com`` and ``base_angular`` are the filtered estimates lambda is built from; ``com_measured`` and
    ``base_angular_measured`` the unfiltered differences the info reports (what the comparison's base
    acceleration metrics measure, whatever the filter).
    """

    com: np.ndarray  # (N, 3) [m/s^2], EMA-filtered (EnvConfig.acceleration_filter)
    base_angular: np.ndarray  # (N, 3) [rad/s^2], EMA-filtered
    joints: np.ndarray  # (N, 12) [rad/s^2], unfiltered
    com_measured: np.ndarray  # (N, 3) [m/s^2], unfiltered
    base_angular_measured: np.ndarray  # (N, 3) [rad/s^2], unfiltered


@dataclass(frozen=True)
class StepOutput:
    """Result of :meth:`AnymalCore.step` for all environments."""

    observation: np.ndarray  # (N, obs) float32, after autoreset for finished environments
    reward: np.ndarray  # (N,) float64
    terminated: np.ndarray  # (N,) bool
    truncated: np.ndarray  # (N,) bool
    info: dict[str, np.ndarray]  # per-environment arrays (reward_<term>, margin, accelerations, ...)
    final_observation: np.ndarray  # (N, obs): the observation before autoreset (valid where done)
    privileged: np.ndarray | None  # (N, priv) critic observation, after autoreset


class AnymalCore:
    """Batched ANYmal environments (see the module docstring)."""

    def __init__(
        self, config: EnvConfig, num_envs: int, seed: int | None = None, autoreset: bool = True, truncate: bool = True
    ) -> None:
        """``autoreset``: reset finished environments inside :meth:`step` (vector semantics); ``truncate``:
        end episodes at ``episode_length_s`` (off when a TimeLimit wrapper does it)."""
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.config = config
        self.num_envs = num_envs
        self.autoreset, self.truncate = autoreset, truncate
        self.robot = load_robot(config.robot)
        self.terrain = flat_terrain() if config.terrain == "flat" else rough_terrain(config.terrain_config, seed or 0)
        self.model = build_model(self.robot, self.terrain, config.terrain_config)
        self.dt = float(self.model.opt.timestep * config.decimation)
        self.max_episode_steps = round(config.episode_length_s / self.dt)
        # One MuJoCo thread per core this process may run on: nthread=0 would start one per core of the
        # machine, so several trainings pinned to a few cores each (taskset, cgroups) would oversubscribe.
        self.batch = mj_batch.Batch(self.model, nsim=num_envs, nthread=_usable_cores())
        self._qpos, self._qvel = self.batch.bind("qpos"), self.batch.bind("qvel")
        self._ctrl, self._xfrc = self.batch.bind("ctrl"), self.batch.bind("xfrc_applied")
        self._sensors, self._site_xpos = self.batch.bind("sensordata"), self.batch.bind("site_xpos")
        self._xpos = self.batch.bind("xpos")
        self._forces = self.batch.bind("actuator_force")
        self._time = self.batch.bind("time")
        m = self.model
        self._base = m.body("base").id
        self._feet = np.array([m.site(f).id for f in self.robot.foot_names])
        # The shank body's origin is the knee (KFE) joint, the lower end of the thigh whose contact ends an episode.
        self._knees = np.array([m.body(f"{leg}_SHANK").id for leg in self.robot.leg_names])
        self._sensor = {
            m.sensor(i).name: slice(m.sensor_adr[i], m.sensor_adr[i] + m.sensor_dim[i]) for i in range(m.nsensor)
        }
        # First entry ("found") of each contact sensor, gathered with one index per step.
        self._foot_contact_adr = np.array([m.sensor(f"{leg}_foot_contact").adr[0] for leg in self.robot.leg_names])
        self._thigh_contact_adr = np.array([m.sensor(f"{leg}_THIGH_contact").adr[0] for leg in self.robot.leg_names])
        self._base_contact_adr = int(m.sensor("base_contact").adr[0])
        key = m.key("standing").id
        self._key_qpos, self._key_ctrl = m.key_qpos[key].copy(), m.key_ctrl[key].copy()
        self._standing_joint_pos = self.robot.standing_joint_pos
        self._floor = m.geom("floor").id
        self._friction = self.batch.expand("geom_friction")
        base_friction = float(m.geom_friction[self._floor, 0])
        self.mu = np.full(num_envs, base_friction)
        self._margin_fn = make_margin_function(config.margin, self.robot, config.margin_weights, MARGIN_CLIP[0])
        self.rng = np.random.default_rng(seed)
        self._added_mass = np.zeros(num_envs)
        if config.randomization.added_base_mass is not None:
            masses = self.batch.expand("body_mass")
            self._added_mass = self.rng.uniform(*config.randomization.added_base_mass, size=num_envs)
            masses[:, self._base] = m.body_mass[self._base] + self._added_mass
            self.batch.set_const()
        n = num_envs
        self.command = np.zeros((n, 3))
        self.last_action = np.zeros((n, 12))
        self.episode_step = np.zeros(n, dtype=np.int64)
        self._prev_com_vel = np.zeros((n, 3))
        self._prev_ang_vel = np.zeros((n, 3))
        self._prev_joint_vel = np.zeros((n, 12))
        self._com_acc = np.zeros((n, 3))
        self._ang_acc = np.zeros((n, 3))
        self._air_time = np.zeros((n, 4))
        self._prev_contacts = np.ones((n, 4), dtype=bool)
        self._push_steps_left = np.zeros(n, dtype=np.int64)
        self._push_force = np.zeros((n, 3))
        self._push_applied = np.zeros((n, 3))
        self._next_push = np.full(n, np.inf)
        self.observation_size = sum(t.size for t in POLICY_OBSERVATIONS)
        self.privileged_size = sum(t.size for t in PRIVILEGED_OBSERVATIONS)
        self._last_margin = np.zeros(n)
        self._last_lambda = np.zeros((n, LAMBDA_DIM))

    # ------------------------------------------------------------------ reset
    def reset(self, ids: np.ndarray | None = None, seed: int | None = None) -> None:
        """Reset environments ``ids`` (all if None) to a randomised standing state and new commands.

        ``seed`` (optional) first reseeds the generator behind every random draw of the core (resets,
        commands, noise, pushes), so the same seed gives the same rollout.
        """
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        ids = np.arange(self.num_envs) if ids is None else np.asarray(ids, dtype=np.int64)
        if ids.size == 0:
            return
        cfg, rnd, rng = self.config, self.config.randomization, self.rng
        self.batch.reset(ids=ids, keyframe=self.model.key("standing").id, stage=mujoco.mjtStage.mjSTAGE_NONE)
        qpos = np.tile(self._key_qpos, (len(ids), 1))
        spawn = self.terrain.spawn_points[rng.integers(0, len(self.terrain.spawn_points), size=len(ids))]
        qpos[:, 0:2] = spawn[:, :2]
        qpos[:, 2] = spawn[:, 2] + self._key_qpos[2] + 0.02
        qpos[:, 7:] += rng.uniform(-1, 1, size=(len(ids), 12)) * rnd.reset_joint_noise
        qvel = np.zeros((len(ids), self.model.nv))
        qvel[:, :6] = rng.uniform(-1, 1, size=(len(ids), 6)) * rnd.reset_velocity_noise
        self._qpos[ids] = qpos
        self._qvel[ids] = qvel
        self._ctrl[ids] = self._key_ctrl
        self._xfrc[ids] = 0.0
        if rnd.friction is not None:
            self.mu[ids] = rng.uniform(*rnd.friction, size=len(ids))
            self._friction[ids, self._floor, 0] = self.mu[ids]
        self.batch.forward(ids=ids)
        c = cfg.command
        self.command[ids] = np.column_stack(
            [
                rng.uniform(*c.forward_velocity, len(ids)),
                rng.uniform(*c.lateral_velocity, len(ids)),
                rng.uniform(*c.yaw_rate, len(ids)),
            ]
        )
        self.last_action[ids] = 0.0
        self.episode_step[ids] = 0
        state = self._read(ids)
        self._prev_com_vel[ids] = state.com_vel
        self._prev_ang_vel[ids] = state.ang_vel_world
        self._prev_joint_vel[ids] = state.joint_vel
        self._com_acc[ids] = 0.0
        self._ang_acc[ids] = 0.0
        self._air_time[ids] = 0.0
        self._prev_contacts[ids] = True
        self._push_steps_left[ids] = 0
        self._push_force[ids] = 0.0
        self._push_applied[ids] = 0.0
        if rnd.push_interval_s is not None:
            self._next_push[ids] = rng.exponential(rnd.push_interval_s / self.dt, size=len(ids))

    # ------------------------------------------------------------------ state
    def _read(self, ids: np.ndarray | slice = slice(None)) -> SimulationState:
        """World-frame state of environments ``ids`` from the batch's live arrays."""
        qpos, qvel, sens = self._qpos[ids], self._qvel[ids], self._sensors[ids]
        R = quat_wxyz_to_matrix(qpos[:, 3:7])
        return SimulationState(
            base_pos=qpos[:, 0:3],
            base_rot=R,
            lin_vel_world=qvel[:, 0:3],
            ang_vel_body=qvel[:, 3:6],
            ang_vel_world=np.einsum("nij,nj->ni", R, qvel[:, 3:6]),
            joint_pos=qpos[:, 7:],
            joint_vel=qvel[:, 6:],
            com=sens[:, self._sensor["com"]],
            com_vel=sens[:, self._sensor["com_vel"]],
            feet=self._site_xpos[ids][:, self._feet],
            contacts=sens[:, self._foot_contact_adr] > 0,
            base_contact=sens[:, self._base_contact_adr] > 0,
            thigh_contacts=sens[:, self._thigh_contact_adr] > 0,
            knees=self._xpos[ids][:, self._knees],
        )

    # ------------------------------------------------------------------ step
    def step(self, actions: np.ndarray) -> StepOutput:
        """Advance every environment by one policy step (the stages of the module docstring)."""
        cfg = self.config
        action = self._actuate(actions)
        diverged = self._simulate()
        self.episode_step += 1
        state = self._measure(diverged)
        acc = self._estimate_accelerations(state)
        stability, margin = self._stability(state, acc)
        touchdown, air_at_touchdown = self._track_air_time(state.contacts)
        values = {
            **self._policy_values(state, slice(None)),
            "margin": margin,
            "torques": self._forces.copy(),
            "action": action,
            "last_action": self.last_action,
            "joint_acc": acc.joints,
            "touchdown": touchdown,
            "air_time_at_touchdown": air_at_touchdown,
            "thigh_contacts": state.thigh_contacts,
        }
        weights = cfg.reward_weights
        if "knee_clearance" in weights:  # a terrain lookup per knee: only when the term is on
            values["knee_heights"] = state.knees[..., 2] - self.terrain.height(state.knees[..., :2])
            values["knee_clearance_height"] = np.full(self.num_envs, cfg.knee_clearance_height)
        reward, terms = compute_rewards(weights, values, cfg.logistic_gain)
        self.last_action = action.copy()
        terminated = self._terminations(state, diverged)
        truncated = (self.episode_step >= self.max_episode_steps) & ~terminated & self.truncate
        info = self._info(state, acc, values, terms, margin, stability, terminated, diverged)
        observation = self._observe(values)
        final_observation = observation.copy()
        done = terminated | truncated
        if self.autoreset and done.any():
            ids = np.nonzero(done)[0]
            self.reset(ids)
            observation[ids] = self._observe_ids(ids)
        privileged = self.privileged_observation() if cfg.privileged_observations else None
        check_finite_outputs(cfg, reward, observation, final_observation)
        return StepOutput(observation, reward, terminated, truncated, info, final_observation, privileged)

    def _actuate(self, actions: np.ndarray) -> np.ndarray:
        """Clip the actions, write the servo targets and this step's pushes; returns the clipped actions."""
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (self.num_envs, 12):
            raise ValueError(f"actions must have shape (num_envs, 12) = ({self.num_envs}, 12), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError("actions contain NaN or inf")
        a = np.clip(a, -1.0, 1.0)
        self._ctrl[:] = self._key_ctrl + self.config.action_scale * a
        self._apply_pushes()
        return a

    def _invalid_state(self) -> np.ndarray:
        """(N,) True where qpos or qvel is non-finite or a velocity exceeds :data:`DIVERGED_SPEED`."""
        qpos, qvel = self._qpos, self._qvel
        return (
            ~np.all(np.isfinite(qvel), axis=1)
            | np.any(np.abs(qvel) > DIVERGED_SPEED, axis=1)
            | ~np.all(np.isfinite(qpos), axis=1)
        )

    def _simulate(self) -> np.ndarray:
        """Step the physics ``decimation`` times; returns the (N,) divergence flags.

        A state that was already invalid before the step (e.g. written by a user) is flagged too. MuJoCo resets
        a simulation whose accelerations blow up (a "bad QACC" warning) instead of raising; its clock then fails
        to advance by the step, which is how such a divergence is caught here.
        """
        diverged = self._invalid_state()
        time_before = self._time.copy()
        try:
            self.batch.step(nstep=self.config.decimation, stage=mujoco.mjtStage.mjSTAGE_ACC)
        except mj_batch.SimulationError as exc:  # a simulation failed: end its episode, keep the others
            diverged[np.asarray(exc.ids, dtype=np.int64)] = True
        expected = time_before + self.config.decimation * self.model.opt.timestep
        diverged |= np.abs(self._time - expected) > 0.5 * self.model.opt.timestep
        return diverged | self._invalid_state()

    def _measure(self, diverged: np.ndarray) -> SimulationState:
        """The state after the step; a diverged environment's numbers are made finite for the bookkeeping."""
        state = self._read()
        return state.finite() if diverged.any() else state

    def _estimate_accelerations(self, state: SimulationState) -> Accelerations:
        """Finite differences of the velocities over the policy step, the CoM and base ones EMA-filtered."""
        alpha = self.config.acceleration_filter
        com_acc = (state.com_vel - self._prev_com_vel) / self.dt
        ang_acc = (state.ang_vel_world - self._prev_ang_vel) / self.dt
        self._com_acc = alpha * self._com_acc + (1 - alpha) * com_acc
        self._ang_acc = alpha * self._ang_acc + (1 - alpha) * ang_acc
        joint_acc = (state.joint_vel - self._prev_joint_vel) / self.dt
        self._prev_com_vel, self._prev_ang_vel = state.com_vel.copy(), state.ang_vel_world.copy()
        self._prev_joint_vel = state.joint_vel.copy()
        return Accelerations(self._com_acc, self._ang_acc, joint_acc, com_acc, ang_acc)

    def _stability(self, state: SimulationState, acc: Accelerations) -> tuple[StabilityState, np.ndarray]:
        """lambda's fields and the clipped margin (N,), one evaluation for the batch (lambda: :attr:`last_lambda`)."""
        ext_force = self._push_applied
        stability = stability_state_from_simulation(
            state.base_rot,
            state.com,
            state.com_vel,
            acc.com,
            acc.base_angular,
            ext_force,
            np.zeros_like(ext_force),
            state.feet,
            self.mu,
            state.contacts,
            self.terrain.normal(state.feet[..., :2]),
        )
        lam = stability.to_lambda()
        margin = np.clip(self._margin_fn(lam), *MARGIN_CLIP)
        self._last_margin, self._last_lambda = margin, lam
        return stability, margin

    def _track_air_time(self, contacts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Touchdowns (N, 4) and each touching-down foot's time in the air [s] (0 elsewhere).

        Kept before the rewards so that a zero reward weight changes nothing.
        """
        touchdown = contacts & ~self._prev_contacts
        self._air_time += self.dt
        air_at_touchdown = np.where(touchdown, self._air_time, 0.0)
        self._air_time = np.where(contacts, 0.0, self._air_time)
        self._prev_contacts = contacts.copy()
        return touchdown, air_at_touchdown

    def _terminations(self, state: SimulationState, diverged: np.ndarray) -> np.ndarray:
        """(N,) base or thigh contact with the terrain, base too low or too tilted, or a diverged simulation."""
        bounds = self.config.termination
        ground = self.terrain.height(state.base_pos[:, :2])
        tilt_cos = state.base_rot[:, 2, 2]
        return (
            state.base_contact
            | state.thigh_contacts.any(axis=1)
            | (state.base_pos[:, 2] - ground < bounds.min_base_height)
            | (tilt_cos < np.cos(bounds.max_tilt_rad))
            | diverged
        )

    def _info(
        self,
        state: SimulationState,
        acc: Accelerations,
        values: dict[str, np.ndarray],
        terms: dict[str, np.ndarray],
        margin: np.ndarray,
        stability: StabilityState,
        terminated: np.ndarray,
        diverged: np.ndarray,
    ) -> dict[str, np.ndarray]:
        """The per-environment step info (every weighted reward term, margin, accelerations, gait, flags)."""
        R = state.base_rot
        return {
            **{f"reward_{k}": v for k, v in terms.items()},
            "margin": margin,
            # Unfiltered: the robot's accelerations, the comparison's metrics (lambda has the filtered ones).
            "base_lin_acc": np.einsum("nji,nj->ni", R, acc.com_measured),  # CoM acceleration, base frame
            "base_ang_acc": np.einsum("nji,nj->ni", R, acc.base_angular_measured),  # base frame
            "base_lin_vel": values["base_lin_vel"],
            "velocity_error": np.abs(self.command[:, 0] - values["base_lin_vel"][:, 0]),
            "contacts": state.contacts.astype(np.float64),
            "stance_width": stance_width(stability.feet),  # feet in H, as they entered lambda
            "lambda": self._last_lambda,  # (N, 47), the margin's input (names: stability.lambda_names())
            "fell": (terminated & ~diverged).astype(np.float64),
            "diverged": diverged.astype(np.float64),
        }

    def push(self, ids: np.ndarray, force: np.ndarray, duration_s: float, frame: str = "world") -> None:
        """Push the base of environments ``ids``, from the next step on: a constant force ``force`` (len(ids), 3)
        [N] at the base origin for ``duration_s`` rounded to whole policy steps (at least one), so the impulse is
        ``force * steps * dt`` [N s]. ``frame``: "world", or "heading" (the base frame turned by its yaw only, as
        it is when the push starts: x forwards, y to the left, z up). The push enters lambda as f_ext like the
        random pushes of :class:`RandomizationConfig`, and replaces a push still running in those environments.

        Raises:
            ValueError: ``force`` is not (len(ids), 3) and finite, ``ids`` out of range, duration <= 0 or an
                unknown frame.
        """
        ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
        force = np.asarray(force, dtype=np.float64)
        if ids.size and (ids.min() < 0 or ids.max() >= self.num_envs):
            raise ValueError(f"push ids must lie in [0, {self.num_envs}), got {ids.min()}..{ids.max()}")
        if force.shape != (len(ids), 3) or not np.all(np.isfinite(force)):
            raise ValueError(f"push force must be finite with shape (len(ids), 3) = ({len(ids)}, 3), got {force.shape}")
        if not duration_s > 0:
            raise ValueError(f"push duration_s must be > 0 [s], got {duration_s}")
        if frame not in ("world", "heading"):
            raise ValueError(f"push frame must be 'world' or 'heading', got {frame!r}")
        if frame == "heading":
            force = np.einsum("nij,nj->ni", heading_rotation(self._read(ids).base_rot), force)
        self._push_force[ids] = force
        self._push_steps_left[ids] = self.push_steps(duration_s)

    def push_steps(self, duration_s: float) -> int:
        """Policy steps a push of ``duration_s`` lasts (see :meth:`push`)."""
        return max(1, round(duration_s / self.dt))

    def _apply_pushes(self) -> None:
        """Write the running pushes (random ones of :class:`RandomizationConfig`, and :meth:`push`) to the base."""
        rnd = self.config.randomization
        self._xfrc[:, self._base, :] = 0.0
        if rnd.push_interval_s is not None:
            self._start_random_pushes(rnd)
        active = self._push_steps_left > 0
        # The force of this step, kept for lambda: the counter below already reads 0 during a push's last step.
        self._push_applied = np.where(active[:, None], self._push_force, 0.0)
        self._xfrc[active, self._base, :3] = self._push_force[active]
        self._push_steps_left = np.maximum(self._push_steps_left - 1, 0)

    def _start_random_pushes(self, rnd: RandomizationConfig) -> None:
        self._next_push -= 1
        start = self._next_push <= 0
        if start.any():
            angle = self.rng.uniform(0, 2 * np.pi, size=int(start.sum()))
            self._push_force[start] = rnd.push_force * np.column_stack(
                [np.cos(angle), np.sin(angle), np.zeros_like(angle)]
            )
            self._push_steps_left[start] = self.push_steps(rnd.push_duration_s)
            self._next_push[start] = self.rng.exponential(rnd.push_interval_s / self.dt, size=int(start.sum()))

    # ------------------------------------------------------------------ observations
    def _observe(self, values: dict[str, np.ndarray]) -> np.ndarray:
        noise = self.config.randomization.observation_noise
        return assemble({**values, "last_action": self.last_action}, POLICY_OBSERVATIONS, noise, self.rng)

    def _observe_ids(self, ids: np.ndarray) -> np.ndarray:
        values = {**self._policy_values(self._read(ids), ids), "last_action": self.last_action[ids]}
        noise = self.config.randomization.observation_noise
        return assemble(values, POLICY_OBSERVATIONS, noise, self.rng)

    def _policy_values(self, state: SimulationState, ids: np.ndarray | slice) -> dict[str, np.ndarray]:
        """The robot-state terms of the observation (and the rewards), from a state read of ``ids``."""
        R = state.base_rot
        return {
            "base_lin_vel": np.einsum("nji,nj->ni", R, state.lin_vel_world),  # base frame
            "base_ang_vel": state.ang_vel_body,
            "projected_gravity": -R[:, 2, :],
            "command": self.command[ids],
            "joint_pos": state.joint_pos - self._standing_joint_pos,
            "joint_vel": state.joint_vel,
        }

    def observe_all(self) -> np.ndarray:
        """Policy observations of every environment (after :meth:`reset`)."""
        observations = self._observe_ids(np.arange(self.num_envs))
        check_finite_outputs(self.config, 0.0, observations)
        return observations

    def privileged_observation(self) -> np.ndarray:
        """Critic group: terrain heights around the feet, friction and the current margin."""
        feet = self._site_xpos[:, self._feet]
        offsets = np.array(FOOT_HEIGHT_OFFSETS)
        points = feet[:, :, None, :2] + offsets[None, None]
        heights = feet[:, :, None, 2] - self.terrain.height(points)
        values = {
            "foot_terrain_heights": heights.reshape(self.num_envs, -1),
            "friction": self.mu[:, None],
            "margin": self._last_margin[:, None],
        }
        return assemble(values, PRIVILEGED_OBSERVATIONS, 0.0, self.rng)

    @property
    def last_lambda(self) -> np.ndarray:
        """lambda (N, 47) of the last step (for analysis and tests)."""
        return self._last_lambda

    def render_data(self, env: int = 0) -> mujoco.MjData:
        """An MjData with environment ``env``'s current state (for rendering)."""
        data = mujoco.MjData(self.model)
        data.qpos[:] = self._qpos[env]
        data.qvel[:] = self._qvel[env]
        mujoco.mj_forward(self.model, data)
        return data
