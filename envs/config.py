"""Environment configuration: frozen dataclasses, built by the named presets below (no inheritance).

Units: s, m, rad, N. ``dt`` scaling of rewards does not exist here: the reward of seed 000 §V-C is used
as written (per policy step), and the shaped preset's weights are per policy step too.

Every config checks its fields when it is built (``__post_init__``): a wrong type raises TypeError, a
non-finite, wrongly signed or out-of-range number ValueError, each naming the field (``EnvConfig.margin_weight``)
and the accepted values. Valid values are stored as given, never converted, with one exception: a mapping
given for ``EnvConfig.reward_params`` becomes a :class:`RewardParams` (its keys checked by name).

The reward's added weights and parameters live in one mapping, ``EnvConfig.reward_params``
(:class:`RewardParams`: ``alive_bonus``, ``knee_clearance``, ``knee_clearance_height``, ``base_height``,
``base_height_fraction``, ``termination_penalty``, ``yaw_tracking``, ``base_acceleration``, ``logistic_gain``);
until EnvConfig v1 (the ``-v1`` ids) they were top-level fields. Stored v0 configs are translated in one place,
:func:`upgrade_stored_env_config` (table :data:`LEGACY_FIELDS`).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from margin_rl.envs.margin_kinds import check_margin_kind
from margin_rl.envs.terrain import TerrainConfig
from margin_rl.robot import available_robots

MARGIN_NORMALS: tuple[str, ...] = ("terrain", "vertical")
"""The contact normals lambda may carry (:attr:`EnvConfig.margin_normals`): the terrain's under each foot, or vertical
everywhere (the margin as if every contact stood on level ground)."""

MAX_TERRAIN_GRID_SIDE = 4001
"""Most heightfield samples per side of a rough terrain (4001^2 float64 = 128 MB): a larger ``size /
resolution`` is almost always a unit slip, and would exhaust memory before any error could be raised."""


# ---------------------------------------------------------------------------------------------------------------------
# field checks shared by the configs (and by the environments' own arguments)
# ---------------------------------------------------------------------------------------------------------------------
def _bounds_text(minimum: float | None, maximum: float | None, min_open: bool, max_open: bool) -> str:
    parts = []
    if minimum is not None:
        parts.append(f"{'>' if min_open else '>='} {minimum:g}")
    if maximum is not None:
        parts.append(f"{'<' if max_open else '<='} {maximum:g}")
    return " and ".join(parts)


def _in_bounds(value: float, minimum: float | None, maximum: float | None, min_open: bool, max_open: bool) -> bool:
    if minimum is not None and (value < minimum or (min_open and value == minimum)):
        return False
    return not (maximum is not None and (value > maximum or (max_open and value == maximum)))


def is_real_number(value: object) -> bool:
    """A real number (Python or numpy int/float), not a bool (``True`` as a weight is a mistake, not 1.0)."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def check_number(
    where: str,
    value: object,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    min_open: bool = False,
    max_open: bool = False,
    hint: str = "",
) -> None:
    """TypeError unless ``value`` is a real number; ValueError unless it is finite and within the bounds.

    ``where`` names the field in the message (``"EnvConfig.margin_weight"``); ``hint`` says what the value means.
    """
    bounds = _bounds_text(minimum, maximum, min_open, max_open)
    wanted = "a finite number" + (f" {bounds}" if bounds else "") + (f" ({hint})" if hint else "")
    if not is_real_number(value):
        example = f"; pass a number such as {where.rsplit('.', 1)[-1]}={float(value)}" if _parses(value) else ""
        raise TypeError(f"{where} must be {wanted}, got {value!r} ({type(value).__name__}){example}")
    if not math.isfinite(value) or not _in_bounds(value, minimum, maximum, min_open, max_open):
        raise ValueError(f"{where} must be {wanted}, got {value!r}")


def _parses(value: object) -> bool:
    """Whether a str holds a number (the message then shows the number to pass instead)."""
    if not isinstance(value, str):
        return False
    try:
        return math.isfinite(float(value))
    except ValueError:
        return False


