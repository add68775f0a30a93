"""The batched ANYmal simulation behind every environment adapter (single, vector, SB3, rsl-rl).

One :class:`AnymalCore` steps ``num_envs`` MuJoCo simulations with ``mujoco.batch.Batch`` on a native
thread pool, evaluates the stability margin once per batch per step, and autoresets finished
environments in the same step (their last observation is returned separately).

Per policy step (``decimation`` physics steps at the MJCF timestep):

* action a in [-1, 1]^12 (clipped; NaN raises) -> position-servo targets ctrl = ctrl_standing + s a,
  with ctrl_standing the keyframe's equilibrium targets, so a = 0 holds the standing pose;
* lambda (seed 000 eq. 4) from the simulator (:func:`lambda_from_simulation`):
  - e_g: third row of the base orientation; CoM and its velocity from the MJCF's subtree sensors;
  - CoM acceleration and base angular acceleration by finite differences of the CoM velocity and
    of the base angular velocity (world frame) over the policy step (20 ms: the mean acceleration
    over the step, exact on average), optionally smoothed by an exponential filter
    (``EnvConfig.acceleration_filter``, off by default);
  - a push applied to the base (xfrc_applied) as f_ext / tau_ext;
  - feet (foot-sphere centres) relative to the CoM and terrain normals under the feet, rotated into
    the horizontal frame (yaw of the base heading); friction of the terrain; contact flags from the
    MJCF's foot-world contact sensors;
* margin m(lambda): learned (batch MLP), analytic (per env, slow), the FWP feasibility factor s of
  seed 004 (per env, slower, dimensionless) or zero, clipped to ``MARGIN_CLIP`` (states with no
  equilibrium get the lower clip);
* reward terms (:mod:`margin_rl.envs.rewards`), terminations (base or thigh contact, height or tilt
  bounds, a diverged simulation) and truncation at the episode length.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from mujoco import batch as mj_batch

from margin_rl.envs.config import EnvConfig
from margin_rl.envs.observations import (
    FOOT_HEIGHT_OFFSETS,
    POLICY_OBSERVATIONS,
    PRIVILEGED_OBSERVATIONS,
    assemble,
)
from margin_rl.envs.rewards import compute_rewards
from margin_rl.envs.terrain import Terrain, flat_terrain, rough_terrain
from margin_rl.robot import Robot, load_robot, quat_wxyz_to_matrix
from margin_rl.stability.lambda_state import LAMBDA_DIM, StabilityState, from_lambda

MARGIN_CLIP: tuple[float, float] = (-0.5, 0.5)
"""Range [m] the margin term is clipped to (the learned model extrapolates outside its data)."""


def _or_nan(evaluate: Callable[[], float]) -> float:
    """A per-environment margin, NaN where its state is invalid (e.g. a diverged simulation's lambda)."""
    try:
        return float(evaluate())
    except ValueError:
        return float("nan")


def heading_rotation(base_rotation: np.ndarray) -> np.ndarray:
    """Rotation (..., 3, 3) of the horizontal frame H in the world: the yaw of the base x axis."""
    yaw = np.arctan2(base_rotation[..., 1, 0], base_rotation[..., 0, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    zero, one = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1), np.stack([zero, zero, one], -1)], -2)


def lambda_from_simulation(
    base_rotation: np.ndarray,
    com: np.ndarray,
    com_vel: np.ndarray,
    com_acc: np.ndarray,
    base_ang_acc: np.ndarray,
    ext_force: np.ndarray,
    ext_torque: np.ndarray,
    feet: np.ndarray,
    mu: np.ndarray,
    contacts: np.ndarray,
    normals: np.ndarray,
) -> np.ndarray:
    """lambda (N, 47) from world-frame simulator quantities (all (N, ...), world frame, SI units).

    e_g is the third row of the base rotation; every other vector is rotated into the horizontal frame
    H (yaw of the base heading) and the feet are taken relative to the CoM.
    """
    R_wh = heading_rotation(base_rotation)

    def to_h(v: np.ndarray) -> np.ndarray:  # world -> H for (N, 3) or (N, k, 3)
        return np.einsum("nji,n...j->n...i", R_wh, v)

    state = StabilityState(
        gravity_axis=base_rotation[:, 2, :],
        com_vel=to_h(com_vel),
        com_acc=to_h(com_acc),
        base_ang_acc=to_h(base_ang_acc),
        ext_force=to_h(ext_force),
        ext_torque=to_h(ext_torque),
        feet=to_h(feet - com[:, None, :]),
        mu=np.asarray(mu, dtype=float),
        contacts=np.asarray(contacts, dtype=float),
        normals=to_h(normals),
    )
    return state.to_lambda()


