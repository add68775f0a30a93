"""Native batched ``gymnasium.vector.VectorEnv`` over :class:`AnymalCore` (same-step autoreset).

``gymnasium.make_vec("margin_rl/AnymalB-v0", num_envs=64)`` builds it through ``vector_entry_point``.
All environments step together in ``mujoco.batch`` with one margin evaluation per step. Finished
environments are reset inside the step (``AutoresetMode.SAME_STEP``): the returned observation is the
reset one, the last one is in ``infos["final_obs"]`` and the last step's info in ``infos["final_info"]``
(masks ``_final_obs``, ``_final_info``), as SB3 and rsl-rl expect. One difference from Gymnasium's
``SyncVectorEnv`` in this mode: the top-level ``infos`` entries of an environment that was just reset hold its
last step's values (masks True), where ``SyncVectorEnv`` would put the (empty) reset info; read
``final_info`` for the last step, as with Gymnasium.

* ``step(actions)``: actions of shape ``(num_envs, 12)``, clipped to [-1, 1] like the single environment's;
  other shapes, NaN/inf or non-numeric values raise; ``step()`` before ``reset()`` raises
  ``gymnasium.error.ResetNeeded``.
* ``reset(seed=...)``: the batch shares one random generator, seeded from ``seed``: None (not reseeded), an
  int, or a list of ``num_envs`` ints, as Gymnasium's vector envs accept. As there, ``seed=s`` and
  ``seed=[s, s + 1, ..., s + num_envs - 1]`` are the same reset; any other list seeds the generator with
  all of its entries together (the same list gives the same rollout, but env i of a list-seeded batch is not
  the single environment reset with ``seed=list[i]``).
* ``render()`` (``render_mode="rgb_array"``): a tuple of ``num_envs`` frames of shape (height, width, 3), one
  per environment, as Gymnasium's ``SyncVectorEnv.render`` returns (``gymnasium.wrappers.vector.RecordVideo``
  tiles them); each costs one offscreen render, so pick ``width``/``height`` to match ``num_envs``.

Stable-Baselines3 accepts only its own ``VecEnv`` class, not this one: use
``margin_rl.train.make_sb3_env`` (same batched core) for SB3 and ``margin_rl.train.make_rsl_env`` for rsl-rl.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from margin_rl.envs.anymal import (
    ACTION_SIZE,
    FrameRenderer,
    check_actions,
    check_frame_size,
    check_reset_options,
    check_seed,
    make_config,
)
from margin_rl.envs.config import EnvConfig, check_int
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.observations import observation_size, observation_structure


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

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"], "render_fps": 50}

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
        **overrides: Any,
    ) -> None:
        check_int("num_envs", num_envs, minimum=1, hint="environments in the batch")
        self.config = make_config(config, robot, terrain, overrides)
        if max_episode_steps is not None:
            check_int("max_episode_steps", max_episode_steps, minimum=1, hint="policy steps per episode, or None")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be 'rgb_array' or None for the batched env, got {render_mode!r}; for a window, "
                "render one environment: gymnasium.make(env_id, render_mode='human')"
            )
        check_frame_size(width, height)
        seed = check_seed(seed, "seed")
        self.core = AnymalCore(self.config, num_envs=num_envs, seed=seed)
        if max_episode_steps is not None:
            self.core.max_episode_steps = int(max_episode_steps)
        self.num_envs = num_envs
        self.render_mode, self.width, self.height = render_mode, width, height
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.dt)}
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (observation_size(),), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_structure = observation_structure()
        self._frames = FrameRenderer(self.core, width, height)
        self._needs_reset = True

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
        observations = self.core.observe_all()
        self._needs_reset = False
        return observations, {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if self._needs_reset:
            raise ResetNeeded("AnymalVectorEnv.step() was called before reset(); call envs.reset(seed=...) first")
        actions = check_actions(
            actions,
            (self.num_envs, ACTION_SIZE),
            f"pass one row of 12 numbers per environment (num_envs={self.num_envs})",
        )
        out = self.core.step(actions)
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
