"""``margin_rl/AnymalB-v0``, ``AnymalC-v0`` and their ``-Rough-v0`` variants: one Gymnasium environment.

ANYmal walks at a commanded heading velocity (0.75 m/s by default) with the reward of seed 000 §V-C,

    r = L(8 (v_cmd - x_dot)) + w_m m(lambda),     L(x) = (e^-x + 2 + e^x)^-1,

where x_dot is the heading velocity in the base frame and m the learned stability margin of the robot
(``margin="learned"``, default), the analytic one (``margin="analytic"``, slow: for validating the
learned term in the loop) or none; ``margin_weight=0`` is the baseline of the with/without comparison.
``reward_preset="shaped"`` adds the usual locomotion regularisers (torques, action rate, orientation,
feet air time, collisions, ...); between "with" and "without margin" only the margin term differs.

* Action: 12 joint-position offsets in [-1, 1] (clipped; NaN raises ValueError), times
  ``action_scale`` [rad], around the standing keyframe's equilibrium servo targets; PD through the
  MJCF's position actuators (force-limited to the torque limits) at the physics rate, 50 Hz policy.
* Observation (48, float32, :data:`margin_rl.envs.observations.POLICY_OBSERVATIONS`, see
  ``observation_structure``): base linear and angular velocity (base frame), projected gravity, command,
  joint positions relative to standing, joint velocities, previous action.
* Episode: 20 s (TimeLimit, 1000 steps); terminated on base or thigh contact with the terrain, base
  height below 0.25 m above the terrain, tilt above 1 rad, or a diverged simulation
  (``info["diverged"]``).
* ``info``: every weighted reward term as ``reward_<term>`` (their sum is the reward), ``margin``,
  ``base_lin_acc`` and ``base_ang_acc`` (base frame; finite differences over the policy step),
  ``base_lin_vel``, ``velocity_error``, ``contacts``, ``stance_width``, ``fell``, ``diverged``.
* Options: ``config=EnvConfig(...)`` or any EnvConfig field as a keyword (``margin_weight``,
  ``reward_preset``, ``randomization=RandomizationConfig(friction=(0.4, 1.0), push_interval_s=5.0,
  observation_noise=1.0, ...)``, ``command=CommandConfig(forward_velocity=(0.25, 1.0))``), plus
  ``render_mode`` ("rgb_array", "human"), ``width``, ``height``.

Version history:
* v0: initial release.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from margin_rl.envs.config import EnvConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.observations import observation_size, observation_structure


def make_config(config: EnvConfig | None, robot: str, terrain: str, overrides: dict[str, Any]) -> EnvConfig:
    """The environment config: ``config`` (or the defaults for robot/terrain) with keyword overrides."""
    base = config if config is not None else EnvConfig(robot=robot, terrain=terrain)
    unknown = set(overrides) - set(EnvConfig.__dataclass_fields__)
    if unknown:
        raise TypeError(
            f"unknown environment options {sorted(unknown)}; EnvConfig fields: {sorted(EnvConfig.__dataclass_fields__)}"
        )
    return base.replace(**overrides) if overrides else base


class AnymalEnv(gymnasium.Env):
    """ANYmal B/C locomotion with a stability-margin reward (see the module docstring)."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 50}

    def __init__(
        self,
        robot: str = "anymal_c",
        terrain: str = "flat",
        config: EnvConfig | None = None,
        render_mode: str | None = None,
        width: int = 640,
        height: int = 480,
        **overrides: Any,
    ) -> None:
        self.config = make_config(config, robot, terrain, overrides)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.core = AnymalCore(self.config, num_envs=1, autoreset=False, truncate=False)
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.core.dt)}
        self.observation_space = spaces.Box(-np.inf, np.inf, (observation_size(),), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (12,), np.float32)
        self.observation_structure = observation_structure()
        self.render_mode, self.width, self.height = render_mode, width, height
        self._renderer = None
        self._viewer = None

    @property
    def dt(self) -> float:
        return self.core.dt

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.core.reset(seed=seed)
        return self.core.observe_all()[0], {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        out = self.core.step(np.asarray(action, dtype=np.float64)[None])
        info = {k: (v[0] if v.ndim == 1 else v[0].copy()) for k, v in out.info.items()}
        info = {k: float(v) if np.ndim(v) == 0 else v for k, v in info.items()}
        if self.render_mode == "human":
            self.render()
        return out.observation[0], float(out.reward[0]), bool(out.terminated[0]), False, info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        import mujoco

        data = self.core.render_data(0)
        if self.render_mode == "human":
            if self._viewer is None:
                import mujoco.viewer

                self._viewer = mujoco.viewer.launch_passive(self.core.model, data)
            self._viewer.sync()
            return None
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.core.model, self.height, self.width)
            self._camera = mujoco.MjvCamera()
            self._camera.distance, self._camera.elevation, self._camera.azimuth = 2.5, -20.0, 120.0
        self._camera.lookat[:] = data.qpos[:3]
        self._renderer.update_scene(data, self._camera)
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
