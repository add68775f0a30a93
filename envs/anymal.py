"""``margin_rl/AnymalB-v1``, ``AnymalC-v1`` and their ``-Rough-v1`` variants: one Gymnasium environment.

ANYmal walks at a commanded heading velocity (0.75 m/s by default) with the reward of seed 000 §V-C,

    r = L(8 (v_cmd - x_dot)) + w_m m(lambda),     L(x) = (e^-x + 2 + e^x)^-1,

where x_dot is the heading velocity in the base frame and m the stability margin of the robot, one of
:data:`margin_rl.envs.margin_kinds.MARGIN_KINDS` (``EnvConfig.margin``):

* ``"learned"`` (default): the learned margin MLP of seed 000 §IV [m], batched, fast;
* ``"analytic"``: the analytic margin of seed 000 §III [m], per environment, slow (validates the learned term);
* ``"fwp"``: the feasible-wrench-polytope feasibility factor s of seed 004 (dimensionless, s <= 1), per
  environment, slower still;
* ``"none"``: no margin term.

``margin_weight=0`` is the baseline of the with/without comparison. ``reward_preset="shaped"`` adds the
usual locomotion regularisers (torques, action rate, orientation, feet air time, collisions, ...); between
"with" and "without margin" only the margin term differs.

* Action: 12 joint-position offsets, shape (12,), times ``action_scale`` [rad], around the standing
  keyframe's equilibrium servo targets; PD through the MJCF's position actuators (force-limited to the
  torque limits) at the physics rate, 50 Hz policy. Clipping policy: values outside the action space
  [-1, 1] are clipped to it without a warning (as SB3 does with its policies' samples), so a = 5 acts as
  a = 1; NaN or inf, a wrong shape or a non-numeric dtype raise ValueError/TypeError naming the
  expected shape. ``step()`` before the first ``reset()`` raises ``gymnasium.error.ResetNeeded``.
* Observation (48, float32, :data:`margin_rl.envs.observations.POLICY_OBSERVATIONS`, see
  ``observation_structure``): base linear and angular velocity (base frame), projected gravity, command,
  joint positions relative to standing, joint velocities, previous action; with ``height_scan=True`` (235) also
  the terrain heights on a 1.6 m x 1.0 m grid around the base (:data:`~margin_rl.envs.observations.HEIGHT_SCAN`).
  Its bounds are ±inf: velocities have no physical bound short of the divergence check, and Gymnasium's MuJoCo
  robots do the same.
* Episode: ``EnvConfig.episode_length_s`` (20 s = 1000 steps by default), truncated by the environment
  itself (the ids carry no TimeLimit, so ``gymnasium.make(id, episode_length_s=10)`` gives 500-step
  episodes; ``max_episode_steps=`` adds a TimeLimit as usual); terminated when any of the named causes of
  :mod:`margin_rl.envs.terminations` holds: ``base_contact`` or ``thigh_contact`` with the terrain,
  ``base_height`` below 0.25 m above the terrain, ``tilt`` above 1 rad, or a ``diverged`` simulation. A
  non-finite reward or observation is never returned: it raises FloatingPointError.
* ``info``: every weighted reward term as ``reward_<term>`` (their sum is the reward), ``margin``,
  ``base_lin_acc`` and ``base_ang_acc`` (base frame; finite differences over the policy step),
  ``base_lin_vel``, ``velocity_error``, ``contacts``, ``stance_width``, ``base_height`` (base origin above the
  terrain under it [m]), ``touchdowns`` and ``edge_touchdowns`` (feet landing this step, and of them those landing
  on a step edge: :data:`margin_rl.envs.terrain.STEP_EDGE_RISE`), ``fell`` (terminated, not diverged),
  ``diverged``, ``termination_<cause>`` for each cause (1.0 where it holds this step, several may), and
  ``lambda``: the (47,) stability state the margin was evaluated on (seed 000 eq. 4; layout
  :data:`margin_rl.stability.LAMBDA_FIELDS`, one name per entry from :func:`margin_rl.stability.lambda_names`,
  decoded by :func:`margin_rl.stability.from_lambda`), so it can be logged, labelled or fed to another margin.
* Options: ``config=EnvConfig(...)`` or any EnvConfig field as a keyword (``margin_weight``,
  ``reward_preset``, ``reward_params={"alive_bonus": 0.1, "knee_clearance": 5.0}`` (the keys named change,
  the others keep their values), ``randomization=RandomizationConfig(friction=(0.4, 1.0),
  push_interval_s=5.0, observation_noise=1.0, ...)``, ``command=CommandConfig(forward_velocity=(0.25, 1.0))``),
  each checked when the config is built, plus ``render_mode``, ``width``, ``height``.
* Seeds: ``reset(seed=s)`` takes None or an int >= 0 (numpy ints too); anything else raises Gymnasium's own
  ``gymnasium.error.Error`` (as :func:`gymnasium.utils.seeding.np_random` does), as :class:`SeedError` /
  :class:`SeedTypeError`, which are also ValueError / TypeError.
* Copies: the environment (and the vector one) pickles and deep-copies, through Gymnasium's wrappers too; the
  copy is rebuilt from the config and given the whole state (simulation, random generator, commands, filters,
  pushes, episode counters), so it steps to exactly the same numbers as the original from there on.
* Rendering: ``"rgb_array"`` everywhere (headless: ``MUJOCO_GL=egl`` or ``osmesa``); ``"human"`` (MuJoCo's
  passive viewer) only where a display can open: ``metadata["render_modes"]`` of an instance lists it only
  when a display is configured, and asking for it without one raises :class:`DisplayUnavailableError`
  (MuJoCo's viewer would otherwise end the process from its GLFW thread, with nothing to catch).

Version history:

* v1: same dynamics, observations, rewards and termination conditions as v0 (a v0 policy runs unchanged). The
  termination causes are named terms, each reported per step as ``info["termination_<cause>"]`` (``fell`` and
  ``diverged`` kept); the reward's added weights and parameters are one mapping, ``reward_params`` (v0's
  top-level ``alive_bonus``, ``knee_clearance``, ``knee_clearance_height``, ``logistic_gain``; on the command
  line ``--env-option reward_params.alive_bonus=0.1``); the native vector env takes ``autoreset_mode``
  (``NEXT_STEP``, Gymnasium's default, is now its default; ``SAME_STEP`` as in v0) and has ``call``,
  ``get_attr``, ``set_attr``; the environments pickle and deep-copy; bad seeds raise ``gymnasium.error.Error``.
* v0: initial release: one termination flag, the reward's weights and parameters as top-level EnvConfig fields,
  same-step autoreset only in the vector env. While the id stayed v0, the acceleration filter's default became
  0.5 (it was 0.0; stored runs keep theirs in config.json) and the knee-clearance term was added (off by default).

The ``-v0`` ids are not registered any more: ``gymnasium.make("margin_rl/AnymalB-v0")`` raises Gymnasium's own
``gymnasium.error.DeprecatedEnv`` naming the ``-v1`` id. Run directories and policy bundles that stored a ``-v0``
id, and their v0 EnvConfig fields, are read as v1 (same dynamics) in one place each:
:func:`margin_rl.registration.current_env_id` and :func:`margin_rl.envs.config.upgrade_stored_env_config`.
"""