def check_int(
    where: str, value: object, *, minimum: int | None = None, maximum: int | None = None, hint: str = ""
) -> None:
    """TypeError unless ``value`` is an integer (Python or numpy, not bool); ValueError outside the bounds."""
    bounds = _bounds_text(minimum, maximum, False, False)
    wanted = "an int" + (f" {bounds}" if bounds else "") + (f" ({hint})" if hint else "")
    if not isinstance(value, numbers.Integral) or isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{where} must be {wanted}, got {value!r} ({type(value).__name__})")
    if not _in_bounds(int(value), minimum, maximum, False, False):
        raise ValueError(f"{where} must be {wanted}, got {value!r}")


def check_range_pair(where: str, value: object, *, minimum: float | None = None, hint: str = "") -> None:
    """``value`` must be a (low, high) pair of finite numbers with low <= high (and low >= ``minimum``).

    Lists are accepted as well as tuples: configs read back from JSON (run directories) hold lists.
    """
    wanted = "a (low, high) pair of finite numbers with low <= high" + (
        f", low >= {minimum:g}" if minimum is not None else ""
    )
    wanted += f" ({hint})" if hint else ""
    pair_like = isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, (str, bytes))
    if not pair_like or len(value) != 2 or not all(is_real_number(v) for v in value):
        raise TypeError(f"{where} must be {wanted}, got {value!r} ({type(value).__name__})")
    low, high = value
    if not (math.isfinite(low) and math.isfinite(high)) or low > high:
        raise ValueError(f"{where} must be {wanted}, got {value!r}")
    if minimum is not None and low < minimum:
        raise ValueError(f"{where} must be {wanted}, got {value!r}")


