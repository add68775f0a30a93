"""Environment configuration: frozen dataclasses, built by the named presets below (no inheritance).

Units: s, m, rad, N. ``dt`` scaling of rewards does not exist here: the reward of seed 000 §V-C is used
as written (per policy step), and the shaped preset's weights are per policy step too.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from margin_rl.envs.terrain import TerrainConfig

REWARD_PRESETS: dict[str, dict[str, float]] = {
    # Seed 000 §V-C exactly: logistic velocity kernel plus the (weighted) learned margin.
    "paper": {"velocity_tracking": 1.0, "margin": 1.0},
    # The paper's two terms plus the usual locomotion regularisers (legged_gym-style magnitudes,
    # scaled to per-step rewards); "with" and "without margin" differ only in the margin weight.
    "shaped": {
        "velocity_tracking": 1.0,
        "margin": 1.0,
        "lateral_velocity": -0.05,
        "yaw_rate": -0.01,
        "vertical_velocity": -0.04,
        "roll_pitch_rate": -0.001,
        "orientation": -0.1,
        "torques": -2e-6,
        "action_rate": -0.002,
        "joint_acceleration": -5e-9,
        "feet_air_time": 0.04,
        "collisions": -0.02,
    },
}
"""Reward weights per preset; every term is defined in :mod:`margin_rl.envs.rewards`. The ``margin``
entry is multiplied by :attr:`EnvConfig.margin_weight`."""


@dataclass(frozen=True)
class CommandConfig:
    """Heading-velocity command [m/s]; a range samples it per episode (uniform)."""

    forward_velocity: tuple[float, float] = (0.75, 0.75)
    lateral_velocity: tuple[float, float] = (0.0, 0.0)
    yaw_rate: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class RandomizationConfig:
    """Domain randomisation (all off by default; the seed-000 experiment uses none)."""

    friction: tuple[float, float] | None = None  # terrain friction coefficient range, per episode
    added_base_mass: tuple[float, float] | None = None  # [kg], per environment at construction
    push_interval_s: float | None = None  # mean time between pushes [s]
    push_force: float = 150.0  # horizontal push magnitude [N], applied for push_duration_s
    push_duration_s: float = 0.2
    observation_noise: float = 0.0  # scale of the per-entry uniform noise (1.0 = legged_gym levels)
    reset_joint_noise: float = 0.1  # uniform joint-angle noise at reset [rad]
    reset_velocity_noise: float = 0.1  # uniform base velocity noise at reset [m/s, rad/s]


@dataclass(frozen=True)
class TerminationConfig:
    """Episode ends on base or thigh contact with the terrain, or outside these bounds."""

    min_base_height: float = 0.25  # base height above the terrain under it [m]
    max_tilt_rad: float = 1.0  # angle between the base z axis and the vertical


@dataclass(frozen=True)
class EnvConfig:
    """Everything that defines an ANYmal environment."""

    robot: str = "anymal_c"
    terrain: str = "flat"  # "flat" or "rough"
    terrain_config: TerrainConfig = field(default_factory=TerrainConfig)
    decimation: int = 4  # physics steps per policy step (5 ms x 4 = 50 Hz)
    action_scale: float = 0.5  # joint-target offset [rad] per unit action
    episode_length_s: float = 20.0
    reward_preset: str = "paper"
    # "learned", "analytic" (slow, ~2 ms per env step: validation), "fwp" (the feasible-wrench-polytope
    # factor s of seed 004 as the margin term, dimensionless, ~4-12 ms per env step) or "none"
    margin: str = "learned"
    margin_weight: float = 1.0  # weight of the margin term; 0 is the baseline of the comparison
    margin_weights: str | None = None  # learned-margin weights (.npz with its card); None: the robot's bundled
    # reward per policy step while the episode runs, added to any preset (the comparison gives both variants
    # the same bonus: the paper's L + m is negative per step for a trot, and PPO then learns to fall)
    alive_bonus: float = 0.0
    logistic_gain: float = 8.0  # L(gain * (v_cmd - v)) of seed 000 §V-C
    acceleration_filter: float = 0.0  # EMA factor on the finite-difference accelerations (0: none)
    privileged_observations: bool = False  # add the critic group (terrain heights, friction, margin)
    command: CommandConfig = field(default_factory=CommandConfig)
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)
    termination: TerminationConfig = field(default_factory=TerminationConfig)

    def __post_init__(self) -> None:
        if self.terrain not in ("flat", "rough"):
            raise ValueError(f"terrain must be 'flat' or 'rough', got {self.terrain!r}")
        if self.reward_preset not in REWARD_PRESETS:
            raise ValueError(f"reward_preset must be one of {sorted(REWARD_PRESETS)}, got {self.reward_preset!r}")
        if self.margin not in ("learned", "analytic", "fwp", "none"):
            raise ValueError(f"margin must be 'learned', 'analytic', 'fwp' or 'none', got {self.margin!r}")
        if not 0.0 <= self.alive_bonus < float("inf"):
            raise ValueError(f"alive_bonus must be finite and >= 0, got {self.alive_bonus}")
        if self.decimation < 1 or self.action_scale <= 0 or self.episode_length_s <= 0:
            raise ValueError("decimation, action_scale and episode_length_s must be positive")
        if not 0.0 <= self.acceleration_filter < 1.0:
            raise ValueError(f"acceleration_filter must be in [0, 1), got {self.acceleration_filter}")

    def replace(self, **changes: object) -> EnvConfig:
        """A copy with some fields changed (configs are never mutated)."""
        return dataclasses.replace(self, **changes)

    @property
    def reward_weights(self) -> dict[str, float]:
        weights = dict(REWARD_PRESETS[self.reward_preset])
        weights["margin"] = weights.get("margin", 0.0) * self.margin_weight
        if self.margin == "none":
            weights["margin"] = 0.0
        if self.alive_bonus:
            weights["alive"] = weights.get("alive", 0.0) + self.alive_bonus
        return weights