def build_model(robot: Robot, terrain: Terrain, config: EnvConfig) -> mujoco.MjModel:
    """The robot on its terrain: the flat scene file, or the robot plus a generated heightfield."""
    if terrain.is_flat:
        return mujoco.MjModel.from_xml_path(str(robot.scene_path))
    h = terrain.heights
    n = h.shape[0]
    half = (n - 1) * terrain.resolution / 2
    z_top = config.terrain_config.max_height
    xml = f"""
<mujoco model="{robot.name}_rough">
  <include file="{Path(robot.xml_path).as_posix()}"/>
  <visual><global offwidth="1280" offheight="720"/></visual>
  <asset>
    <hfield name="terrain" nrow="{n}" ncol="{n}" size="{half} {half} {z_top} 0.1"/>
    <texture type="2d" name="grid" builtin="checker" rgb1="0.35 0.4 0.45" rgb2="0.25 0.3 0.35" width="300"
             height="300"/>
    <material name="grid" texture="grid" texrepeat="24 24"/>
  </asset>
  <worldbody>
    <light pos="0 0 5" dir="0 0 -1" directional="true"/>
    <geom name="floor" type="hfield" hfield="terrain" material="grid" contype="1" conaffinity="1" condim="3"
          friction="1.0 0.005 0.0001" priority="1"/>
  </worldbody>
</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    # MuJoCo hfield data: row-major, rows along y, columns along x, values in [0, 1] of z_top.
    model.hfield_data[:] = (h / z_top).ravel()
    return model


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
        self.model = build_model(self.robot, self.terrain, config)
        self.dt = float(self.model.opt.timestep * config.decimation)
        self.max_episode_steps = round(config.episode_length_s / self.dt)
        self.batch = mj_batch.Batch(self.model, nsim=num_envs, nthread=0)
        self._qpos, self._qvel = self.batch.bind("qpos"), self.batch.bind("qvel")
        self._ctrl, self._xfrc = self.batch.bind("ctrl"), self.batch.bind("xfrc_applied")
        self._sensors, self._site_xpos = self.batch.bind("sensordata"), self.batch.bind("site_xpos")
        self._forces = self.batch.bind("actuator_force")
        self._time = self.batch.bind("time")
        m = self.model
        self._base = m.body("base").id
        self._feet = np.array([m.site(f).id for f in self.robot.foot_names])
        self._sensor = {
            m.sensor(i).name: slice(m.sensor_adr[i], m.sensor_adr[i] + m.sensor_dim[i]) for i in range(m.nsensor)
        }
        key = m.key("standing").id
        self._key_qpos, self._key_ctrl = m.key_qpos[key].copy(), m.key_ctrl[key].copy()
        self._standing_joint_pos = self.robot.standing_joint_pos
        self._floor = m.geom("floor").id
        self._friction = self.batch.expand("geom_friction")
        base_friction = float(m.geom_friction[self._floor, 0])
        self.mu = np.full(num_envs, base_friction)
        self._margin_fn = self._make_margin_fn()
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
        self._next_push = np.full(n, np.inf)
        self.observation_size = sum(t.size for t in POLICY_OBSERVATIONS)
        self.privileged_size = sum(t.size for t in PRIVILEGED_OBSERVATIONS)
        self._last_margin = np.zeros(n)
        self._last_lambda = np.zeros((n, LAMBDA_DIM))

    # ------------------------------------------------------------------ margin
    def _make_margin_fn(self):
        kind = self.config.margin
        if kind == "none":
            return lambda lam: np.zeros(len(lam))
        if kind == "learned":
            from threadpoolctl import ThreadpoolController

            from margin_rl.stability.learned import LearnedMargin

            model = LearnedMargin.load(self.config.margin_weights or self.config.robot)
            # OpenBLAS threads even these small GEMMs; on a few cores they collide with MuJoCo's thread
            # pool (measured 4x slower env steps), so the margin runs on one BLAS thread (~16 us to switch).
            blas = ThreadpoolController()

            def learned(lam: np.ndarray) -> np.ndarray:
                with blas.limit(limits=1, user_api="blas"):
                    return np.asarray(model(lam))

            return learned
        if kind == "fwp":
            from margin_rl.stability.fwp import fwp_feasibility

            def fwp(lam: np.ndarray) -> np.ndarray:
                # s <= 1 is dimensionless (a relative depth in the wrench polytope), not a distance.
                values = np.array([_or_nan(lambda x=x: fwp_feasibility(self.robot, x).s) for x in lam])
                return np.where(np.isfinite(values), values, MARGIN_CLIP[0])

            return fwp
        from margin_rl.stability.analytic import analytic_margin

        def analytic(lam: np.ndarray) -> np.ndarray:
            values = np.array([_or_nan(lambda x=x: analytic_margin(self.robot, x).margin) for x in lam])
            return np.where(np.isfinite(values), values, MARGIN_CLIP[0])

        return analytic

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
        self._prev_com_vel[ids] = state["com_vel"]
        self._prev_ang_vel[ids] = state["ang_vel_world"]
        self._prev_joint_vel[ids] = state["joint_vel"]
        self._com_acc[ids] = 0.0
        self._ang_acc[ids] = 0.0
        self._air_time[ids] = 0.0
        self._prev_contacts[ids] = True
        self._push_steps_left[ids] = 0
        self._push_force[ids] = 0.0
        if rnd.push_interval_s is not None:
            self._next_push[ids] = rng.exponential(rnd.push_interval_s / self.dt, size=len(ids))

    # ------------------------------------------------------------------ state
    def _read(self, ids: np.ndarray | slice = slice(None)) -> dict[str, np.ndarray]:
        """World-frame state of environments ``ids`` from the batch's live arrays."""
        qpos, qvel, sens = self._qpos[ids], self._qvel[ids], self._sensors[ids]
        quat = qpos[:, 3:7]
        R = quat_wxyz_to_matrix(quat)
        return {
            "base_pos": qpos[:, 0:3],
            "base_rot": R,
            "lin_vel_world": qvel[:, 0:3],
            "ang_vel_body": qvel[:, 3:6],
            "ang_vel_world": np.einsum("nij,nj->ni", R, qvel[:, 3:6]),
            "joint_pos": qpos[:, 7:],
            "joint_vel": qvel[:, 6:],
            "com": sens[:, self._sensor["com"]],
            "com_vel": sens[:, self._sensor["com_vel"]],
            "feet": self._site_xpos[ids][:, self._feet],
            "contacts": np.stack(
                [sens[:, self._sensor[f"{leg}_foot_contact"]][:, 0] > 0 for leg in self.robot.leg_names], axis=1
            ),
            "base_contact": sens[:, self._sensor["base_contact"]][:, 0] > 0,
            "thigh_contacts": np.stack(
                [sens[:, self._sensor[f"{leg}_THIGH_contact"]][:, 0] > 0 for leg in self.robot.leg_names], axis=1
            ),
        }

    # ------------------------------------------------------------------ step
    def step(self, actions: np.ndarray) -> StepOutput:
        """Advance every environment by one policy step (see the module docstring)."""
        a = np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 12)
        if not np.all(np.isfinite(a)):
            raise ValueError("actions contain NaN or inf")
        a = np.clip(a, -1.0, 1.0)
        cfg = self.config
        self._ctrl[:] = self._key_ctrl + cfg.action_scale * a
        self._apply_pushes()
        # A state that is already non-finite or exploding (e.g. written by a user) is not stepped further.
        diverged = ~np.all(np.isfinite(self._qvel), axis=1) | np.any(np.abs(self._qvel) > 1e3, axis=1)
        diverged |= ~np.all(np.isfinite(self._qpos), axis=1)
        time_before = self._time.copy()
        try:
            self.batch.step(nstep=cfg.decimation, stage=mujoco.mjtStage.mjSTAGE_ACC)
        except mj_batch.SimulationError as exc:  # a simulation failed: end its episode, keep the others
            diverged[np.asarray(exc.ids, dtype=np.int64)] = True
        # MuJoCo resets a simulation whose accelerations blow up (a "bad QACC" warning) instead of raising;
        # its clock then usually fails to advance by the step, which is how such a divergence is caught here
        # (velocities above 1e3 are caught before or after the step).
        expected = time_before + cfg.decimation * self.model.opt.timestep
        diverged |= np.abs(self._time - expected) > 0.5 * self.model.opt.timestep
        diverged |= ~np.all(np.isfinite(self._qpos), axis=1) | ~np.all(np.isfinite(self._qvel), axis=1)
        diverged |= np.any(np.abs(self._qvel) > 1e3, axis=1)
        self.episode_step += 1
        s = self._read()
        if diverged.any():  # keep the numbers finite for this step's bookkeeping
            for key, value in s.items():
                if value.dtype.kind == "f":
                    s[key] = np.where(np.isfinite(value), value, 0.0)

        # Accelerations: finite differences over the policy step, optionally filtered.
        alpha = cfg.acceleration_filter
        com_acc = (s["com_vel"] - self._prev_com_vel) / self.dt
        ang_acc = (s["ang_vel_world"] - self._prev_ang_vel) / self.dt
        self._com_acc = alpha * self._com_acc + (1 - alpha) * com_acc
        self._ang_acc = alpha * self._ang_acc + (1 - alpha) * ang_acc
        joint_acc = (s["joint_vel"] - self._prev_joint_vel) / self.dt
        self._prev_com_vel, self._prev_ang_vel = s["com_vel"].copy(), s["ang_vel_world"].copy()
        self._prev_joint_vel = s["joint_vel"].copy()

        # Stability input and margin (one evaluation for the whole batch).
        normals = self.terrain.normal(s["feet"][..., :2])
        ext_force = self._push_force * (self._push_steps_left > 0)[:, None]
        lam = lambda_from_simulation(
            s["base_rot"],
            s["com"],
            s["com_vel"],
            self._com_acc,
            self._ang_acc,
            ext_force,
            np.zeros_like(ext_force),
            s["feet"],
            self.mu,
            s["contacts"],
            normals,
        )
        margin = np.clip(self._margin_fn(lam), *MARGIN_CLIP)
        self._last_margin, self._last_lambda = margin, lam

        # Feet air time (bookkeeping before the rewards, so a zero weight changes nothing).
        touchdown = s["contacts"] & ~self._prev_contacts
        self._air_time += self.dt
        air_at_touchdown = np.where(touchdown, self._air_time, 0.0)
        self._air_time = np.where(s["contacts"], 0.0, self._air_time)
        self._prev_contacts = s["contacts"].copy()

        R = s["base_rot"]
        values = {
            **self._policy_values(s, slice(None)),
            "margin": margin,
            "torques": self._forces.copy(),
            "action": a,
            "last_action": self.last_action,
            "joint_acc": joint_acc,
            "touchdown": touchdown,
            "air_time_at_touchdown": air_at_touchdown,
            "thigh_contacts": s["thigh_contacts"],
        }
        reward, terms = compute_rewards(cfg.reward_weights, values, cfg.logistic_gain)
        self.last_action = a.copy()

        ground = self.terrain.height(s["base_pos"][:, :2])
        tilt_cos = R[:, 2, 2]
        terminated = (
            s["base_contact"]
            | s["thigh_contacts"].any(axis=1)
            | (s["base_pos"][:, 2] - ground < cfg.termination.min_base_height)
            | (tilt_cos < np.cos(cfg.termination.max_tilt_rad))
            | diverged
        )
        truncated = (self.episode_step >= self.max_episode_steps) & ~terminated & self.truncate
        feet_h = from_lambda(lam).feet  # feet relative to the CoM in the heading frame, as built above
        info = {
            **{f"reward_{k}": v for k, v in terms.items()},
            "margin": margin,
            "base_lin_acc": np.einsum("nji,nj->ni", R, self._com_acc),  # CoM acceleration, base frame
            "base_ang_acc": np.einsum("nji,nj->ni", R, self._ang_acc),  # base frame
            "base_lin_vel": values["base_lin_vel"],
            "velocity_error": np.abs(self.command[:, 0] - values["base_lin_vel"][:, 0]),
            "contacts": s["contacts"].astype(np.float64),
            "stance_width": 0.5
            * (np.abs(feet_h[:, 0, 1] - feet_h[:, 1, 1]) + np.abs(feet_h[:, 2, 1] - feet_h[:, 3, 1])),
            "fell": (terminated & ~diverged).astype(np.float64),
            "diverged": diverged.astype(np.float64),
        }
        observation = self._observe(values)
        final_observation = observation.copy()
        done = terminated | truncated
        if self.autoreset and done.any():
            ids = np.nonzero(done)[0]
            self.reset(ids)
            observation[ids] = self._observe_ids(ids)
        privileged = self.privileged_observation() if cfg.privileged_observations else None
        return StepOutput(observation, reward, terminated, truncated, info, final_observation, privileged)

    def _apply_pushes(self) -> None:
        rnd = self.config.randomization
        self._xfrc[:, self._base, :] = 0.0
        if rnd.push_interval_s is None:
            return
        self._next_push -= 1
        start = self._next_push <= 0
        if start.any():
            angle = self.rng.uniform(0, 2 * np.pi, size=int(start.sum()))
            self._push_force[start] = rnd.push_force * np.column_stack(
                [np.cos(angle), np.sin(angle), np.zeros_like(angle)]
            )
            self._push_steps_left[start] = max(1, round(rnd.push_duration_s / self.dt))
            self._next_push[start] = self.rng.exponential(rnd.push_interval_s / self.dt, size=int(start.sum()))
        active = self._push_steps_left > 0
        self._xfrc[active, self._base, :3] = self._push_force[active]
        self._push_steps_left = np.maximum(self._push_steps_left - 1, 0)

    # ------------------------------------------------------------------ observations
    def _observe(self, values: dict[str, np.ndarray]) -> np.ndarray:
        noise = self.config.randomization.observation_noise
        return assemble({**values, "last_action": self.last_action}, POLICY_OBSERVATIONS, noise, self.rng)

    def _observe_ids(self, ids: np.ndarray) -> np.ndarray:
        values = {**self._policy_values(self._read(ids), ids), "last_action": self.last_action[ids]}
        noise = self.config.randomization.observation_noise
        return assemble(values, POLICY_OBSERVATIONS, noise, self.rng)

    def _policy_values(self, s: dict[str, np.ndarray], ids: np.ndarray | slice) -> dict[str, np.ndarray]:
        """The robot-state terms of the observation (and the rewards), from a state read of ``ids``."""
        R = s["base_rot"]
        return {
            "base_lin_vel": np.einsum("nji,nj->ni", R, s["lin_vel_world"]),  # base frame
            "base_ang_vel": s["ang_vel_body"],
            "projected_gravity": -R[:, 2, :],
            "command": self.command[ids],
            "joint_pos": s["joint_pos"] - self._standing_joint_pos,
            "joint_vel": s["joint_vel"],
        }

    def observe_all(self) -> np.ndarray:
        """Policy observations of every environment (after :meth:`reset`)."""
        return self._observe_ids(np.arange(self.num_envs))

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
