"""Native batched ``gymnasium.vector.VectorEnv`` over :class:`AnymalCore` (same-step autoreset).

``gymnasium.make_vec("margin_rl/AnymalB-v0", num_envs=64)`` builds it through ``vector_entry_point``.
All environments step together in ``mujoco.batch`` with one margin evaluation per step. Finished
environments are reset inside the step (``AutoresetMode.SAME_STEP``): the returned observation is the
reset one, the last one is in ``infos["final_obs"]`` and the last step's info in ``infos["final_info"]``
(masks ``_final_obs``, ``_final_info``), as SB3 and rsl-rl expect.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from margin_rl.envs.anymal import make_config
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.observations import observation_size, observation_structure


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
        **overrides: Any,
    ) -> None:
        self.config = make_config(config, robot, terrain, overrides)
        self.core = AnymalCore(self.config, num_envs=num_envs, seed=seed)
        if max_episode_steps is not None:
            self.core.max_episode_steps = int(max_episode_steps)
        self.num_envs = num_envs
        self.render_mode = render_mode
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (observation_size(),), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (12,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_structure = observation_structure()

    @property
    def dt(self) -> float:
        return self.core.dt

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.core.reset(seed=seed)
        return self.core.observe_all(), {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
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

    def render(self) -> np.ndarray | None:
        return None

    def close_extras(self, **kwargs: Any) -> None:
        pass
