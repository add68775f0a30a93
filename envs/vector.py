"""Native batched ``gymnasium.vector.VectorEnv`` over :class:`AnymalCore`.

``gymnasium.make_vec("margin_rl/AnymalB-v1", num_envs=64)`` builds it through ``vector_entry_point``.
All environments step together in ``mujoco.batch`` with one margin evaluation per step.

Autoreset (``autoreset_mode=``, an ``AutoresetMode`` or its value string, e.g. ``"SameStep"``;
``metadata["autoreset_mode"]`` holds the instance's mode):

* ``AutoresetMode.NEXT_STEP`` (the default): as Gymnasium defines it, the step after an episode ended returns
  that environment's reset observation, reward 0 and terminated = truncated = False, and ignores its action;
  its ``infos`` entries are masked out (``_key`` False, values zero). The default because it is Gymnasium's
  (``SyncVectorEnv``, ``AsyncVectorEnv``, ``make_vec`` in every mode) and the one its vector wrappers
  (``NormalizeObservation``, ``NormalizeReward``, ...) accept, so ``gymnasium.make_vec(id, n)`` behaves like a
  ``SyncVectorEnv`` of ``gymnasium.make(id)``. The training adapters of ``margin_rl.train`` (SB3, rsl-rl) step
  :class:`AnymalCore` directly with its same-step autoreset and are unaffected by this choice.
* ``AutoresetMode.SAME_STEP``: finished environments are reset inside the step that ended them: the returned
  observation is the reset one, the last one is in ``infos["final_obs"]`` and the last step's info in
  ``infos["final_info"]`` (masks ``_final_obs``, ``_final_info``), as SB3 and rsl-rl expect (and as v0 of the
  ids always did). One difference from Gymnasium's ``SyncVectorEnv`` in this mode: the top-level ``infos`` entries
  of an environment that was just reset hold its last step's values (masks True), where ``SyncVectorEnv`` would
  put the (empty) reset info; read ``final_info`` for the last step, as with Gymnasium.

``AutoresetMode.DISABLED`` (resets by ``reset(options={"reset_mask": ...})``) is not offered.

* ``step(actions)``: actions of shape ``(num_envs, 12)``, clipped to [-1, 1] like the single environment's;
  other shapes, NaN/inf or non-numeric values raise; ``step()`` before ``reset()`` raises
  ``gymnasium.error.ResetNeeded``.
* ``reset(seed=...)``: the batch shares one random generator, seeded from ``seed``: None (not reseeded), an
  int, or a list of ``num_envs`` ints, as Gymnasium's vector envs accept. As there, ``seed=s`` and
  ``seed=[s, s + 1, ..., s + num_envs - 1]`` are the same reset; any other list seeds the generator with
  all of its entries together (the same list gives the same rollout, but env i of a list-seeded batch is not
  the single environment reset with ``seed=list[i]``). A negative or non-int seed raises Gymnasium's
  ``gymnasium.error.Error`` (:class:`~margin_rl.envs.anymal.SeedError`, :class:`~margin_rl.envs.anymal.SeedTypeError`).
* ``get_attr(name)``, ``set_attr(name, values)``, ``call(name, *args, **kwargs)``: Gymnasium's VectorEnv API with
  per-environment semantics (one value per environment, in order), see :meth:`AnymalVectorEnv.get_attr`.
* ``render()`` (``render_mode="rgb_array"``): a tuple of ``num_envs`` frames of shape (height, width, 3), one
  per environment, as Gymnasium's ``SyncVectorEnv.render`` returns (``gymnasium.wrappers.vector.RecordVideo``
  tiles them); each costs one offscreen render, so pick ``width``/``height`` to match ``num_envs``.
* ``pickle`` and ``copy.deepcopy`` give an environment that steps to exactly the same numbers from there on.

Stable-Baselines3 accepts only its own ``VecEnv`` class, not this one: use
``margin_rl.train.make_sb3_env`` (same batched core) for SB3 and ``margin_rl.train.make_rsl_env`` for rsl-rl.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from margin_rl.arrays import like, to_numpy
from margin_rl.envs.anymal import (
    ACTION_SIZE,
    FrameRenderer,
    check_actions,
    check_frame_size,
    check_reset_options,
    check_seed,
    make_config,
)
from margin_rl.envs.backends import PHYSICS_BACKENDS
from margin_rl.envs.config import EnvConfig, check_int
from margin_rl.envs.core import ACTION_BOUND, AnymalCore
from margin_rl.envs.observations import observation_size, observation_structure, policy_observations

AUTORESET_MODES: tuple[AutoresetMode, ...] = (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)
"""The autoreset modes :class:`AnymalVectorEnv` offers; the first is the default (see the module docstring)."""

CONFIG_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(EnvConfig))
"""EnvConfig's fields: attributes shared by every environment of the batch."""