def check_choice(where: str, value: object, choices: Sequence[str], hint: str = "") -> None:
    """ValueError unless ``value`` is one of ``choices`` (a str field with a fixed set of names)."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{where} must be one of {sorted(choices)}{f' ({hint})' if hint else ''}, got {value!r}")


def check_optional_path(where: str, value: object) -> None:
    """TypeError unless ``value`` is None, a str or a path (a weights file)."""
    if value is not None and not isinstance(value, (str, os.PathLike)):
        raise TypeError(f"{where} must be None or a path (str), got {value!r} ({type(value).__name__})")


def check_instance(where: str, value: object, cls: type, hint: str) -> None:
    """TypeError unless ``value`` is a ``cls`` (a nested config); ``hint`` says how to build one."""
    if not isinstance(value, cls):
        raise TypeError(f"{where} must be a {cls.__name__}, got {value!r} ({type(value).__name__}); {hint}")


def check_terrain_config(config: TerrainConfig) -> None:
    """Check a :class:`TerrainConfig`; :class:`EnvConfig` calls it (terrain.py is imported by this module, so
    it cannot import these checks back without an import cycle)."""
    where = "TerrainConfig"
    check_number(f"{where}.size", config.size, minimum=0.0, min_open=True, hint="side of the square of tiles [m]")
    check_number(f"{where}.border", config.border, minimum=0.0, hint="flat ground around the tiles [m]")
    check_number(f"{where}.resolution", config.resolution, minimum=0.0, min_open=True, hint="grid spacing [m]")
    check_number(f"{where}.tile", config.tile, minimum=0.0, min_open=True, hint="side of one tile [m]")
    check_range_pair(f"{where}.step_height", config.step_height, minimum=0.0, hint="[m]")
    check_number(
        f"{where}.max_slope_deg", config.max_slope_deg, minimum=0.0, maximum=90.0, max_open=True, hint="degrees"
    )
    check_number(f"{where}.pad", config.pad, minimum=0.0, maximum=config.tile, hint="flat spawn pad [m], <= tile")
    check_number(f"{where}.base_level", config.base_level, minimum=0.0, hint="[m]")
    check_number(
        f"{where}.max_height",
        config.max_height,
        minimum=config.base_level,
        min_open=True,
        hint="vertical extent of the heightfield [m], above base_level",
    )
    # The generator lays whole tiles of whole grid cells; other ratios would not fill the grid.
    for name, outer, inner, least in (
        ("size / tile", config.size, config.tile, 1),
        ("tile / resolution", config.tile, config.resolution, 1),
        ("border / resolution", config.border, config.resolution, 0),
    ):
        ratio = outer / inner
        if round(ratio) < least or abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio):
            raise ValueError(
                f"{where}: {name} must be a whole number >= {least} (the terrain is whole tiles of whole grid cells), "
                f"got size={config.size}, tile={config.tile}, border={config.border}, resolution={config.resolution}"
            )
    levels = config.curriculum_levels
    if isinstance(levels, bool) or not isinstance(levels, int) or levels == 1 or levels < 0:
        raise ValueError(
            f"{where}.curriculum_levels must be 0 (no curriculum) or a whole number >= 2 (rows of rising difficulty), "
            f"got {levels!r}"
        )
    initial = config.initial_max_level
    if isinstance(initial, bool) or not isinstance(initial, int) or initial < 0 or (levels and initial >= levels):
        raise ValueError(
            f"{where}.initial_max_level must be a whole level >= 0 and below curriculum_levels = {levels} "
            f"(environments start on levels 0..initial_max_level), got {initial!r}"
        )
    rows, columns = config.grid_shape()
    if max(rows, columns) > MAX_TERRAIN_GRID_SIDE:
        raise ValueError(
            f"{where}: the tiles and border at this resolution give a {rows} x {columns} heightfield, more than "
            f"{MAX_TERRAIN_GRID_SIDE} per side; use a coarser resolution, a smaller size, border or fewer curriculum "
            "levels (lengths are in metres)"
        )


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
    # The field's flat velocity task for ANYmal (legged_gym's anymal_c_flat, Isaac Lab's ANYmal-C flat velocity
    # task): their per-second weights times the policy step of 0.02 s, exponential kernels on the commanded planar
    # velocity and yaw rate. The margin's 0.08 per metre keeps its size against the tracking kernel's peak as in
    # "paper" (1 m against 0.25 there; 0.08 m against 0.02 here), so a margin weight means the same in both. Where
    # the two codebases differ and why (docs/rl.md "The field's reward").
    "field": {
        "tracking_lin_vel_xy": 1.0 * 0.02,
        "tracking_ang_vel_z": 0.5 * 0.02,
        "margin": 4.0 * 0.02,
        "vertical_velocity": -2.0 * 0.02,
        "roll_pitch_rate": -0.05 * 0.02,
        "orientation": -5.0 * 0.02,
        "torques": -2.5e-5 * 0.02,
        "joint_acceleration": -2.5e-7 * 0.02,
        "action_rate": -0.01 * 0.02,
        "feet_air_time": 0.5 * 0.02,
        "collisions": -1.0 * 0.02,
    },
}
"""Reward weights per preset; every term is defined in :mod:`margin_rl.envs.rewards`. The ``margin``
entry is multiplied by :attr:`EnvConfig.margin_weight`."""


@dataclass(frozen=True)
class CommandConfig:
    """Heading-velocity command [m/s]; a range samples it per episode (uniform)."""

    forward_velocity: tuple[float, float] = (0.75, 0.75)
    lateral_velocity: tuple[float, float] = (0.0, 0.0)
    yaw_rate: tuple[float, float] = (0.0, 0.0)  # [rad/s]

    def __post_init__(self) -> None:
        for name in ("forward_velocity", "lateral_velocity", "yaw_rate"):
            check_range_pair(f"CommandConfig.{name}", getattr(self, name), hint="(v, v) for a fixed command")


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

    def __post_init__(self) -> None:
        where = "RandomizationConfig"
        if self.friction is not None:
            check_range_pair(f"{where}.friction", self.friction, minimum=0.0, hint="friction coefficients, or None")
        if self.added_base_mass is not None:
            check_range_pair(f"{where}.added_base_mass", self.added_base_mass, hint="[kg], or None")
        if self.push_interval_s is not None:
            check_number(
                f"{where}.push_interval_s",
                self.push_interval_s,
                minimum=0.0,
                min_open=True,
                hint="[s], None: no pushes",
            )
        check_number(f"{where}.push_force", self.push_force, minimum=0.0, hint="[N]")
        check_number(f"{where}.push_duration_s", self.push_duration_s, minimum=0.0, min_open=True, hint="[s]")
        check_number(f"{where}.observation_noise", self.observation_noise, minimum=0.0, hint="0: none, 1: legged_gym")
        # A joint offset beyond pi wraps around the circle: a larger value is a degrees-for-radians slip.
        check_number(f"{where}.reset_joint_noise", self.reset_joint_noise, minimum=0.0, maximum=math.pi, hint="[rad]")
        check_number(f"{where}.reset_velocity_noise", self.reset_velocity_noise, minimum=0.0, hint="[m/s, rad/s]")


@dataclass(frozen=True)
class TerminationConfig:
    """Episode ends on base or thigh contact with the terrain, or outside these bounds."""

    min_base_height: float = 0.25  # base height above the terrain under it [m]
    max_tilt_rad: float = 1.0  # angle between the base z axis and the vertical

    def __post_init__(self) -> None:
        check_number("TerminationConfig.min_base_height", self.min_base_height, minimum=0.0, hint="[m]")
        # Tilt is an angle to the vertical, at most pi: a larger bound is a degrees-for-radians slip.
        check_number(
            "TerminationConfig.max_tilt_rad",
            self.max_tilt_rad,
            minimum=0.0,
            maximum=math.pi,
            min_open=True,
            hint="[rad]; pi never ends an episode on tilt",
        )


@dataclass(frozen=True)
class RewardParams(Mapping):
    """The weights of the terms added to any reward preset, and the reward's parameters: one mapping.

    Read like a dict (``params["alive_bonus"]``, ``dict(params)``) or by attribute; built from a mapping of
    some of its keys with :meth:`from_mapping` (an unknown key is an error listing the known ones).
    """

    # reward per policy step while the episode runs (term "alive"), added to any preset (the comparison gives
    # both variants the same bonus: the paper's L + m is negative per step for a trot, and PPO then learns to fall)
    alive_bonus: float = 0.0
    # Penalty per metre of knee below knee_clearance_height, summed over the legs (term "knee_clearance", 0: off),
    # added to any preset. The margin rewards a low CoM (the ICP offset v/omega_0 shrinks with height) and a wide
    # stance, and margin policies learned a crouched gait whose knees touch the floor (BENCHMARKS "Why the margin
    # policies fall"); the comparison gives both variants the same term.
    knee_clearance: float = 0.0
    knee_clearance_height: float = 0.2  # [m] above the terrain under the knee
    # Penalty per metre of base below base_height_fraction x the MJCF standing keyframe's base height (term
    # "base_height", 0: off), added to any preset. The knee term moves the margin policies' crouch rather than
    # removing it (BENCHMARKS "Margin weight sweep under the robust recipe"); this asks for the body height
    # itself. One-sided: a policy may walk taller; the comparison gives both variants the same term.
    base_height: float = 0.0
    base_height_fraction: float = 0.9  # of the standing keyframe's base height above the floor
    # Penalty on the step an episode ends in a fall (term "termination", 0: off), added to any preset, as the field's
    # rough-terrain tasks have it (legged_gym's "termination"). The alive bonus pays for every step survived; this
    # also makes the fall itself cost, which matters where falls come early (a policy walking onto a step it cannot
    # climb). The comparison gives both variants the same term.
    termination_penalty: float = 0.0
    # Weight of the yaw-rate tracking reward L(gain (omega_cmd - omega_z)) (term "yaw_tracking", 0: off), added to
    # any preset, as the field's velocity-tracking tasks track the yaw rate beside the linear velocity (legged_gym: half
    # the linear term's weight). The paper's reward tracks the heading velocity only, and policies trained on it turn
    # freely under a zero yaw command: on the terrain curriculum, whose promotion reads the distance from the spawn
    # point, a policy walking in circles is demoted however well it walks. The comparison gives both variants the
    # same term.
    yaw_tracking: float = 0.0
    # Penalty per (m/s^2)^2 of base linear acceleration, |a|^2 (term "base_acceleration", 0: off), added to any
    # preset: a plain smoothness penalty on what the margin is found to lower, the control that asks whether the
    # margin does anything a penalty of equal smoothing does not (docs/studies/field_reward.md).
    base_acceleration: float = 0.0
    logistic_gain: float = 8.0  # L(gain * (v_cmd - v)) of seed 000 §V-C

    def __post_init__(self) -> None:
        where = "RewardParams"
        check_number(f"{where}.alive_bonus", self.alive_bonus, minimum=0.0, hint="reward per step while alive")
        check_number(
            f"{where}.knee_clearance", self.knee_clearance, minimum=0.0, hint="penalty per m of knee too low, 0: off"
        )
        check_number(
            f"{where}.knee_clearance_height", self.knee_clearance_height, minimum=0.0, hint="[m] above the terrain"
        )
        check_number(
            f"{where}.base_height", self.base_height, minimum=0.0, hint="penalty per m of base too low, 0: off"
        )
        check_number(
            f"{where}.base_height_fraction",
            self.base_height_fraction,
            minimum=0.0,
            maximum=1.5,
            min_open=True,
            hint="of the standing keyframe's base height",
        )
        check_number(
            f"{where}.termination_penalty", self.termination_penalty, minimum=0.0, hint="penalty per fall, 0: off"
        )
        check_number(
            f"{where}.base_acceleration",
            self.base_acceleration,
            minimum=0.0,
            hint="penalty per (m/s^2)^2 of base linear acceleration, 0: off",
        )
        check_number(
            f"{where}.yaw_tracking",
            self.yaw_tracking,
            minimum=0.0,
            hint="weight of the yaw-rate tracking reward, 0: off",
        )
        # L is even (L(x) = L(-x)), so only the gain's size matters; 0 would make the velocity term constant.
        check_number(f"{where}.logistic_gain", self.logistic_gain, minimum=0.0, min_open=True, hint="[s/m]")

    @classmethod
    def keys_known(cls) -> tuple[str, ...]:
        """The keys, in order."""
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def check_keys(cls, mapping: Mapping[str, Any], where: str = "EnvConfig.reward_params") -> None:
        """TypeError naming every unknown key of ``mapping`` and listing the known ones."""
        if not isinstance(mapping, Mapping):
            raise TypeError(f"{where} must be a mapping of {', '.join(cls.keys_known())}, got {mapping!r}")
        unknown = [key for key in mapping if key not in cls.keys_known()]
        if unknown:
            raise TypeError(
                f"{where}: unknown key(s) {unknown}; the known keys are {', '.join(cls.keys_known())} "
                "(reward weights of the added terms and reward parameters)"
            )

    @classmethod
    def from_mapping(cls, mapping: Mapping[str, Any], where: str = "EnvConfig.reward_params") -> RewardParams:
        """The params with the keys of ``mapping``, the defaults elsewhere (unknown keys: TypeError)."""
        cls.check_keys(mapping, where)
        try:
            return cls(**dict(mapping))
        except (TypeError, ValueError) as exc:  # a bad value: say which mapping it came in
            raise type(exc)(f"{where}: {exc}") from exc

    def replace(self, **changes: Any) -> RewardParams:
        """A copy with the named keys changed (unknown keys: TypeError listing the known ones)."""
        self.check_keys(changes)
        return dataclasses.replace(self, **changes)

    def __getitem__(self, key: str) -> float:
        if key not in self.keys_known():
            raise KeyError(f"{key!r}: the reward parameters are {', '.join(self.keys_known())}")
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(self.keys_known())

    def __len__(self) -> int:
        return len(self.keys_known())


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
    margin: str = "learned"  # a name of margin_rl.envs.margin_kinds.MARGIN_KINDS
    margin_weight: float = 1.0  # weight of the margin term; 0 is the baseline of the comparison
    margin_weights: str | None = None  # learned-margin weights (.npz with its card); None: the robot's bundled
    # The contact normals lambda carries, so the margin the reward and the critic see: "terrain" (seed 000: each
    # foot's friction cone on the ground's normal under it) or "vertical" (every cone upright, as on flat ground: the
    # ablation that asks what the terrain normals add). Evaluation conditions measure with "terrain" (conditions.py).
    margin_normals: str = "terrain"
    # Weights of the terms added to any preset and the reward's parameters (RewardParams); a mapping of some
    # of its keys is accepted too: reward_params={"alive_bonus": 0.1} (the others keep their defaults here,
    # and keep the config's values in replace() and in gymnasium.make keywords).
    reward_params: RewardParams = field(default_factory=RewardParams)
    # EMA factor on the finite-difference accelerations in lambda (0: none). 0.5 halves the touchdown-impact
    # noise that otherwise drives the margin term (introduced with learned margin v2: BENCHMARKS "Accelerations in
    # lambda"); runs recorded before v2 keep their 0.0 in their config.json.
    acceleration_filter: float = 0.5
    privileged_observations: bool = False  # add the critic group (terrain heights, friction, margin)
    height_scan: bool = False  # add the actor's terrain height scan (observations.HEIGHT_SCAN): perceptive policies
    command: CommandConfig = field(default_factory=CommandConfig)
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)
    termination: TerminationConfig = field(default_factory=TerminationConfig)

    def __post_init__(self) -> None:
        where = "EnvConfig"
        if isinstance(self.reward_params, Mapping) and not isinstance(self.reward_params, RewardParams):
            object.__setattr__(self, "reward_params", RewardParams.from_mapping(self.reward_params))
        check_choice(f"{where}.robot", self.robot, available_robots())
        check_choice(f"{where}.terrain", self.terrain, ("flat", "rough"))
        check_choice(f"{where}.reward_preset", self.reward_preset, tuple(REWARD_PRESETS))
        check_margin_kind(self.margin)
        for name, cls in (
            ("terrain_config", TerrainConfig),
            ("command", CommandConfig),
            ("randomization", RandomizationConfig),
            ("termination", TerminationConfig),
        ):
            value = getattr(self, name)
            built = f"{name}={cls.__name__}(**{value!r})" if isinstance(value, dict) else f"{name}={cls.__name__}(...)"
            check_instance(f"{where}.{name}", value, cls, f"pass {built}")
        example = "{'alive_bonus': 0.1}"
        check_instance(
            f"{where}.reward_params",
            self.reward_params,
            RewardParams,
            f"pass a mapping such as reward_params={example} (keys: {', '.join(RewardParams.keys_known())})",
        )
        check_terrain_config(self.terrain_config)
        check_int(f"{where}.decimation", self.decimation, minimum=1, hint="physics steps per policy step")
        check_number(f"{where}.action_scale", self.action_scale, minimum=0.0, min_open=True, hint="[rad] per unit")
        check_number(f"{where}.episode_length_s", self.episode_length_s, minimum=0.0, min_open=True, hint="[s]")
        # A negative weight would reward instability; 0 is the without-margin baseline of the comparison.
        check_number(
            f"{where}.margin_weight", self.margin_weight, minimum=0.0, hint="0: the baseline without the margin term"
        )
        check_optional_path(f"{where}.margin_weights", self.margin_weights)
        check_choice(f"{where}.margin_normals", self.margin_normals, MARGIN_NORMALS)
        check_number(
            f"{where}.acceleration_filter",
            self.acceleration_filter,
            minimum=0.0,
            maximum=1.0,
            max_open=True,
            hint="EMA factor, 0: no filter",
        )
        for name in ("privileged_observations", "height_scan"):
            value = getattr(self, name)
            if not isinstance(value, (bool, np.bool_)):
                raise TypeError(f"{where}.{name} must be True or False, got {value!r} ({type(value).__name__})")

    def replace(self, **changes: object) -> EnvConfig:
        """A copy with some fields changed (configs are never mutated); a mapping for ``reward_params``
        changes only the keys it names (``replace(reward_params={"alive_bonus": 0.1})``)."""
        params = changes.get("reward_params")
        if isinstance(params, Mapping) and not isinstance(params, RewardParams):
            changes["reward_params"] = self.reward_params.replace(**params)
        return dataclasses.replace(self, **changes)

    @classmethod
    def upgrade_stored(cls, data: Mapping[str, Any]) -> dict[str, Any]:
        """A stored EnvConfig dict in the current layout (:func:`upgrade_stored_env_config`); read by
        ``margin_rl.train.config.from_dict`` before it builds the config."""
        return upgrade_stored_env_config(data)

    @classmethod
    def unknown_field_hint(cls, names: Iterable[str]) -> str:
        """What to pass instead of unknown field ``names`` that were EnvConfig v0 fields ("" for others)."""
        return legacy_field_hint(names)

    @property
    def reward_weights(self) -> dict[str, float]:
        weights = dict(REWARD_PRESETS[self.reward_preset])
        weights["margin"] = weights.get("margin", 0.0) * self.margin_weight
        if self.margin == "none":
            weights["margin"] = 0.0
        params = self.reward_params
        if params.alive_bonus:
            weights["alive"] = weights.get("alive", 0.0) + params.alive_bonus
        if params.knee_clearance:
            weights["knee_clearance"] = weights.get("knee_clearance", 0.0) - params.knee_clearance
        if params.base_height:
            weights["base_height"] = weights.get("base_height", 0.0) - params.base_height
        if params.termination_penalty:
            weights["termination"] = weights.get("termination", 0.0) - params.termination_penalty
        if params.yaw_tracking:
            weights["yaw_tracking"] = weights.get("yaw_tracking", 0.0) + params.yaw_tracking
        if params.base_acceleration:
            weights["base_acceleration"] = weights.get("base_acceleration", 0.0) - params.base_acceleration
        return weights


# ---------------------------------------------------------------------------------------------------------------------
# configs stored by earlier versions (run directories, policy bundles)
# ---------------------------------------------------------------------------------------------------------------------
LEGACY_FIELDS: dict[str, str] = {
    "alive_bonus": "reward_params",
    "knee_clearance": "reward_params",
    "knee_clearance_height": "reward_params",
    "logistic_gain": "reward_params",
}
"""EnvConfig v0 fields (the environment ids ``-v0``) -> the v1 field holding them, under the same key.