from __future__ import annotations

import os
import sys
import warnings
from typing import Any

import gymnasium
import mujoco
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from margin_rl.arrays import to_numpy
from margin_rl.envs.backends import PHYSICS_BACKENDS
from margin_rl.envs.config import EnvConfig, check_int
from margin_rl.envs.core import ACTION_BOUND, AnymalCore
from margin_rl.envs.observations import observation_size, observation_structure, policy_observations
from margin_rl.robot import mjcf_names

ACTION_SIZE = 12
"""One joint-position offset per joint (4 legs x HAA, HFE, KFE)."""


def make_config(
    config: EnvConfig | None, robot: str, terrain: str, overrides: dict[str, Any], owner: str = "AnymalEnv"
) -> EnvConfig:
    """The environment config: ``config`` (or the defaults for robot/terrain) with keyword overrides (a mapping
    for ``reward_params`` changes the keys it names).

    Raises:
        TypeError: an override that is no EnvConfig field, worded as Python words it (``<owner>.__init__() got an
            unexpected keyword argument 'x'``, so that a client probing optional keywords by that message can
            retry without it), followed by the valid fields.
    """
    if config is not None and not isinstance(config, EnvConfig):
        raise TypeError(
            f"config must be an EnvConfig or None, got {type(config).__name__}; pass config=EnvConfig(...) "
            "or the fields as keywords"
        )
    base = config if config is not None else EnvConfig(robot=robot, terrain=terrain)
    unknown = sorted(set(overrides) - set(EnvConfig.__dataclass_fields__))
    if unknown:
        raise TypeError(
            f"{owner}.__init__() got an unexpected keyword argument {unknown[0]!r}"
            f"{f' (and {unknown[1:]})' if unknown[1:] else ''}; the environment options are the EnvConfig fields "
            f"{sorted(EnvConfig.__dataclass_fields__)}{EnvConfig.unknown_field_hint(unknown)}"
        )
    return base.replace(**overrides) if overrides else base


