"""The batched ANYmal simulation behind every environment adapter (single, vector, SB3, rsl-rl).

One :class:`AnymalCore` steps ``num_envs`` MuJoCo simulations (through its physics seam,
:class:`~margin_rl.envs.physics.PhysicsBackend`: ``mujoco.batch.Batch`` on a native thread pool by default, or
MuJoCo Warp with ``physics="warp"``, :mod:`margin_rl.envs.physics_warp`), evaluates
the stability margin once per batch per step, and autoresets finished environments in the same step (their last
observation is returned separately). Robot names (bodies, sensors, keyframe, the qpos/qvel layout) come from
:mod:`margin_rl.robot.mjcf_names`.

:meth:`AnymalCore.step` runs these stages once per policy step:

1. ``_actuate``: action a in [-1, 1]^12 (clipped; NaN raises) -> position-servo targets ctrl = ctrl_standing + s a
   (the keyframe's equilibrium targets, so a = 0 holds the standing pose); pushes (:mod:`.pushes`) on the base;
2. ``_simulate``: ``decimation`` physics steps, the backend's buffer check (Warp's fixed contact buffers) and the
   divergence check (non-finite or runaway state before or after, a simulation MuJoCo reset);
3. ``_measure``: the world-frame state (:mod:`.state_read`), and the ground under the robot in one terrain lookup
   (:mod:`.ground`);
4. ``_estimate_accelerations``: CoM, base angular and joint accelerations by finite differences over the 20 ms
   step (the mean acceleration over it), the first two smoothed by ``EnvConfig.acceleration_filter``;
5. ``_stability``: lambda (seed 000 eq. 4, :mod:`.stability_input`) and the margin of the configured kind
   (:mod:`.margin_kinds`) clipped to :data:`MARGIN_CLIP`; a push enters lambda as f_ext;
6. ``_track_air_time``: touchdowns and the air time of each foot;
7. rewards (:mod:`.rewards`), terminations (:mod:`.terminations`, each cause in ``info["termination_<cause>"]``),
   truncation at the episode length, the info (:mod:`.step_info`);
8. observations and the same-step autoreset of finished environments (:mod:`.reset_rows`).

**Where it computes.** In the kind of its physics' live arrays (:mod:`margin_rl.arrays`): numpy on the host beside
``mujoco.batch``, torch tensors on the physics' device beside Warp, float64 either way; its random draws come from a
generator of the same kind (numpy's, or :class:`~margin_rl.arrays.TorchRandom` on the device), so the two backends
draw different numbers from one seed. Every method takes numpy or the core's kind and answers in the core's kind.
On a device the step reads nothing from the host (resets by mask, draws of a fixed count, state at fixed addresses:
:mod:`.episode_state`; checks as flags read every :attr:`AnymalCore.check_every` steps: :mod:`.step_checks`), and
on a CUDA device it is replayed as one graph (:mod:`.step_graph`).

A core pickles (and deep-copies): rebuilt from its config and terrain, given back its state (the physics' state and
per-environment model fields, the generator, commands, filters, pushes, episode counters), it steps as the original.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from array_api_compat import device as device_of

from margin_rl.arrays import (
    ALL_ROWS,
    Array,
    finite_mask,
    like,
    namespace,
    random_generator,
    rotate,
    rows_of,
    write_where,
)
from margin_rl.envs.backends import PHYSICS_BACKENDS, PhysicsChoice, make_physics
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.episode_state import EPISODE_COUNTERS, EPISODE_STATE, episode_columns, episode_views
from margin_rl.envs.ground import GroundQueries
from margin_rl.envs.margin_kinds import check_margin_runs_on, make_margin_function
from margin_rl.envs.observations import (
    FOOT_HEIGHT_OFFSETS,
    HEIGHT_SCAN_POINTS,
    PRIVILEGED_OBSERVATIONS,
    assemble,
    policy_observations,
    robot_state_terms,
)
from margin_rl.envs.physics import PhysicsBackend
from margin_rl.envs.pushes import checked_push, push_steps, start_random_pushes
from margin_rl.envs.reset_rows import ResetRows
from margin_rl.envs.reset_state import StandingStart, draw_reset
from margin_rl.envs.rewards import compute_rewards
from margin_rl.envs.scene import build_model
from margin_rl.envs.stability_input import (
    heading_rotation,
    lambda_from_simulation,
    stability_state_from_simulation,
)
from margin_rl.envs.state_read import StateReader
from margin_rl.envs.step_checks import StepChecks
from margin_rl.envs.step_data import (
    Accelerations,
    SimulationState,
    StepOutput,
    check_finite_outputs,
    estimate_accelerations,
    finite_output_hint,
)
from margin_rl.envs.step_graph import step_graph_for
from margin_rl.envs.step_info import step_info
from margin_rl.envs.terminations import any_cause, termination_causes
from margin_rl.envs.terrain import (
    Terrain,
    checked_levels,
    flat_terrain,
    next_levels,
    rough_terrain,
)
from margin_rl.robot import load_robot
from margin_rl.robot import mjcf_names as names
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, StabilityState

__all__ = [
    "ACTION_BOUND",
    "MARGIN_CLIP",
    "AnymalCore",
    "SimulationState",
    "StepOutput",
    "heading_rotation",
    "lambda_from_simulation",
]

ACTION_BOUND = 1.0
"""Half-width of the action box: actions are clipped to [-ACTION_BOUND, ACTION_BOUND]^12, then scaled by
``EnvConfig.action_scale`` into joint-position offsets [rad] from the standing keyframe."""

MARGIN_CLIP: tuple[float, float] = (-0.5, 0.5)
"""Range [m] the margin term is clipped to (the learned model extrapolates outside its data)."""

DIVERGED_SPEED = 1e3
"""A generalised velocity above this (m/s, rad/s) marks a simulation as diverged."""

TORQUE_LIMIT_TOLERANCE = 1e-4
"""A joint whose |torque| is within this share of its actuator's force limit counts as at the limit
(``info["torque_at_limit"]``): 0.008 N m of ANYmal's 80 N m."""