v0 kept the reward's added weights and parameters as top-level fields; v1 holds them in one mapping,
:class:`RewardParams`. Configs stored by v0 (``config.json`` of run directories and of the shipped policy
bundles) are read through :func:`upgrade_stored_env_config`, the one place they are translated; new code
and the command line use the v1 spelling (``reward_params={"alive_bonus": 0.1}``, ``--env-option
reward_params.alive_bonus=0.1``), and the v0 names get an error saying so."""


def upgrade_stored_env_config(data: Mapping[str, Any]) -> dict[str, Any]:
    """A stored EnvConfig dict with the v0 fields of :data:`LEGACY_FIELDS` moved to where v1 keeps them.

    A dict in the current layout is returned unchanged (as a new dict).

    Raises:
        ValueError: the dict holds a v0 field and a different value for the same key in its v1 place.
    """
    upgraded = dict(data)
    for old, new in LEGACY_FIELDS.items():
        if old not in upgraded:
            continue
        value = upgraded.pop(old)
        holder = upgraded.get(new)
        holder = dict(holder) if isinstance(holder, Mapping) else {} if holder is None else holder
        if not isinstance(holder, dict):
            raise TypeError(f"env_config.{new} must be a mapping, got {holder!r}")
        if old in holder and holder[old] != value:
            raise ValueError(
                f"env_config holds {old}={value!r} (EnvConfig v0) and {new}.{old}={holder[old]!r} (v1); keep one"
            )
        holder.setdefault(old, value)
        upgraded[new] = holder
    return upgraded


def legacy_field_hint(names: Iterable[str]) -> str:
    """An empty string, or, for the v0 fields of :data:`LEGACY_FIELDS` among ``names``, how v1 spells them."""
    moved = [name for name in names if name in LEGACY_FIELDS]
    if not moved:
        return ""
    parts = [f"{name} is now {LEGACY_FIELDS[name]}={{{name!r}: ...}}" for name in moved]
    first = moved[0]
    return (
        f"; EnvConfig v1 (the -v1 ids) keeps the reward weights and parameters in one mapping: {'; '.join(parts)} "
        f"(command line: --env-option {LEGACY_FIELDS[first]}.{first}=VALUE)"
    )