# ---------------------------------------------------------------------------------------------------------------------
# checks of the public surface, shared with the batched env (margin_rl.envs.vector)
# ---------------------------------------------------------------------------------------------------------------------
def check_actions(actions: object, shape: tuple[int, ...], hint: str) -> np.ndarray:
    """``actions`` as float64 of exactly ``shape``, or a TypeError/ValueError naming the expected shape.

    Finite values are returned unchanged (the core clips them to [-1, 1]); ``hint`` says what to do instead.
    """
    expected = f"a float array of shape {shape} (joint-position offsets in [-1, 1], clipped outside)"
    try:
        raw = np.asarray(actions)
    except (TypeError, ValueError) as exc:  # ragged nested sequences
        raise ValueError(f"actions must be {expected}, got {actions!r}: {exc}; {hint}") from exc
    if raw.dtype.kind not in "iuf":  # strings, objects, bools and complex numbers are not joint offsets
        raise TypeError(f"actions must be {expected}, got dtype {raw.dtype} ({type(actions).__name__}); {hint}")
    if raw.shape != shape:
        raise ValueError(f"actions must be {expected}, got shape {raw.shape}; {hint}")
    values = raw.astype(np.float64)
    if not np.all(np.isfinite(values)):
        bad = np.argwhere(~np.isfinite(values)).tolist()
        raise ValueError(f"actions contain NaN or inf at {bad}; actions must be finite ({expected})")
    return values


class SeedError(gymnasium.error.Error, ValueError):
    """A negative seed: Gymnasium's own error type (``gymnasium.utils.seeding.np_random`` raises
    ``gymnasium.error.Error``), and a ValueError."""


class SeedTypeError(gymnasium.error.Error, TypeError):
    """A seed that is not an int: Gymnasium's own error type, and a TypeError."""


def check_seed(seed: object, where: str = "seed") -> int | None:
    """``seed`` as a Python int (numpy integers accepted) or None; :class:`SeedTypeError` (not an int) or
    :class:`SeedError` (negative) otherwise, both ``gymnasium.error.Error``."""
    if seed is None:
        return None
    try:
        check_int(where, seed, minimum=0, hint="None, or a non-negative int for a reproducible reset")
    except TypeError as exc:
        raise SeedTypeError(str(exc)) from None
    except ValueError as exc:
        raise SeedError(str(exc)) from None
    return int(seed)