PER_ENV_ATTRIBUTES: dict[str, Callable[[AnymalCore], np.ndarray]] = {
    "command": lambda core: core.command,
    "episode_step": lambda core: core.episode_step,
    "friction": lambda core: core.mu,
    "added_base_mass": lambda core: core._added_mass,
}
"""Attributes with a value of their own in each environment: the heading-velocity command (forward, lateral
[m/s], yaw rate [rad/s]; settable), the running episode's policy steps, the terrain friction coefficient and the
mass added to the base [kg]."""


def check_autoreset_mode(mode: object) -> AutoresetMode:
    """``mode`` (an ``AutoresetMode``, its value such as ``"NextStep"`` or its name such as ``"NEXT_STEP"``) as
    an ``AutoresetMode`` of :data:`AUTORESET_MODES`; ValueError naming the accepted ones otherwise."""
    accepted = ", ".join(f"AutoresetMode.{m.name} ({m.value!r})" for m in AUTORESET_MODES)
    found = None
    if isinstance(mode, AutoresetMode):
        found = mode
    elif isinstance(mode, str):
        found = next((m for m in AutoresetMode if mode in (m.value, m.name)), None)
    if found is None:
        raise ValueError(f"autoreset_mode must be one of {accepted}, got {mode!r}")
    if found not in AUTORESET_MODES:
        raise ValueError(
            f"autoreset_mode {found} is not offered by the batched ANYmal env (it resets the environments "
            f"itself); use one of {accepted}"
        )
    return found


def batch_seed(seed: object, num_envs: int) -> int | None:
    """The one seed of the batch's generator for a vector ``reset(seed=...)`` (see the module docstring)."""
    if seed is None or not isinstance(seed, (Sequence, np.ndarray)) or isinstance(seed, (str, bytes)):
        return check_seed(seed, "seed")
    seeds = list(seed)
    if len(seeds) != num_envs:
        raise ValueError(f"a list of seeds must have one seed per environment ({num_envs}), got {len(seeds)}")
    if all(s is None for s in seeds):
        return None
    if any(s is None for s in seeds):
        raise ValueError(
            f"seed list {seeds!r} mixes None and ints, but the batch shares one random generator: "
            "pass an int for every environment, or None alone"
        )
    seeds = [check_seed(s, f"seed[{i}]") for i, s in enumerate(seeds)]
    if seeds == list(range(seeds[0], seeds[0] + num_envs)):
        return seeds[0]  # Gymnasium's meaning of an int seed s: [s, s + 1, ...]
    # Every entry matters: the generator is seeded with a 128-bit hash of the whole list.
    state = np.random.SeedSequence(seeds).generate_state(4, np.uint32)
    return int.from_bytes(state.tobytes(), "little")


