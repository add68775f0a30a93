r"""``margin_rl/SLIPHopper-v0``: apex-to-apex velocity tracking with the aSLIP hopper of seed 001.

The seed-000 idea (a velocity-tracking reward plus a learned margin term) applied to the learned
failure margin :math:`M(s, a)` of seed 001.  Everything is nondimensional (:math:`m = g = l_0 = 1`;
lengths in :math:`[l_0]`, velocities in :math:`[\sqrt{g l_0}]`), in the sagittal plane of
:mod:`margin_rl.slip.dynamics` (:math:`x` forward, :math:`y` up from the ground).

* One step is one hop from apex to apex, simulated with the true aSLIP (the reference simulator
  :func:`~margin_rl.slip.dynamics.simulate_hop`, paper parameters :class:`~margin_rl.slip.dynamics.SlipParams`).
* Action (float32, ``Box([-1, 1]^2)``): ``[a_alpha, a_dL]``, rescaled affinely to the action ranges of
  the eq. (13) box, touchdown angle :math:`\alpha = 0.6\,a_\alpha \in [-0.6, 0.6]` rad (from the vertical,
  positive with the foot ahead of the body) and actuator extension at maximum compression
  :math:`\Delta L = 0.05 + 0.1\,a_{dL} \in [-0.05, 0.15]` :math:`[l_0]`.  Out-of-range values are clipped;
  a non-finite or wrongly shaped action raises ``ValueError``.
* Observation (float32, 3): ``[y, xdot, xdot_goal]``, the apex height and forward speed and the goal
  apex velocity.  Bounds: ``y`` in [0, 3], ``xdot`` in [-3, 3] (apex states are clipped to them, which
  only happens on terminal steps with the default box termination; ``info["apex_state"]`` is unclipped),
  ``xdot_goal`` in ``goal_range``.
* Reset: the apex state is drawn uniformly from ``[init_low, init_high]`` (default ``y`` in [1.0, 1.2],
  ``xdot`` in [-1, 1]: every such state has valid actions, while below ``y`` of about 0.95 none has, since
  touchdown needs :math:`\cos\alpha \le y` and no touchdown slip needs :math:`|\tan\alpha| \le \mu = 0.5`),
  and the goal apex velocity uniformly from ``goal_range`` (default [-1, 1], the eq. (13) ``xdot`` range),
  unless fixed by ``goal_velocity=`` or by ``reset(options={"goal_velocity": v, "state": [y, xdot]})``.
* Reward, with every term in ``info["reward_<term>"]`` (their sum is the reward):

  - ``tracking`` :math:`= \exp(-((\dot x' - \dot x_{goal}) / \sigma)^2)`, :math:`\sigma` =
    ``tracking_sigma`` = 0.25 by default, with :math:`\dot x'` the speed at the next apex (0 when the hop
    fails);
  - ``margin`` :math:`= w_m M(s, a)`, the bundled learned failure margin
    (:func:`margin_rl.slip.models.load_bundle`) at the taken state-action :math:`z = [y, \dot x, \alpha,
    \Delta L]` (weighted-norm distance to failure, positive on predicted-valid pairs; about [0, 0.11] on
    valid and [-0.5, 0] on invalid pairs of the box), :math:`w_m` = ``margin_weight`` (1.0 by default;
    0.0 is the baseline of the with/without comparison);
  - ``failure`` = ``failure_reward`` (-1.0 by default) on a terminating step, else 0.

* Termination: an aSLIP failure of the hop (``Status`` FALL, SLIP, NO_LIFTOFF, NO_APEX, NO_TOUCHDOWN;
  the observation keeps the previous apex state) or, with ``terminate_out_of_box=True`` (default), a
  next apex outside the state part of the eq. (13) box (:math:`0.8 \le y \le 1.2`,
  :math:`|\dot x| \le 1`), where the learned :math:`M` was never trained (``info["out_of_box"]``).
  Episodes last 50 hops (TimeLimit of the registration).
* ``info``: ``status`` (the hop's :class:`~margin_rl.slip.dynamics.Status`), ``failed``, ``out_of_box``,
  ``alpha``, ``delta_l`` (the applied physical action), ``margin`` (:math:`M(s, a)`, unweighted),
  ``goal_velocity``, ``apex_state`` (``[y, xdot]`` now observed), ``velocity_error``
  (:math:`\dot x - \dot x_{goal}` of that state), ``dx`` (the hop's forward displacement, 0 on failure),
  ``x`` (forward position of the apex since the reset), and the reward terms.
* ``render_mode="rgb_array"``: a matplotlib drawing of the last hop (body path, leg at touchdown and
  liftoff).  Recording the path limits the integrator step, which changes the hops at the level of the
  integrator tolerance (1e-10).

Version history:
* v0: initial release.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from margin_rl.slip.dynamics import HopResult, SlipParams, Status, simulate_hop
from margin_rl.slip.margin import BOX_HIGH, BOX_LOW
from margin_rl.slip.models import BUNDLE_DIR, load_bundle

__all__ = [
    "ACTION_HIGH",
    "ACTION_LOW",
    "OBS_STATE_HIGH",
    "OBS_STATE_LOW",
    "STATE_BOX_HIGH",
    "STATE_BOX_LOW",
    "SlipHopperEnv",
    "action_to_physical",
]

FloatArray = NDArray[np.float64]

#: Physical action range ``[alpha, delta_L]`` (rad, :math:`[l_0]`): the action part of the eq. (13) box.
ACTION_LOW: FloatArray = BOX_LOW[2:].copy()
ACTION_HIGH: FloatArray = BOX_HIGH[2:].copy()
#: Observation bounds of the apex state ``[y, xdot]`` (:math:`[l_0]`, :math:`[\sqrt{g l_0}]`).
OBS_STATE_LOW: FloatArray = np.array([0.0, -3.0])
OBS_STATE_HIGH: FloatArray = np.array([3.0, 3.0])
#: State part ``[y, xdot]`` of the eq. (13) box: the domain of the learned networks.
STATE_BOX_LOW: FloatArray = BOX_LOW[:2].copy()
STATE_BOX_HIGH: FloatArray = BOX_HIGH[:2].copy()


def action_to_physical(action: ArrayLike) -> FloatArray:
    """Map a policy action in :math:`[-1, 1]^2` (clipped) to ``[alpha, delta_L]`` (rad, :math:`[l_0]`).

    Raises ``ValueError`` for a wrongly shaped or non-finite action.
    """
    a = np.asarray(action, dtype=np.float64)
    if a.shape != (2,):
        raise ValueError(f"action must have shape (2,) = [a_alpha, a_dL]; got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action must be finite; got {a!r}")
    a = np.clip(a, -1.0, 1.0)
    return ACTION_LOW + 0.5 * (a + 1.0) * (ACTION_HIGH - ACTION_LOW)


def _pair(name: str, value: Sequence[float] | ArrayLike) -> FloatArray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be two finite numbers; got {value!r}")
    return arr


class SlipHopperEnv(gymnasium.Env):
    """aSLIP apex-to-apex velocity tracking with an optional learned failure-margin reward.

    See the module docstring for spaces, reward, termination and ``info``.

    Parameters
    ----------
    margin_weight : float
        Weight :math:`w_m` of the learned-margin term (0.0: baseline without it).
    goal_velocity : float, optional
        Fixed goal apex velocity :math:`[\\sqrt{g l_0}]` (inside ``goal_range``); None: drawn per episode.
    goal_range : (float, float)
        Range of the goal apex velocity (observation bounds, and the uniform sampling range).
    init_low, init_high : (float, float)
        Corners of the uniform initial apex state ``[y, xdot]``.
    tracking_sigma : float
        :math:`\\sigma` of the tracking kernel, :math:`[\\sqrt{g l_0}]`.
    failure_reward : float
        Reward term of a terminating step (aSLIP failure or leaving the box).
    terminate_out_of_box : bool
        Terminate when the next apex leaves the state part of the eq. (13) box.
    params : SlipParams, optional
        aSLIP parameters (paper defaults; the bundled :math:`M` was trained with those).
    margin_bundle : str or Path, optional
        Directory of the ``P``/``M`` bundle (default: the one shipped in :mod:`margin_rl.slip`).
    render_mode : str, optional
        ``"rgb_array"`` or None.
    width, height : int
        Rendered image size in pixels.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(
        self,
        margin_weight: float = 1.0,
        goal_velocity: float | None = None,
        goal_range: Sequence[float] = (-1.0, 1.0),
        init_low: Sequence[float] = (1.0, -1.0),
        init_high: Sequence[float] = (1.2, 1.0),
        tracking_sigma: float = 0.25,
        failure_reward: float = -1.0,
        terminate_out_of_box: bool = True,
        params: SlipParams | None = None,
        margin_bundle: str | Path | None = None,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 320,
    ) -> None:
        for name, value in (("margin_weight", margin_weight), ("failure_reward", failure_reward)):
            if not np.isfinite(value):
                raise ValueError(f"{name} must be finite; got {value!r}")
        if not (np.isfinite(tracking_sigma) and tracking_sigma > 0):
            raise ValueError(f"tracking_sigma must be positive; got {tracking_sigma!r}")
        self.goal_range = _pair("goal_range", goal_range)
        if self.goal_range[1] < self.goal_range[0]:
            raise ValueError(f"goal_range must be increasing; got {goal_range!r}")
        if goal_velocity is not None:
            self._check_goal(goal_velocity)
        self.init_low, self.init_high = _pair("init_low", init_low), _pair("init_high", init_high)
        if np.any(self.init_high < self.init_low) or self.init_low[0] <= 0:
            raise ValueError(f"need 0 < init_low <= init_high (y > 0); got {init_low!r}, {init_high!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")

        self.margin_weight = float(margin_weight)
        self.goal_velocity = None if goal_velocity is None else float(goal_velocity)
        self.tracking_sigma = float(tracking_sigma)
        self.failure_reward = float(failure_reward)
        self.terminate_out_of_box = bool(terminate_out_of_box)
        self.params = params if params is not None else SlipParams()
        self.margin_model = load_bundle(BUNDLE_DIR if margin_bundle is None else margin_bundle).margin
        self.render_mode, self.width, self.height = render_mode, int(width), int(height)

        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        low = np.array([*OBS_STATE_LOW, self.goal_range[0]], dtype=np.float32)
        high = np.array([*OBS_STATE_HIGH, self.goal_range[1]], dtype=np.float32)
        self.observation_space = spaces.Box(low, high, (3,), np.float32)

        self._state: FloatArray | None = None
        self._goal = 0.0
        self._x = 0.0
        self._last_hop: HopResult | None = None
        self._last_hop_x = 0.0

    # ------------------------------------------------------------------ helpers

    def _check_goal(self, goal: float) -> float:
        g = float(goal)
        if not (np.isfinite(g) and self.goal_range[0] <= g <= self.goal_range[1]):
            raise ValueError(f"goal velocity must lie in goal_range {self.goal_range.tolist()}; got {goal!r}")
        return g

    def margin(self, state: ArrayLike, action: ArrayLike) -> float:
        """Learned failure margin :math:`M(s, a)` at apex state ``[y, xdot]`` and physical ``[alpha, delta_L]``."""
        z = np.concatenate([np.asarray(state, dtype=np.float64), np.asarray(action, dtype=np.float64)])
        return float(self.margin_model(z)[0])

    def _observation(self) -> np.ndarray:
        assert self._state is not None
        s = np.clip(self._state, OBS_STATE_LOW, OBS_STATE_HIGH)
        return np.array([s[0], s[1], self._goal], dtype=np.float32)

    @property
    def state(self) -> FloatArray:
        """Current apex state ``[y, xdot]`` (unclipped copy); raises before the first reset."""
        if self._state is None:
            raise RuntimeError("call reset() first")
        return self._state.copy()

    @property
    def goal(self) -> float:
        """Goal apex velocity of the episode."""
        return self._goal

    # ------------------------------------------------------------------ gymnasium API

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        opts = dict(options or {})
        unknown = set(opts) - {"goal_velocity", "state"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; known: goal_velocity, state")
        if opts.get("state") is not None:
            state = _pair("state", opts["state"])
            if state[0] <= 0:
                raise ValueError(f"apex height must be positive; got {state[0]!r}")
        else:
            state = self.init_low + (self.init_high - self.init_low) * self.np_random.random(2)
        if opts.get("goal_velocity") is not None:
            goal = self._check_goal(opts["goal_velocity"])
        elif self.goal_velocity is not None:
            goal = self.goal_velocity
        else:
            goal = float(self.goal_range[0] + (self.goal_range[1] - self.goal_range[0]) * self.np_random.random())
        self._state, self._goal, self._x = state, goal, 0.0
        self._last_hop, self._last_hop_x = None, 0.0
        info = {"goal_velocity": goal, "apex_state": state.copy(), "x": 0.0}
        return self._observation(), info

    def step(self, action: ArrayLike) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        physical = action_to_physical(action)
        state = self._state
        hop = simulate_hop(state, physical, self.params, record_path=self.render_mode == "rgb_array")
        margin = self.margin(state, physical)
        failed = not hop.ok
        if failed:
            next_state, dx, tracking = state, 0.0, 0.0
            out_of_box = False
        else:
            dx, next_state = float(hop.next_apex[0]), hop.next_apex[1:].copy()
            tracking = float(np.exp(-(((next_state[1] - self._goal) / self.tracking_sigma) ** 2)))
            out_of_box = bool(np.any(next_state < STATE_BOX_LOW) or np.any(next_state > STATE_BOX_HIGH))
        terminated = failed or (out_of_box and self.terminate_out_of_box)
        terms = {
            "reward_tracking": tracking,
            "reward_margin": self.margin_weight * margin,
            "reward_failure": self.failure_reward if terminated else 0.0,
        }
        self._last_hop, self._last_hop_x = hop, self._x
        self._state = next_state
        self._x += dx
        info: dict[str, Any] = {
            "status": Status(hop.status),
            "failed": failed,
            "out_of_box": out_of_box,
            "alpha": float(physical[0]),
            "delta_l": float(physical[1]),
            "margin": margin,
            "goal_velocity": self._goal,
            "apex_state": next_state.copy(),
            "velocity_error": float(next_state[1] - self._goal),
            "dx": dx,
            "x": self._x,
            **terms,
        }
        reward = float(sum(terms.values()))
        return self._observation(), reward, bool(terminated), False, info

    def render(self) -> np.ndarray | None:
        """An RGB image ``(height, width, 3)`` of the last hop (or of the apex after a reset)."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self._state is None:
            raise RuntimeError("call reset() before render()")
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        dpi = 100
        fig = Figure(figsize=(self.width / dpi, self.height / dpi), dpi=dpi)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes((0.1, 0.15, 0.86, 0.75))
        hop, x0 = self._last_hop, self._last_hop_x
        xs: list[float] = [self._x]
        if hop is not None and hop.path is not None:
            ax.plot(hop.path[:, 1] + x0, hop.path[:, 2], color="tab:blue", lw=1.5, label="body")
            xs.extend((hop.path[:, 1] + x0).tolist())
            for body, colour in ((hop.touchdown, "tab:green"), (hop.liftoff, "tab:orange")):
                if np.all(np.isfinite(body[:2])) and np.isfinite(hop.foot_x):
                    ax.plot([body[0] + x0, hop.foot_x + x0], [body[1], 0.0], color=colour, lw=2.0)
            title = f"hop: {Status(hop.status).name}"
        else:
            title = "reset"
        ax.plot([self._x], [self._state[0]], "o", color="black")
        lo, hi = min(xs) - 0.8, max(xs) + 0.8
        ax.axhline(0.0, color="0.3", lw=1.0)
        ax.set_xlim(lo, hi)
        ax.set_ylim(-0.05, max(1.4, float(self._state[0]) + 0.2))
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [l0]")
        ax.set_ylabel("y [l0]")
        ax.set_title(f"{title}, apex xdot {self._state[1]:+.2f}, goal {self._goal:+.2f}", fontsize=9)
        canvas.draw()
        image = np.asarray(canvas.buffer_rgba())[..., :3].copy()
        fig.clear()
        return image