def check_reset_options(options: object, owner: str) -> None:
    """The ANYmal environments take no reset options: any given would be silently ignored otherwise."""
    if options is None or (isinstance(options, dict) and not options):
        return
    raise ValueError(
        f"{owner}.reset takes no options, got {options!r}; set environment options when it is built "
        "(gymnasium.make(..., margin_weight=...)) instead"
    )


def check_frame_size(width: object, height: object) -> None:
    check_int("width", width, minimum=1, hint="frame width [pixels]")
    check_int("height", height, minimum=1, hint="frame height [pixels]")


# ---------------------------------------------------------------------------------------------------------------------
# rendering
# ---------------------------------------------------------------------------------------------------------------------
class DisplayUnavailableError(RuntimeError):
    """``render_mode="human"`` was asked for where MuJoCo's viewer cannot open a window."""


HEADLESS_ADVICE = (
    "on a headless machine use render_mode='rgb_array' (MUJOCO_GL=egl or osmesa) and keep the frames, e.g. "
    "with gymnasium.wrappers.RecordVideo, or run under a virtual display (xvfb-run)"
)


def display_unavailable_reason() -> str | None:
    """Why MuJoCo's interactive viewer cannot open here, or None where it may (a cheap check, opens nothing)."""
    if sys.platform == "darwin":
        # launch_passive needs the UI thread that only the `mjpython` launcher provides on macOS.
        viewer = sys.modules.get("mujoco.viewer")
        if getattr(viewer, "_MJPYTHON", None) is None:
            return "on macOS MuJoCo's viewer needs the script to run under `mjpython`"
        return None
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return "no display: neither DISPLAY nor WAYLAND_DISPLAY is set"
    return None


def require_display() -> None:
    """DisplayUnavailableError unless GLFW (MuJoCo's viewer backend) can open the display.

    MuJoCo's passive viewer starts GLFW on its own thread and, when that fails, ends the process with status
    1 and no Python exception; so GLFW is started here first, where a failure can be raised.
    """
    reason = display_unavailable_reason()
    if reason is None and sys.platform != "darwin":  # under mjpython GLFW belongs to the UI thread
        import glfw

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                started = glfw.init()
            except Exception as exc:  # glfw.ERROR_REPORTING = "raise" turns the failure into an exception
                started, caught = False, [exc]
        if not started:
            detail = "; ".join(str(getattr(w, "message", w)) for w in caught) or "glfw.init() failed"
            reason = f"GLFW cannot open the display {os.environ.get('DISPLAY', '')!r} ({detail})"
    if reason is not None:
        raise DisplayUnavailableError(f"render_mode='human' needs a display: {reason}; {HEADLESS_ADVICE}")


def available_render_modes() -> list[str]:
    """The render modes an environment built now can honour (``"human"`` only with a display)."""
    return ["human", "rgb_array"] if display_unavailable_reason() is None else ["rgb_array"]


class FrameRenderer:
    """RGB frames of the environments of an :class:`AnymalCore`, from a camera that follows each base."""

    def __init__(self, core: AnymalCore, width: int, height: int) -> None:
        self.core, self.width, self.height = core, width, height
        self._renderer: mujoco.Renderer | None = None
        self._camera = mujoco.MjvCamera()
        self._camera.distance, self._camera.elevation, self._camera.azimuth = 2.5, -20.0, 120.0

    def __getstate__(self) -> dict[str, Any]:  # the OpenGL renderer and the camera are rebuilt, not copied
        return {"core": self.core, "width": self.width, "height": self.height}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["core"], state["width"], state["height"])

    def frame(self, env: int) -> np.ndarray:
        """(height, width, 3) uint8 image of environment ``env``."""
        if self._renderer is None:  # built on first use: it needs an OpenGL context (MUJOCO_GL)
            self._renderer = mujoco.Renderer(self.core.model, self.height, self.width)
        data = self.core.render_data(env)
        self._camera.lookat[:] = data.qpos[mjcf_names.BASE_POSITION_QPOS]
        self._renderer.update_scene(data, self._camera)
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