class AnymalVectorEnv(VectorEnv):
    """``num_envs`` ANYmal environments stepped as one batch (see the module docstring)."""

    metadata = {"autoreset_mode": AUTORESET_MODES[0], "render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(
        self,
        num_envs: int = 1,
        robot: str = "anymal_c",
        terrain: str = "flat",
        config: EnvConfig | None = None,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        seed: int | None = None,
        width: int = 640,
        height: int = 480,
        autoreset_mode: AutoresetMode | str = AUTORESET_MODES[0],
        physics: str = PHYSICS_BACKENDS[0],
        physics_device: str | None = None,
        physics_options: dict[str, Any] | None = None,
        **overrides: Any,
    ) -> None:
        check_int("num_envs", num_envs, minimum=1, hint="environments in the batch")
        self.autoreset_mode = check_autoreset_mode(autoreset_mode)
        config = make_config(config, robot, terrain, overrides, type(self).__name__)
        if max_episode_steps is not None:
            check_int("max_episode_steps", max_episode_steps, minimum=1, hint="policy steps per episode, or None")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be 'rgb_array' or None for the batched env, got {render_mode!r}; for a window, "
                "render one environment: gymnasium.make(env_id, render_mode='human')"
            )
        check_frame_size(width, height)
        seed = check_seed(seed, "seed")
        same_step = self.autoreset_mode == AutoresetMode.SAME_STEP
        self.core = AnymalCore(
            config,
            num_envs=num_envs,
            seed=seed,
            autoreset=same_step,
            physics=physics,
            physics_device=physics_device,
            physics_options=physics_options,
        )
        if max_episode_steps is not None:
            self.core.max_episode_steps = int(max_episode_steps)
        self.num_envs = num_envs
        self.render_mode, self.width, self.height = render_mode, width, height
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.dt), "autoreset_mode": self.autoreset_mode}
        terms = policy_observations(self.core.config.height_scan)
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (observation_size(terms),), np.float32)
        self.single_action_space = spaces.Box(-ACTION_BOUND, ACTION_BOUND, (ACTION_SIZE,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_structure = observation_structure(terms)
        self._frames = FrameRenderer(self.core, width, height)
        self._needs_reset = True
        self._autoreset_envs = np.zeros(num_envs, dtype=bool)  # NEXT_STEP: reset these at the next step

    @property
    def config(self) -> EnvConfig:
        """The batch's EnvConfig (its core's: :meth:`set_attr` changes it there)."""
        return self.core.config

    @property
    def dt(self) -> float:
        return self.core.dt

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict]:
        seed = batch_seed(seed, self.num_envs)
        check_reset_options(options, type(self).__name__)
        super().reset(seed=seed)
        self.core.reset(seed=seed)
        observations = to_numpy(self.core.observe_all())
        self._needs_reset = False
        self._autoreset_envs[:] = False
        return observations, {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if self._needs_reset:
            raise ResetNeeded("AnymalVectorEnv.step() was called before reset(); call envs.reset(seed=...) first")
        actions = check_actions(
            actions,
            (self.num_envs, ACTION_SIZE),
            f"pass one row of 12 numbers per environment (num_envs={self.num_envs})",
        )
        out = self.core.step(actions).to_numpy()
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            return self._next_step_autoreset(out.observation, out.reward, out.terminated, out.truncated, out.info)
        infos: dict[str, Any] = {}
        all_envs = np.ones(self.num_envs, dtype=bool)
        for key, value in out.info.items():
            infos[key], infos[f"_{key}"] = value, all_envs
        done = out.terminated | out.truncated
        if done.any():
            final_obs = np.empty(self.num_envs, dtype=object)
            for i in np.nonzero(done)[0]:
                final_obs[i] = out.final_observation[i]
            infos["final_obs"], infos["_final_obs"] = final_obs, done
            infos["final_info"] = {**{k: v for k, v in out.info.items()}, **{f"_{k}": done for k in out.info}}
            infos["_final_info"] = done
        return out.observation, out.reward, out.terminated, out.truncated, infos

    def _next_step_autoreset(
        self,
        observation: np.ndarray,
        reward: np.ndarray,
        terminated: np.ndarray,
        truncated: np.ndarray,
        info: dict[str, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """NEXT_STEP: the environments that ended at the previous step are reset now. The batch stepped them
        too (it steps as one); that step is discarded: reset observation, reward 0, not done, info masked out."""
        resetting = self._autoreset_envs
        active = ~resetting
        if resetting.any():
            ids = np.flatnonzero(resetting)
            self.core.reset(ids)
            observation[ids] = to_numpy(self.core.observe(ids))
            reward[ids], terminated[ids], truncated[ids] = 0.0, False, False
            info = {k: np.where(active.reshape(-1, *([1] * (v.ndim - 1))), v, 0) for k, v in info.items()}
        infos: dict[str, Any] = {}
        for key, value in info.items():
            infos[key], infos[f"_{key}"] = value, active.copy()
        self._autoreset_envs = terminated | truncated
        return observation, reward, terminated, truncated, infos

    # ------------------------------------------------------------------ Gymnasium's attribute API
    def get_attr(self, name: str) -> tuple[Any, ...]:
        """One value per environment of attribute ``name``, as ``SyncVectorEnv.get_attr`` returns:

        * :data:`PER_ENV_ATTRIBUTES` (``command``, ``episode_step``, ``friction``, ``added_base_mass``): each
          environment's own value (a copy);
        * an EnvConfig field (``margin_weight``, ``reward_params``, ...): the batch's config value, the same for
          every environment (they share one config);
        * ``observation_space``, ``action_space``: the single environment's spaces;
        * any other public attribute of the batch (``render_mode``, ``dt``, ``config``, ``spec``, ...), repeated.

        Raises:
            AttributeError: no such attribute (the message lists the per-environment ones and the config fields).
        """
        if name in PER_ENV_ATTRIBUTES:
            values = to_numpy(PER_ENV_ATTRIBUTES[name](self.core))
            return tuple(values[i].item() if values.ndim == 1 else values[i].copy() for i in range(self.num_envs))
        if name in CONFIG_FIELDS:
            return (getattr(self.config, name),) * self.num_envs
        if name in ("observation_space", "action_space"):
            return (getattr(self, f"single_{name}"),) * self.num_envs
        if not name.startswith("_") and hasattr(self, name) and not callable(getattr(self, name)):
            return (getattr(self, name),) * self.num_envs
        raise AttributeError(f"{type(self).__name__} has no attribute {name!r} to get; {self._attribute_help()}")

    def set_attr(self, name: str, values: list[Any] | tuple[Any, ...] | Any) -> None:
        """Set attribute ``name`` of every environment, as ``SyncVectorEnv.set_attr``: a list or tuple gives one
        value per environment, anything else (e.g. a numpy array) the same value to all.

        * ``command``: each environment's heading-velocity command, 3 finite numbers; it holds from the next step
          until the environment's next reset draws a new one from ``EnvConfig.command``.
        * an EnvConfig field: the environments share one config, so every value must be the same; it is checked
          like any EnvConfig value (a mapping for ``reward_params`` changes the keys it names) and holds from the
          next step (randomisation and command ranges from each environment's next reset). Fields the
          simulation is built from (robot, terrain, decimation, episode length, margin model) cannot change.

        Raises:
            ValueError: a list of the wrong length, different values for a shared config field, a field that
                cannot change, or a bad command. AttributeError: any other name (the message lists the settable
                ones). TypeError: a badly typed config value.
        """
        if not isinstance(values, (list, tuple)):
            values = [values for _ in range(self.num_envs)]
        if len(values) != self.num_envs:
            raise ValueError(
                "Values must be a list or tuple with length equal to the number of environments. "
                f"Got `{len(values)}` values for {self.num_envs} environments (set_attr({name!r}, ...))."
            )
        if name == "command":
            self.core.command[:] = like(_commands(values), self.core.command)
            return
        if name in CONFIG_FIELDS:
            first = values[0]
            if any(not _same(v, first) for v in values[1:]):
                raise ValueError(
                    f"{name}: the environments of the batch share one EnvConfig, so set_attr({name!r}, ...) takes "
                    f"one value (or the same for every environment), got {list(values)!r}"
                )
            self.core.reconfigure(self.config.replace(**{name: first}))
            return
        raise AttributeError(
            f"{type(self).__name__}: {name!r} cannot be set; settable: command (per environment) and the EnvConfig "
            "fields (shared)"
        )

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """One result per environment, as ``SyncVectorEnv.call``: a method is called, an attribute read.

        ``call("render")`` gives the frames of :meth:`render` (None per environment without a render mode); an
        attribute name gives :meth:`get_attr`'s values. ``reset``, ``step`` and ``close`` act on the whole batch:
        call them on the vector env itself.

        Raises:
            AttributeError: no such method or attribute. TypeError: arguments for an attribute or for ``render``.
        """
        if name == "render":
            if args or kwargs:
                raise TypeError("render() takes no arguments (the frame size is set when the env is built)")
            frames = self.render()
            return frames if frames is not None else (None,) * self.num_envs
        if name in ("reset", "step", "close"):
            raise AttributeError(
                f"call({name!r}) would {name} each environment on its own, but the batch steps as one: call "
                f"envs.{name}(...) on the vector env"
            )
        values = self.get_attr(name)
        if args or kwargs:
            raise TypeError(f"{name!r} is an attribute, not a method: call({name!r}) takes no arguments")
        return values

    def _attribute_help(self) -> str:
        fields = ", ".join(CONFIG_FIELDS)
        return (
            f"per-environment attributes: {', '.join(PER_ENV_ATTRIBUTES)}; EnvConfig fields: {fields}; and the "
            "environment's own (render_mode, dt, config, spec, metadata, observation_space, action_space, ...)"
        )

    # ------------------------------------------------------------------ rendering, copies
    def render(self) -> tuple[np.ndarray, ...] | None:
        """One (height, width, 3) uint8 frame per environment (see the module docstring)."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self._needs_reset:
            raise ResetNeeded("AnymalVectorEnv.render() was called before reset(); call envs.reset(seed=...) first")
        return tuple(self._frames.frame(i) for i in range(self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        self._frames.close()


def _commands(values: Sequence[Any]) -> np.ndarray:
    """(N, 3) commands from one value per environment; ValueError unless each is 3 finite numbers."""
    try:
        commands = [np.asarray(v, dtype=np.float64) for v in values]
    except (TypeError, ValueError):
        commands = []
    if len(commands) != len(values) or any(c.shape != (3,) or not np.all(np.isfinite(c)) for c in commands):
        raise ValueError(
            "command values must be 3 finite numbers each (forward, lateral velocity [m/s], yaw rate [rad/s]), "
            f"got {list(values)!r}"
        )
    return np.stack(commands)


def _same(a: Any, b: Any) -> bool:
    """Whether two config values are equal (numpy arrays elementwise)."""
    try:
        return bool(np.all(a == b)) if isinstance(a, np.ndarray) or isinstance(b, np.ndarray) else bool(a == b)
    except (TypeError, ValueError):
        return False