DEVICE_CHECK_STEPS = 24
"""The recipes' rollout length: the cadence the rsl-rl adapter gives a core that computes on a device
(:attr:`AnymalCore.check_every`), so one read of the step's checks per PPO iteration."""


class AnymalCore:
    """Batched ANYmal environments (see the module docstring)."""

    _STATE: tuple[str, ...] = (
        "max_episode_steps", "rng", "mu", "_added_mass", "command", "last_action", "episode_step", "_prev_com_vel",
        "_prev_ang_vel", "_prev_joint_vel", "_com_acc", "_ang_acc", "_air_time", "_prev_contacts",
        "_push_steps_left", "_push_force", "_push_applied", "_next_push", "_last_margin", "_last_lambda",
        "terrain_level", "_spawn_xy",
    )  # fmt: skip
    """What a pickled core carries besides its config, terrain and physics state (everything a step changes)."""

    def __init__(
        self,
        config: EnvConfig,
        num_envs: int,
        seed: int | None = None,
        autoreset: bool = True,
        truncate: bool = True,
        physics: str = PHYSICS_BACKENDS[0],
        physics_device: str | None = None,
        physics_options: dict[str, Any] | None = None,
    ) -> None:
        """``autoreset``: reset finished environments inside :meth:`step` (vector semantics); ``truncate``:
        end episodes at ``episode_length_s`` (off when a TimeLimit wrapper does it); ``physics``,
        ``physics_device``, ``physics_options``: the simulator behind the seam, where it computes and its own
        settings (:func:`~margin_rl.envs.backends.make_physics`); not EnvConfig fields, so that a run made with one
        backend evaluates and resumes with another."""
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        terrain = flat_terrain() if config.terrain == "flat" else rough_terrain(config.terrain_config, seed or 0)
        backend = PhysicsChoice(physics, physics_device, dict(physics_options or {}))
        self._build(config, num_envs, autoreset, truncate, terrain, backend)
        self.rng = random_generator(seed, self.physics.qpos)
        xp, n = self.xp, num_envs
        self._added_mass = xp.zeros(n, dtype=xp.float64, device=self.device)
        if config.randomization.added_base_mass is not None:
            masses = self.physics.per_env_field("body_mass")
            self._added_mass = self.rng.uniform(*config.randomization.added_base_mass, size=num_envs)
            masses[:, self._base] = self._cast(self.physics.body_mass(self._base) + self._added_mass, masses)
            self.physics.set_const()
        # the curriculum row each environment spawns on (0 without)
        self.terrain_level = xp.zeros(n, dtype=xp.int64, device=self.device)
        if self.terrain.levels:
            first = self.rng.integers(0, config.terrain_config.initial_max_level + 1, size=n)
            self.terrain_level = self._index(first)

    def _build(
        self,
        config: EnvConfig,
        num_envs: int,
        autoreset: bool,
        truncate: bool,
        terrain: Terrain,
        backend: PhysicsChoice,
    ) -> None:
        """Everything that follows from the config, the terrain and the backend: robot, model, physics, ids, margin."""
        check_margin_runs_on(config.margin, backend.name)
        self.config = config
        self.backend = backend
        self.num_envs = num_envs
        self.autoreset, self.truncate = autoreset, truncate
        self.robot = load_robot(config.robot)
        self.terrain = terrain
        self.model = build_model(self.robot, self.terrain, config.terrain_config)
        self.physics: PhysicsBackend = make_physics(backend.name, self.model, num_envs, backend.device, backend.options)
        physics = self.physics
        # The core computes where the physics' arrays live: numpy on the host beside mujoco.batch, torch tensors on
        # the device beside Warp (margin_rl.arrays), in float64 either way (a device's tensors here are small: its
        # step is bound by kernel launches, not by memory traffic).
        self.xp = namespace(physics.qpos)
        self.device = device_of(physics.qpos)
        # On a device (Warp, on a GPU or on its CPU device) the step reads nothing from the host: its checks become
        # flags read every check_every steps (envs.step_checks), its resets and random draws are by mask, of a fixed
        # size. On the host (mujoco.batch) every check raises at once and the draws are numpy's, as they always were.
        self.sync_free = self.xp is not np
        self.check_every = 1
        """Steps between two reads of a device step's checks (:meth:`raise_pending_errors`): 1 (at once) unless a
        learner sets its rollout length; ignored on the host, where every check raises at once."""
        self.steps_taken = self._steps_since_check = 0  # steps since the core was built, since the checks' last read
        self._step_graph = step_graph_for(physics)  # the step recorded and replayed: CUDA only
        self._checks = StepChecks(self.xp.zeros(num_envs, device=self.device))
        self.dt = float(physics.timestep * config.decimation)
        self.max_episode_steps = round(config.episode_length_s / self.dt)
        self._base = physics.body_id(names.BASE_BODY)
        self._base_wrench = physics.xfrc_applied[:, self._base]  # (N, 6) the pushes' row of the live array, a view
        self._reader = StateReader(physics, self.robot)
        self._key, key_qpos, key_ctrl = physics.keyframe(names.STANDING_KEYFRAME)
        self._key_qpos, self._key_ctrl = self._array(key_qpos), self._array(key_ctrl)
        self._standing_start = StandingStart.of(self._key_qpos, physics.nv)  # what a reset starts from
        self._standing_joint_pos = self._array(self.robot.standing_joint_pos)
        # |tau| within this share of the MJCF forcerange counts as at the limit (MuJoCo clips to it exactly; Warp's
        # float32 rounds within ~1e-7 of it)
        self._torque_at_limit = self._array((1.0 - TORQUE_LIMIT_TOLERANCE) * self.robot.torque_limits)
        self._floor = physics.geom_id(names.FLOOR_GEOM)
        # a valid state: every qpos finite (at most the largest float), every qvel at most DIVERGED_SPEED, in the
        # physics' dtype, so that one comparison of the joined state checks both (_invalid_state)
        nq, nv, largest = physics.qpos.shape[1], physics.qvel.shape[1], self.xp.finfo(physics.qpos.dtype).max
        self._valid_state_bound = self._cast(self._array([largest] * nq + [DIVERGED_SPEED] * nv), physics.qpos)
        self._floor_friction = physics.per_env_field("geom_friction")[:, self._floor, 0]  # (N,) a view, made once
        self._allocate_state()
        self._margin_fn = make_margin_function(config.margin, self.robot, config.margin_weights, MARGIN_CLIP[0])
        self._policy_terms = policy_observations(config.height_scan)
        self.observation_size = sum(t.size for t in self._policy_terms)
        scan = np.array(HEIGHT_SCAN_POINTS)
        self._scan_offsets = self._array(np.column_stack([scan, np.zeros(len(scan))]))  # (P, 3) in the heading frame
        self._foot_offsets = self._array(np.array(FOOT_HEIGHT_OFFSETS))  # (9, 2): made once, not a copy per step
        self.privileged_size = sum(t.size for t in PRIVILEGED_OBSERVATIONS)

    def _allocate_state(self) -> None:
        """The per-environment state a step changes, at fixed addresses (:mod:`~margin_rl.envs.episode_state`)."""
        xp, n = self.xp, self.num_envs
        self._episode_floats = xp.zeros((n, sum(EPISODE_STATE.values())), dtype=xp.float64, device=self.device)
        self._episode_counters = xp.zeros((n, len(EPISODE_COUNTERS)), dtype=xp.int64, device=self.device)
        for name, view in episode_views(self._episode_floats, self._episode_counters).items():
            setattr(self, name, view)
        self.mu[...] = self.physics.geom_friction(self._floor)
        self._next_push[...] = xp.inf
        self._prev_contacts = xp.ones((n, 4), dtype=xp.bool, device=self.device)
        self._last_margin = xp.zeros(n, dtype=xp.float64, device=self.device)
        self._last_lambda = xp.zeros((n, LAMBDA_DIM), dtype=xp.float64, device=self.device)

    @property
    def _ground(self) -> GroundQueries:
        """The step's terrain lookups (:mod:`.ground`) on the core's terrain as it is now."""
        return GroundQueries(self.terrain, self.robot.foot_radius, self.robot.standing_height, self._scan_offsets)

    # ------------------------------------------------------------------ arrays
    def _array(self, value: Any, dtype: Any = None) -> Any:
        """``value`` (numpy, Python or a tensor) as an array of the core's kind, on its device (numpy: unchanged)."""
        return like(value, self.physics.qpos, dtype)

    def _index(self, values: Any) -> Any:
        """Integer indices (environments, sites, sensors; a list, numpy or a tensor on any device) as the core's int64
        array."""
        return self._array(values, self.xp.int64)

    def _cast(self, value: Any, target: Any) -> Any:
        """``value`` in ``target``'s dtype, to be written into it (a no-op where they agree, e.g. numpy float64)."""
        return self.xp.astype(value, target.dtype, copy=False)

    def _float(self, value: Any) -> Any:
        """A physics array (float32 in Warp) as float64, the core's precision (a no-op for mujoco.batch's)."""
        return self.xp.astype(value, self.xp.float64, copy=False)

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        state = {name: getattr(self, name) for name in self._STATE}
        state["_setup"] = (self.config, self.num_envs, self.autoreset, self.truncate, self.terrain, self.backend)
        state["_physics"] = self.physics.get_state()
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        state = dict(state)
        setup = state.pop("_setup")
        if len(setup) == 5:  # pickled before the physics backends: mujoco.batch, the only one then
            setup = (*setup, PhysicsChoice(PHYSICS_BACKENDS[0], None, {}))
        self._build(*setup)
        self.physics.set_state(state.pop("_physics"))
        num_envs = setup[1]  # pickled before the terrain curriculum: no levels (and no spawn points) kept
        state.setdefault("terrain_level", self.xp.zeros(num_envs, dtype=self.xp.int64, device=self.device))
        fixed = {*EPISODE_STATE, *EPISODE_COUNTERS, "_prev_contacts", "_last_margin", "_last_lambda"}
        for name, value in state.items():
            if name in fixed:  # into the buffers at their fixed addresses
                getattr(self, name)[...] = like(value, getattr(self, name))
            else:
                setattr(self, name, value)

    BUILD_FIELDS: tuple[str, ...] = (
        "robot", "terrain", "terrain_config", "decimation", "episode_length_s", "margin", "margin_weights",
        "height_scan",
    )  # fmt: skip
    """EnvConfig fields a core is built from (model, time step, episode length, margin model): fixed for its life."""

    def reconfigure(self, config: EnvConfig) -> None:
        """Use ``config`` from the next step on: the reward, termination bounds, action scale, filter and
        observation settings at once, the command ranges and randomisation at each environment's next reset.

        Raises:
            ValueError: ``config`` changes a field of :data:`BUILD_FIELDS` or the added base masses (drawn once,
                when the core is built): build a new environment instead.
        """
        fixed = [name for name in self.BUILD_FIELDS if getattr(config, name) != getattr(self.config, name)]
        if config.randomization.added_base_mass != self.config.randomization.added_base_mass:
            fixed.append("randomization.added_base_mass")
        if fixed:
            raise ValueError(
                f"{', '.join(fixed)} cannot change in a running environment (the simulation is built from them); "
                "make a new environment with the new value instead"
            )
        self.config = config

    # ------------------------------------------------------------------ reset
    def reset(self, ids: Array | None = None, seed: int | None = None) -> None:
        """Reset environments ``ids`` (all if None) to a randomised standing state and new commands.

        ``seed`` (optional) first reseeds the generator behind every random draw of the core (resets,
        commands, noise, pushes), so the same seed gives the same rollout.
        """
        if seed is not None:
            self.rng = random_generator(seed, self.physics.qpos)
        ids = self.xp.arange(self.num_envs, device=self.device) if ids is None else self._index(ids)
        if int(ids.shape[0]) == 0:
            return
        self._reset_rows(ResetRows.at(ids))

    def _reset_rows(self, rows: ResetRows) -> SimulationState:
        """Reset the environments of ``rows`` (:class:`ResetRows`: given ids, or a mask over every environment) to a
        randomised standing state and new commands; the random draws are one per row of ``rows``. Returns the state
        of the rows read after the reset (what their first observation is made of)."""
        xp = self.xp
        n = rows.count
        cfg, rnd, rng, physics = self.config, self.config.randomization, self.rng, self.physics
        if self.terrain.levels:
            self._move_between_levels(rows)
        physics.reset(rows.physics_rows, self._key)
        spawn_points = self.terrain.spawn_points_like(self._key_qpos)
        if self.terrain.levels:  # a tile of the environment's level, at random along its row
            columns = spawn_points.shape[0] // self.terrain.levels
            tile = rows.of(self.terrain_level) * columns + self._index(rng.integers(0, columns, size=n))
            spawn = spawn_points[tile]
        else:
            spawn = spawn_points[rng.integers(0, spawn_points.shape[0], size=n)]
        draws = draw_reset(rng, n, cfg)
        qpos, qvel = self._standing_start.state(spawn, draws, cfg)
        # the backend's reset gave the rows the keyframe's controls and no applied force (its contract)
        rows.write(physics.qpos, self._cast(qpos, physics.qpos))
        rows.write(physics.qvel, self._cast(qvel, physics.qvel))
        mu = rows.of(self.mu)
        if draws.friction is not None:
            mu = draws.friction
            rows.write(self._floor_friction, self._cast(mu, self._floor_friction))
        physics.forward(rows.forward_rows)
        state = self._read(rows.select)
        next_push = rows.of(self._next_push)
        if rnd.push_interval_s is not None:
            next_push = rng.exponential(rnd.push_interval_s / self.dt, size=n)
        start = {  # the episode's first values, in EPISODE_STATE's columns (the rest 0)
            "_spawn_xy": qpos[:, :2],
            "command": draws.command,
            "_prev_com_vel": state.com_vel,
            "_prev_ang_vel": state.ang_vel_world,
            "_prev_joint_vel": state.joint_vel,
            "_next_push": next_push[:, None],
            "mu": mu[:, None],
        }
        rows.write(self._episode_floats, xp.concat(episode_columns(start, n, xp, self.device), axis=1))
        rows.write(self._episode_counters, 0)  # episode_step, push steps left
        rows.write(self._prev_contacts, True)
        return state

    def restart_on_levels(self, levels: Any) -> None:
        """Start every environment afresh on the terrain curriculum's row ``levels[i]`` (a resumed training's
        curriculum, saved with its checkpoint: without it a resumed run would start again from the lowest rows).

        ``levels``: (num_envs,) integers in 0 .. ``curriculum_levels`` − 1 (a list, numpy or a tensor on any device).

        Raises:
            ValueError: the terrain has no curriculum, or ``levels`` has another length or a row outside it.
        """
        given = checked_levels(levels, self.terrain.levels, self.num_envs, self.config.terrain)
        self.terrain_level[:] = self._index(given)
        self.episode_step[:] = 0  # no episode to judge: every environment keeps the row it is given
        self.reset()

    def _move_between_levels(self, rows: ResetRows) -> None:
        """The terrain curriculum's step at the end of the episodes of ``rows`` (:func:`~margin_rl.envs.terrain.
        next_levels`), before they are reset; environments that have not stepped since their last reset keep
        their level."""
        xp, levels, level = self.xp, self.terrain.levels, rows.of(self.terrain_level)
        episode_step = rows.of(self.episode_step)
        where = self._float(rows.of(self.physics.qpos)[:, names.BASE_POSITION_QPOS][:, :2])
        walked = xp.linalg.vector_norm(where - rows.of(self._spawn_xy), axis=1)
        commanded = xp.linalg.vector_norm(rows.of(self.command)[:, :2], axis=1) * episode_step * self.dt
        random_level = self._index(self.rng.integers(0, levels, size=rows.count))
        moved = next_levels(level, walked, commanded, self.config.terrain_config.tile, levels - 1, random_level)
        rows.write(self.terrain_level, xp.where(episode_step > 0, moved, level))

    # ------------------------------------------------------------------ state
    def _read(self, ids: Any = ALL_ROWS, finite: bool = False) -> SimulationState:
        """World-frame state of environments ``ids`` from the physics' live arrays (float64; :mod:`.state_read`)."""
        return self._reader.read(ids, finite)

    # ------------------------------------------------------------------ step
    def step(self, actions: Any) -> StepOutput:
        """Advance every environment by one policy step (the stages of the module docstring). ``actions`` (N, 12):
        numpy or a tensor (moved to the core's device); the output is in the core's kind (:meth:`StepOutput.to_numpy`
        for the host). On CUDA the stages replay as one graph (:mod:`.step_graph`), the host's bookkeeping outside."""
        a = self._array(actions, self.xp.float64)
        if tuple(a.shape) != (self.num_envs, 12):
            raise ValueError(f"actions must have shape (num_envs, 12) = ({self.num_envs}, 12), got {tuple(a.shape)}")
        graph, stages = self._step_graph, self._step_stages
        output = stages(a) if graph is None else graph.step(stages, a, self._graph_key(), self.rng)
        self.steps_taken += 1
        self._steps_since_check += 1
        if self.sync_free and self._steps_since_check >= self.check_every:  # the flags, read every check_every steps
            self.raise_pending_errors()
        return output

    def _graph_key(self) -> tuple[Any, ...]:
        """What a recorded step bakes in besides its arrays (:mod:`.step_graph`): a change records it again."""
        moved = getattr(self.physics, "recordings_invalidated", 0)
        return (self.config, self.rng, self.terrain, moved, self.max_episode_steps, self.autoreset, self.truncate)

    def _step_stages(self, a: Any) -> StepOutput:
        """The stages of one step for actions ``a`` ((N, 12) float64, the core's kind): what a graph records."""
        cfg = self.config
        action = self._actuate(a)
        diverged = self._simulate()
        self.episode_step += 1
        state = self._measure(diverged)
        ground = self._ground.heights(state, cfg)
        acc = self._estimate_accelerations(state)
        stability, margin, lam = self._stability(state, acc, self._ground.contact_normals(state, ground))
        touchdown, air_at_touchdown = self._track_air_time(state.contacts)
        edge_touchdown = self._ground.edge_touchdowns(touchdown, ground)
        base_height = state.base_pos[:, 2] - ground["base"]
        values = {
            **self._policy_values(state, ALL_ROWS, ground.get("scan")),
            "margin": margin,
            "torques": self.xp.astype(self.physics.actuator_force, self.xp.float64),  # a copy
            "action": action,
            "last_action": self.last_action,
            "joint_acc": acc.joints,
            "touchdown": touchdown,
            "edge_touchdown": edge_touchdown,
            "air_time_at_touchdown": air_at_touchdown,
            "thigh_contacts": state.thigh_contacts,
            "base_height": base_height,
        }
        weights = cfg.reward_weights
        if "knee_clearance" in weights:  # a terrain lookup per knee: only when the term is on
            values["knee_heights"] = state.knees[..., 2] - ground["knees"]
            values["knee_clearance_height"] = self._full(cfg.reward_params.knee_clearance_height)
        if "base_acceleration" in weights:  # the comparison's metric: unfiltered, its norm frame-free
            values["base_lin_acc"] = acc.com_measured
        if "base_height" in weights:
            values["base_height_target"] = self._full(
                cfg.reward_params.base_height_fraction * self.robot.standing_height
            )
        causes = self._terminations(state, base_height, diverged)
        terminated = any_cause(causes)
        values["fell"] = terminated & ~diverged  # a diverged simulation is the simulator's failure, not the policy's
        reward, terms = compute_rewards(weights, values, cfg.reward_params.logistic_gain)
        self.last_action[...] = action
        truncated = (self.episode_step >= self.max_episode_steps) & ~terminated & self.truncate
        levels = self.terrain_level if self.terrain.levels else None
        context = (self.command, self._torque_at_limit, levels)
        info = step_info(state, acc, values, terms, margin, lam, stability, diverged, causes, *context)
        observation = self._observe(values)
        done, masked_reset, privileged = terminated | truncated, self.autoreset and self.sync_free, None
        # the observation before any reset: a copy where a reset writes rows in place (a masked one makes a new array)
        final_observation = observation if masked_reset else self.xp.asarray(observation, copy=True)
        if masked_reset:  # every row reset where done, observed again where done
            after_reset = self._reset_rows(ResetRows.where(done))
            ground = self._ground.reset_heights(after_reset, cfg, self._foot_offsets)  # the scan's and the critic's
            first = self._observe_state(after_reset, ALL_ROWS, ground.get("scan"))
            observation = self.xp.where(done[:, None], first, observation)
            if "around_feet" in ground:  # the critic's: every row's state now is the read after the reset
                privileged = self._privileged(after_reset.feet, ground["around_feet"])
        elif self.autoreset and bool(self.xp.any(done)):
            ids = self.xp.nonzero(done)[0]
            observation[ids] = self._observe_state(self._reset_rows(ResetRows.at(ids)), ids)
        if cfg.privileged_observations and privileged is None:
            privileged = self.privileged_observation()
        if self.sync_free:  # flags, which step reads every check_every steps
            self._checks.record_step(self._nonfinite_action, reward, (observation, final_observation))
        else:
            check_finite_outputs(cfg, reward, observation, final_observation)
        return StepOutput(observation, reward, terminated, truncated, info, final_observation, privileged)

    def _full(self, value: float) -> Any:
        """(N,) float64 of ``value``."""
        return self.xp.full(self.num_envs, value, dtype=self.xp.float64, device=self.device)

    def _actuate(self, a: Any) -> Any:
        """Clip the actions ((N, 12) float64, the core's kind), write the servo targets and this step's pushes;
        returns the clipped actions."""
        xp = self.xp
        usable = finite_mask(a)
        if self.sync_free:  # raised at the next read; 0 in its place keeps the physics finite until then
            self._nonfinite_action = ~xp.all(usable, axis=1)  # recorded with the outputs' checks
            a = xp.where(usable, a, 0.0)
        elif not bool(xp.all(usable)):
            raise ValueError("actions contain NaN or inf")
        a = xp.clip(a, -ACTION_BOUND, ACTION_BOUND)
        self.physics.ctrl[:] = self._key_ctrl + self.config.action_scale * a  # cast to the physics' dtype as written
        self._apply_pushes()
        return a

    def _invalid_state(self) -> Any:
        """(N,) True where qpos or qvel is non-finite or a velocity exceeds :data:`DIVERGED_SPEED`."""
        xp = self.xp
        state = xp.concat((self.physics.qpos, self.physics.qvel), axis=1)
        # |x| <= a bound is false for NaN and inf as well: one comparison covers finiteness and the speed limit
        return ~xp.all(xp.abs(state) <= self._valid_state_bound, axis=1)

    def _simulate(self) -> Array:
        """Step the physics ``decimation`` times; returns the (N,) divergence flags: the simulations the backend
        reports failed (MuJoCo: an error, or a reset after its accelerations blew up; Warp reports none, its state
        turns non-finite instead), and every state not valid before or after the step (e.g. written by a user)."""
        diverged = self._invalid_state()
        failed = self.physics.step(self.config.decimation)
        if not self.sync_free:  # on a device with the step's other checks (raise_pending_errors)
            self.physics.check_overflow()  # dropped contacts would make every later step of a world wrong
        if failed.shape[0]:  # a simulation failed: end its episode, keep the others
            diverged[failed] = True
        return diverged | self._invalid_state()

    def raise_pending_errors(self) -> None:
        """Read a device step's checks and the physics' buffer flags (the host reads the step defers), and raise
        what they hold: a NaN or inf action (ValueError), a non-finite observation or reward (FloatingPointError),
        a buffer overflow (:class:`~margin_rl.envs.physics_warp.PhysicsOverflowError`), naming the first step and
        the environments. Called by the step every :attr:`check_every` steps; a learner may call it too."""
        self._steps_since_check = 0
        hint = finite_output_hint(self.config)
        self._checks.raise_pending({"observation": hint, "reward": hint})
        self.physics.check_overflow()

    def _measure(self, diverged: Any) -> SimulationState:
        """The state after the step; a diverged environment's numbers are made finite for the bookkeeping (on a
        device always: whether any diverged is a host read)."""
        return self._read(finite=self.sync_free or bool(diverged.any()))

    def _estimate_accelerations(self, state: SimulationState) -> Accelerations:
        """Finite differences of the velocities over the policy step, the CoM and base ones EMA-filtered."""
        velocities = self.xp.concat((state.com_vel, state.ang_vel_world, state.joint_vel), axis=1)
        alpha = self.config.acceleration_filter
        acc, filtered = estimate_accelerations(velocities, self._prev_velocities, self._filtered_acc, alpha, self.dt)
        # the state in place (fixed addresses, what a recorded graph needs); the step's values are its own arrays
        self._filtered_acc[...], self._prev_velocities[...] = filtered, velocities
        return acc

    def _stability(self, state: SimulationState, acc: Accelerations, normals: Any) -> tuple[StabilityState, Any, Any]:
        """lambda's fields, the clipped margin (N,) and lambda (N, 47), one evaluation for the batch (kept as
        :attr:`last_lambda`)."""
        ext_force = self._push_applied
        stability = stability_state_from_simulation(
            state.base_rot,
            state.com,
            state.com_vel,
            acc.com,
            acc.base_angular,
            ext_force,
            self._push_torque,  # always 0
            state.feet,
            self.mu,
            state.contacts,
            normals,
            heading=state.heading_rot,
        )
        lam = stability.to_lambda()
        margin = self.xp.clip(self._margin_fn(lam), *MARGIN_CLIP)
        self._last_margin[...], self._last_lambda[...] = margin, lam
        return stability, margin, lam

    def _track_air_time(self, contacts: Array) -> tuple[Array, Array]:
        """Touchdowns (N, 4) and each touching-down foot's time in the air [s] (0 elsewhere); kept before the
        rewards so that a zero reward weight changes nothing."""
        xp = self.xp
        touchdown = contacts & ~self._prev_contacts
        self._air_time += self.dt
        air_at_touchdown = xp.where(touchdown, self._air_time, 0.0)
        write_where(self._air_time, contacts, 0.0)
        self._prev_contacts[...] = contacts
        return touchdown, air_at_touchdown

    def _terminations(self, state: SimulationState, base_height: Array, diverged: Array) -> dict[str, Array]:
        """(N,) flags of each cause of :mod:`margin_rl.envs.terminations` (OR'ed, they are ``terminated``);
        ``base_height`` [m] above the terrain under the base."""
        inputs = {
            "base_contact": state.base_contact,
            "thigh_contacts": state.thigh_contacts,
            "base_height": base_height,
            "tilt_cos": state.base_rot[:, 2, 2],
            "diverged": diverged,
        }
        return termination_causes(inputs, self.config.termination)

    def push(self, ids: Array, force: Array, duration_s: float, frame: str = "world") -> None:
        """Push the base of environments ``ids``, from the next step on: a constant force ``force`` (len(ids), 3)
        [N] at the base origin for ``duration_s`` rounded to whole policy steps (at least one), so the impulse is
        ``force * steps * dt`` [N s]. ``frame``: "world", or "heading" (the base frame turned by its yaw only, as
        it is when the push starts: x forwards, y to the left, z up). The push enters lambda as f_ext like the
        random pushes of :class:`RandomizationConfig`, and replaces a push still running in those environments.

        Raises:
            ValueError: ``force`` is not (len(ids), 3) and finite, ``ids`` out of range, duration <= 0 or an
                unknown frame.
        """
        ids, force = checked_push(ids, force, duration_s, frame, self.num_envs)
        ids, force = self._index(ids), self._array(force)
        if frame == "heading":
            force = rotate(self._read(ids).heading_rot, force)
        self._push_force[ids] = force
        self._push_steps_left[ids] = self.push_steps(duration_s)

    def push_steps(self, duration_s: float) -> int:
        """Policy steps a push of ``duration_s`` lasts (see :meth:`push`)."""
        return push_steps(duration_s, self.dt)

    def _apply_pushes(self) -> None:
        """Write the running pushes (random ones of :class:`RandomizationConfig`, and :meth:`push`) to the base."""
        rnd = self.config.randomization
        if rnd.push_interval_s is not None:
            start_random_pushes(
                self._next_push, self._push_force, self._push_steps_left, self.rng, rnd, self.dt, self.sync_free
            )
        active = self._push_steps_left > 0
        # The force of this step, kept for lambda: the counter below already reads 0 during a push's last step.
        self._push_applied[...] = self.xp.where(active[:, None], self._push_force, 0.0)
        self._base_wrench[...] = self._push_wrench  # the force, and no torque
        self._push_steps_left[...] = self.xp.clip(self._push_steps_left - 1, min=0)

    # ------------------------------------------------------------------ observations
    def _observe(self, values: dict[str, Array]) -> Array:
        noise = self.config.randomization.observation_noise
        return assemble({**values, "last_action": self.last_action}, self._policy_terms, noise, self.rng)

    def _observe_state(self, state: SimulationState, ids: Any, scan_heights: Any = None) -> Any:
        """Policy observations of environments ``ids`` in ``state`` (read), ``scan_heights`` as in _policy_values."""
        values = {**self._policy_values(state, ids, scan_heights), "last_action": rows_of(self.last_action, ids)}
        noise = self.config.randomization.observation_noise
        return assemble(values, self._policy_terms, noise, self.rng)

    def _policy_values(self, state: SimulationState, ids: Any, scan_heights: Any = None) -> dict[str, Any]:
        """The robot-state terms of the observation (and the rewards), from a state read of ``ids``;
        ``scan_heights``: the ground under the scan's points where the step looked them up already."""
        values = robot_state_terms(state, rows_of(self.command, ids), self._standing_joint_pos)
        if self.config.height_scan:
            values["height_scan"] = self._ground.height_scan(state, scan_heights)
        return values

    def observe_all(self) -> Array:
        """Policy observations of every environment (after :meth:`reset`)."""
        return self.observe(np.arange(self.num_envs))

    def observe(self, ids: Any) -> Any:
        """Policy observations (len(ids), obs) of environments ``ids`` (e.g. just reset)."""
        ids = self._index(ids)
        observations = self._observe_state(self._read(ids), ids)
        check_finite_outputs(self.config, 0.0, observations)
        return observations

    def privileged_observation(self) -> Array:
        """Critic group: terrain heights around the feet, friction and the current margin."""
        return self._privileged(self._float(self.physics.site_xpos[:, self._reader.feet_sites]))

    def _privileged(self, feet: Any, around_feet: Any = None) -> Array:
        """The critic group with the feet (N, 4, 3) [m] (and the ground around them, where it was looked up)."""
        values = {
            "foot_terrain_heights": self._ground.heights_around(feet, self._foot_offsets, around_feet),
            "friction": self.mu[:, None],
            "margin": self._last_margin[:, None],
        }
        return assemble(values, PRIVILEGED_OBSERVATIONS, 0.0, self.rng)

    @property
    def last_lambda(self) -> Array:
        """lambda (N, 47) of the last step (for analysis and tests)."""
        return self._last_lambda

    def render_data(self, env: int = 0) -> mujoco.MjData:
        """An MjData with environment ``env``'s current state (for rendering)."""
        return self.physics.render_data(env)