# ---------------------------------------------------------------------------------------------------------------------
# the environment
# ---------------------------------------------------------------------------------------------------------------------
class AnymalEnv(gymnasium.Env):
    """ANYmal B/C locomotion with a stability-margin reward (see the module docstring)."""

    # The class lists every mode so that gymnasium.make passes render_mode="human" on to the constructor
    # (which then opens the viewer or raises DisplayUnavailableError); an instance lists what works here.
    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 50}

    def __init__(
        self,
        robot: str = "anymal_c",
        terrain: str = "flat",
        config: EnvConfig | None = None,
        render_mode: str | None = None,
        width: int = 640,
        height: int = 480,
        physics: str = PHYSICS_BACKENDS[0],
        physics_device: str | None = None,
        physics_options: dict[str, Any] | None = None,
        **overrides: Any,
    ) -> None:
        self.config = make_config(config, robot, terrain, overrides, type(self).__name__)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        check_frame_size(width, height)
        if render_mode == "human":
            require_display()
        # The env truncates its own episodes at EnvConfig.episode_length_s (the ids carry no TimeLimit), so a
        # shorter or longer episode_length_s given to gymnasium.make is the length the agent sees.
        self.core = AnymalCore(
            self.config,
            num_envs=1,
            autoreset=False,
            truncate=True,
            physics=physics,
            physics_device=physics_device,
            physics_options=physics_options,
        )
        self.metadata = {**self.metadata, "render_modes": available_render_modes(), "render_fps": round(1.0 / self.dt)}
        terms = policy_observations(self.core.config.height_scan)
        self.observation_space = spaces.Box(-np.inf, np.inf, (observation_size(terms),), np.float32)
        self.action_space = spaces.Box(-ACTION_BOUND, ACTION_BOUND, (ACTION_SIZE,), np.float32)
        self.observation_structure = observation_structure(terms)
        self.render_mode, self.width, self.height = render_mode, width, height
        self._frames = FrameRenderer(self.core, width, height)
        self._viewer = None
        self._needs_reset = True

    @property
    def dt(self) -> float:
        return self.core.dt

    def __getstate__(self) -> dict[str, Any]:  # an open viewer window is not copied
        return {**self.__dict__, "_viewer": None}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        seed = check_seed(seed)
        check_reset_options(options, type(self).__name__)
        super().reset(seed=seed)
        self.core.reset(seed=seed)
        observation = to_numpy(self.core.observe_all()[0])
        self._needs_reset = False
        return observation, {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._needs_reset:
            raise ResetNeeded("AnymalEnv.step() was called before reset(); call env.reset(seed=...) first")
        action = check_actions(
            action,
            (ACTION_SIZE,),
            "one environment takes one action of 12 numbers (use gymnasium.make_vec for a batch)",
        )
        out = self.core.step(action[None]).to_numpy()
        info = {k: (v[0] if v.ndim == 1 else v[0].copy()) for k, v in out.info.items()}
        info = {k: float(v) if np.ndim(v) == 0 else v for k, v in info.items()}
        if self.render_mode == "human":
            self.render()
        return out.observation[0], float(out.reward[0]), bool(out.terminated[0]), bool(out.truncated[0]), info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self._needs_reset:
            raise ResetNeeded("AnymalEnv.render() was called before reset(); call env.reset(seed=...) first")
        if self.render_mode == "rgb_array":
            return self._frames.frame(0)
        if self._viewer is None:
            import mujoco.viewer

            self._viewer = mujoco.viewer.launch_passive(self.core.model, self.core.render_data(0))
        else:  # the viewer shows the MjData it was given: copy the current state into it
            data = self.core.render_data(0)
            with self._viewer.lock():
                self._viewer.d.qpos[:], self._viewer.d.qvel[:] = data.qpos, data.qvel
                mujoco.mj_forward(self.core.model, self._viewer.d)
        self._viewer.sync()
        return None

    def close(self) -> None:
        self._frames.close()
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
