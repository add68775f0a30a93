r"""Nondimensional actuated spring-loaded inverted pendulum (aSLIP) hopper.

All quantities are nondimensional: mass :math:`m = 1`, gravity :math:`g = 1`, rest leg
length :math:`l_0 = 1`; lengths are in :math:`[l_0]`, velocities in :math:`[\sqrt{g l_0}]`,
times in :math:`[\sqrt{l_0 / g}]`, forces in :math:`[m g]` and energies in :math:`[m g l_0]`.

Model
-----
A point mass at :math:`q = (x, y)` rides on a massless leg.  The leg is a linear spring
(stiffness :math:`k`) in parallel with a linear damper (coefficient
:math:`c = 2 \zeta \sqrt{k m}`, damping ratio :math:`\zeta`), and this spring-damper is in
series with a prismatic extension actuator of prescribed length :math:`L_a(t)`.  The
friction coefficient between foot and ground is :math:`\mu`.  Defaults follow the paper:
:math:`k = 20`, :math:`\zeta = 0.1`, :math:`\mu = 0.5`.

The reduced apex state is :math:`s = [y, \dot x]` and the action is
:math:`a = [\alpha, \Delta L]`: touchdown leg angle (from the vertical, positive when the
foot is placed *ahead* of the body in :math:`+x`) and actuator extension at maximum
compression.  A hop starts at an apex :math:`(x, y, \dot x, \dot y) = (0, y_0, \dot x_0, 0)`.

Flight (ballistic; the leg is repositioned instantly to :math:`\alpha`)
    .. math:: \ddot x = 0, \qquad \ddot y = -1.

Touchdown guard
    The foot :math:`(x + \sin\alpha,\; y - \cos\alpha)` reaches the ground:
    :math:`y - \cos\alpha = 0` with :math:`\dot y \le 0`, i.e. at
    :math:`t_{td} = \sqrt{2 (y_0 - \cos\alpha)}`.  The foot is pinned at
    :math:`x_f = x_{td} + \sin\alpha`; the actuator starts at :math:`L_a = 0` so the spring
    is at rest length and there is no impact loss (the leg is massless).

Stance (foot pinned at :math:`(x_f, 0)`; :math:`r = (x - x_f, y)`, :math:`l = |r|`,
:math:`\dot l = r \cdot \dot q / l`)
    spring-damper compression :math:`\delta = 1 + L_a(t) - l`, leg force (pushing the body
    away from the foot)

    .. math:: F = k \delta + c \dot\delta = k (1 + L_a - l) + c (\dot L_a - \dot l),

    .. math:: \ddot x = F (x - x_f) / l, \qquad \ddot y = F y / l - 1.

    The ground reaction force on the foot has normal part :math:`F_n = F y / l` and
    tangential part :math:`F_t = F (x - x_f) / l`.

Actuator profile (Raibert-style thrust at bottom)
    :math:`L_a = 0` until maximum compression :math:`t_{mc}` (first :math:`\dot l = 0` in
    stance, from below).  Afterwards the actuator extends by :math:`\Delta L` along a cubic
    smoothstep of duration :math:`T_e` (``extension_time``):

    .. math:: L_a(t) = \Delta L\,(3\sigma^2 - 2\sigma^3), \quad
              \sigma = \mathrm{clip}((t - t_{mc}) / T_e, 0, 1).

    :math:`L_a` and :math:`\dot L_a` are continuous, so :math:`F` is continuous (a step in
    :math:`L_a` would put an impulse through the damper).  :math:`\Delta L < 0` retracts.

Liftoff guard
    The foot can only push: liftoff when :math:`F` decreases through zero.  With damping,
    :math:`F = 0` happens while the spring is still compressed (:math:`k\delta = -c\dot\delta`);
    that residual spring energy :math:`\tfrac12 k \delta_{lo}^2` is dissipated in the massless
    leg during flight (``leg_energy_loss``).

Next apex (section of eq. 11)
    After liftoff, flight until :math:`\dot y = 0`:
    :math:`t_{ap} = \dot y_{lo}`, :math:`y_1 = y_{lo} + \dot y_{lo}^2 / 2`,
    :math:`\Delta x = x_{lo} + \dot x_{lo} \dot y_{lo}`, :math:`\dot x_1 = \dot x_{lo}`.
    The controlled first return map (eq. 14) is
    :math:`[\Delta x, y_1, \dot x_1] = \Phi(y_0, \dot x_0, \alpha, \Delta L)`.

Failure modes (:class:`Status`)
    * ``NO_TOUCHDOWN`` -- :math:`y_0 < \cos\alpha`: the foot would start below the ground, so
      the leg cannot be placed at :math:`\alpha` (the paper's box, eq. 13, contains such
      points; we label them invalid).
    * ``FALL`` -- the body reaches :math:`y = 0` in stance, or the leg is already lengthening
      at touchdown (:math:`\dot l_{td} > 0`): it can never be loaded and nothing arrests the
      descent.
    * ``SLIP`` -- :math:`|F_t| > \mu F_n` with :math:`F > 0`.  Because the massless leg only
      transmits axial force this is the geometric condition :math:`|x - x_f| > \mu y`; it is
      checked at touchdown (:math:`|\tan\alpha| > \mu`) and as an event during stance.
    * ``NO_LIFTOFF`` -- stance lasts longer than ``max_stance_time``.
    * ``NO_APEX`` -- liftoff with :math:`\dot y_{lo} \le 0`: the body never rises to an apex.

Energy bookkeeping
    :math:`E = \tfrac12 |\dot q|^2 + y + \tfrac12 k \delta^2` obeys
    :math:`\dot E = F \dot L_a - c \dot\delta^2` in stance, so
    :math:`E_1 = E_0 + W_{act} - W_{damp} - \tfrac12 k \delta_{lo}^2`, with apex energies
    :math:`E = \tfrac12 \dot x^2 + y`.  Both simulators integrate :math:`W_{act}` and
    :math:`W_{damp}` alongside the state so this identity can be checked.

Two simulators are provided: :func:`simulate_hop`, a reference single-hop simulator built
on :func:`scipy.integrate.solve_ivp` with event detection, and :func:`simulate_batch`, a
vectorised fixed-step RK4 integrator over many hops at once with per-sample event location
(bisection on the cubic Hermite interpolant of the step, then an exact RK4 re-step to the
event time).  Flight phases are integrated in closed form by the batch simulator.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import solve_ivp

__all__ = [
    "BatchResult",
    "HopResult",
    "SlipParams",
    "Status",
    "actuator_profile",
    "apex_energy",
    "return_map",
    "simulate_batch",
    "simulate_hop",
]

FloatArray = NDArray[np.float64]


class Status(enum.IntEnum):
    """Outcome of one hop from apex to apex (0 means success)."""

    OK = 0
    FALL = 1
    SLIP = 2
    NO_LIFTOFF = 3
    NO_APEX = 4
    NO_TOUCHDOWN = 5


@dataclass(frozen=True)
class SlipParams:
    """Nondimensional aSLIP parameters.

    Parameters
    ----------
    stiffness : float
        Leg spring stiffness :math:`k` in :math:`[m g / l_0]` (paper: 20).
    damping_ratio : float
        :math:`\\zeta = c / (2\\sqrt{k m})` (paper: 0.1).
    friction : float
        Coulomb friction coefficient :math:`\\mu` (paper: 0.5).
    extension_time : float
        Duration :math:`T_e` of the actuator smoothstep in :math:`[\\sqrt{l_0/g}]`.  Not given
        in the paper; 0.1 is about a third of the decompression half of a stance.
    max_stance_time : float
        Stance longer than this is a ``NO_LIFTOFF`` failure (a loaded stance lasts about
        :math:`\\pi/\\sqrt{k} \\approx 0.7`).
    """

    stiffness: float = 20.0
    damping_ratio: float = 0.1
    friction: float = 0.5
    extension_time: float = 0.1
    max_stance_time: float = 3.0

    def __post_init__(self) -> None:
        checks = {
            "stiffness": self.stiffness > 0,
            "damping_ratio": self.damping_ratio >= 0,
            "friction": self.friction >= 0,
            "extension_time": self.extension_time > 0,
            "max_stance_time": self.max_stance_time > 0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (ok and np.isfinite(value)):
                raise ValueError(f"SlipParams.{name} is invalid: {value!r}")

    @property
    def damping(self) -> float:
        """Damping coefficient :math:`c = 2 \\zeta \\sqrt{k m}` with :math:`m = 1`."""
        return 2.0 * self.damping_ratio * float(np.sqrt(self.stiffness))


# ----------------------------------------------------------------------------------------
# Shared model pieces
# ----------------------------------------------------------------------------------------


def actuator_profile(tau: ArrayLike, delta_l: ArrayLike, extension_time: float) -> tuple[FloatArray, FloatArray]:
    """Actuator length and rate, :math:`L_a` and :math:`\\dot L_a`, ``tau`` after max compression.

    Returns zeros for ``tau <= 0`` (before maximum compression, or ``tau = -inf``).
    """
    tau_arr = np.asarray(tau, dtype=float)
    dl = np.asarray(delta_l, dtype=float)
    sigma = np.clip(tau_arr / extension_time, 0.0, 1.0)
    length = dl * sigma * sigma * (3.0 - 2.0 * sigma)
    rate = dl * 6.0 * sigma * (1.0 - sigma) / extension_time
    return length, rate


def apex_energy(y: ArrayLike, xdot: ArrayLike) -> FloatArray:
    """Mechanical energy at an apex, :math:`E = \\dot x^2 / 2 + y` in :math:`[m g l_0]`."""
    return 0.5 * np.square(np.asarray(xdot, dtype=float)) + np.asarray(y, dtype=float)


def _stance_rhs(
    t: FloatArray | float,
    z: FloatArray,
    t_mc: FloatArray | float,
    delta_l: FloatArray | float,
    p: SlipParams,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Stance vector field on ``z = [x - x_f, y, xdot, ydot, W_act, W_damp]`` (rows).

    Works on shape ``(6,)`` or ``(6, n)``.  Returns ``(dz, ldot, F)`` so that callers get the
    quantities their event functions need without recomputation.
    """
    xr, y, vx, vy = z[0], z[1], z[2], z[3]
    length = np.sqrt(xr * xr + y * y)
    ldot = (xr * vx + y * vy) / length
    la, la_dot = actuator_profile(np.asarray(t) - t_mc, delta_l, p.extension_time)
    delta_dot = la_dot - ldot
    force = p.stiffness * (1.0 + la - length) + p.damping * delta_dot
    f_over_l = force / length
    dz = np.stack([vx, vy, f_over_l * xr, f_over_l * y - 1.0, force * la_dot, p.damping * delta_dot * delta_dot])
    return dz, ldot, force


def _validate_batch(states: ArrayLike, actions: ArrayLike) -> tuple[FloatArray, FloatArray]:
    s = np.asarray(states, dtype=float)
    a = np.asarray(actions, dtype=float)
    if s.ndim != 2 or s.shape[1] != 2:
        raise ValueError(f"states must have shape (n, 2) = [y, xdot]; got {s.shape}")
    if a.ndim != 2 or a.shape[1] != 2:
        raise ValueError(f"actions must have shape (n, 2) = [alpha, delta_L]; got {a.shape}")
    if s.shape[0] != a.shape[0]:
        raise ValueError(f"states and actions differ in length: {s.shape[0]} != {a.shape[0]}")
    if not np.all(np.isfinite(s)):
        raise ValueError("states contain non-finite values")
    if not np.all(np.isfinite(a)):
        raise ValueError("actions contain non-finite values")
    if np.any(s[:, 0] <= 0):
        raise ValueError("states: apex height y must be positive")
    if np.any(np.abs(a[:, 0]) >= np.pi / 2):
        raise ValueError("actions: |alpha| must be below pi/2")
    return s, a


# ----------------------------------------------------------------------------------------
# Reference single-hop simulator (solve_ivp with events)
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class HopResult:
    """Outcome of one simulated hop from the apex ``(0, y0, xdot0, 0)`` at ``t = 0``.

    States are world-frame ``[x, y, xdot, ydot]``; entries that the hop never reached are NaN.

    Attributes
    ----------
    status : Status
        ``Status.OK`` when the next apex was reached.
    next_apex : ndarray, shape (3,)
        ``[dx, y1, xdot1]`` (eq. 14); NaN on failure.
    touchdown, liftoff, failure : ndarray, shape (4,)
        World state at touchdown, at liftoff, and where the failure was detected.
    t_touchdown, t_max_compression, t_liftoff, t_apex : float
        Event times (NaN when not reached).
    foot_x : float
        Foot position during stance.
    energy0, energy1 : float
        Apex energies :math:`\\dot x^2/2 + y` (``energy1`` NaN on failure).
    work_actuator, work_damping, leg_energy_loss : float
        :math:`\\int F \\dot L_a\\,dt`, :math:`\\int c \\dot\\delta^2 dt` and
        :math:`\\tfrac12 k \\delta_{lo}^2` (up to the end of stance or the failure).
    path : ndarray, shape (m, 3), optional
        Rows ``[t, x, y]`` of the body path up to the next apex or the failure, when
        ``record_path=True`` was passed (for plots).
    """

    status: Status
    next_apex: FloatArray
    touchdown: FloatArray
    liftoff: FloatArray
    failure: FloatArray
    t_touchdown: float
    t_max_compression: float
    t_liftoff: float
    t_apex: float
    foot_x: float
    energy0: float
    energy1: float
    work_actuator: float
    work_damping: float
    leg_energy_loss: float
    path: FloatArray | None = None

    @property
    def ok(self) -> bool:
        """True when the hop returned to the apex section."""
        return self.status is Status.OK

    @property
    def energy_residual(self) -> float:
        """:math:`E_1 - (E_0 + W_{act} - W_{damp} - E_{leg})`; zero up to integration error."""
        return self.energy1 - (self.energy0 + self.work_actuator - self.work_damping - self.leg_energy_loss)


_EventFn = Callable[[float, FloatArray], float]


def _event(fun: _EventFn, direction: float) -> _EventFn:
    """Mark a scalar function as a terminal solve_ivp event with the given direction."""

    def wrapped(t: float, z: FloatArray) -> float:
        return fun(t, z)

    wrapped.terminal = True  # type: ignore[attr-defined]
    wrapped.direction = direction  # type: ignore[attr-defined]
    return wrapped


def simulate_hop(
    state: ArrayLike,
    action: ArrayLike,
    params: SlipParams | None = None,
    *,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    method: str = "DOP853",
    record_path: bool = False,
) -> HopResult:
    """Simulate one hop with :func:`scipy.integrate.solve_ivp` and event detection.

    This is the slow, accurate reference (all phases, including flight, are integrated
    numerically so the guards are exercised as events).

    Parameters
    ----------
    state : array_like, shape (2,)
        Apex state ``[y0, xdot0]``.
    action : array_like, shape (2,)
        ``[alpha, delta_L]`` (rad, :math:`[l_0]`).
    params : SlipParams, optional
        Model parameters (paper defaults).
    rtol, atol : float
        Integrator tolerances.
    method : str
        ``solve_ivp`` method.
    record_path : bool
        Keep the body path (``HopResult.path``), sampled at most every 0.01 time units.
    """
    p = params if params is not None else SlipParams()
    s, a = _validate_batch(
        np.reshape(np.asarray(state, dtype=float), (1, -1)), np.reshape(np.asarray(action, dtype=float), (1, -1))
    )
    y0, vx0 = float(s[0, 0]), float(s[0, 1])
    alpha, delta_l = float(a[0, 0]), float(a[0, 1])
    nan4 = np.full(4, np.nan)
    info: dict[str, object] = {
        "touchdown": nan4,
        "liftoff": nan4,
        "failure": nan4,
        "t_touchdown": np.nan,
        "t_max_compression": np.nan,
        "t_liftoff": np.nan,
        "t_apex": np.nan,
        "foot_x": np.nan,
        "work_actuator": 0.0,
        "work_damping": 0.0,
        "leg_energy_loss": 0.0,
    }
    energy0 = float(apex_energy(y0, vx0))
    path: list[FloatArray] = [np.array([[0.0, 0.0, y0]])]
    extra = {"max_step": 0.01} if record_path else {}

    def keep(sol: object, x_offset: float = 0.0) -> None:
        if record_path:
            tt, yy = sol.t, sol.y  # type: ignore[attr-defined]
            path.append(np.column_stack([tt, yy[0] + x_offset, yy[1]]))

    def finish(status: Status, next_apex: FloatArray | None = None) -> HopResult:
        nxt = np.full(3, np.nan) if next_apex is None else next_apex
        e1 = float(apex_energy(nxt[1], nxt[2])) if next_apex is not None else np.nan
        trace = np.vstack(path) if record_path else None
        return HopResult(status=status, next_apex=nxt, energy0=energy0, energy1=e1, path=trace, **info)  # type: ignore[arg-type]

    cos_a, sin_a = np.cos(alpha), np.sin(alpha)
    if y0 < cos_a:
        info["failure"] = np.array([0.0, y0, vx0, 0.0])
        return finish(Status.NO_TOUCHDOWN)

    # Flight 1: integrate the ballistic flight to the touchdown guard y = cos(alpha).
    flight = lambda t, z: np.array([z[2], z[3], 0.0, -1.0])  # noqa: E731
    z_ap = np.array([0.0, y0, vx0, 0.0])
    if y0 > cos_a:
        td_event = _event(lambda t, z: z[1] - cos_a, -1.0)
        sol = solve_ivp(
            flight, (0.0, np.sqrt(2.0 * y0) + 1.0), z_ap, method=method, events=td_event, rtol=rtol, atol=atol, **extra
        )
        keep(sol)
        t_td, z_td = float(sol.t_events[0][0]), sol.y_events[0][0].copy()
        z_td[1] = cos_a  # land exactly on the guard
    else:
        t_td, z_td = 0.0, z_ap
    x_f = float(z_td[0] + sin_a)
    info.update(touchdown=z_td.copy(), t_touchdown=t_td, foot_x=x_f)

    xr_td = -sin_a
    ldot_td = xr_td * z_td[2] + cos_a * z_td[3]
    if ldot_td > 0.0:
        info["failure"] = z_td.copy()
        return finish(Status.FALL)
    if abs(sin_a) > p.friction * cos_a:
        info["failure"] = z_td.copy()
        return finish(Status.SLIP)

    # Stance, in segments: compression (L_a = 0) until max compression, the actuator ramp,
    # then constant extension.  Splitting at the profile's kinks keeps the adaptive
    # integrator from stepping across a discontinuous second derivative.
    mu = p.friction
    z = np.array([xr_td, cos_a, z_td[2], z_td[3], 0.0, 0.0])
    t = t_td
    t_end_stance = t_td + p.max_stance_time
    t_mc = np.inf
    segment = 0
    while True:
        mc_known = np.isfinite(t_mc)

        def rhs(tt: float, zz: FloatArray, _t_mc: float = t_mc) -> FloatArray:
            return _stance_rhs(tt, zz, _t_mc, delta_l, p)[0]

        events = [
            _event(lambda tt, zz, _t_mc=t_mc: float(_stance_rhs(tt, zz, _t_mc, delta_l, p)[2]), -1.0),
            _event(lambda tt, zz: mu * zz[1] - abs(zz[0]), -1.0),
            _event(lambda tt, zz: zz[1], -1.0),
        ]
        names = [Status.OK, Status.SLIP, Status.FALL]  # OK here means "liftoff"
        if not mc_known:
            events.append(_event(lambda tt, zz: float(_stance_rhs(tt, zz, np.inf, delta_l, p)[1]), 1.0))
            seg_end = t_end_stance
        elif segment == 1:
            seg_end = min(t_mc + p.extension_time, t_end_stance)
        else:
            seg_end = t_end_stance
        sol = solve_ivp(rhs, (t, seg_end), z, method=method, events=events, rtol=rtol, atol=atol, **extra)
        keep(sol, x_f)
        hit = [(float(te[0]), i) for i, te in enumerate(sol.t_events) if te.size]
        if not hit:
            t, z = float(sol.t[-1]), sol.y[:, -1].copy()
            if t >= t_end_stance:
                info.update(
                    work_actuator=float(z[4]),
                    work_damping=float(z[5]),
                    failure=np.array([z[0] + x_f, z[1], z[2], z[3]]),
                )
                return finish(Status.NO_LIFTOFF)
            segment += 1
            continue
        t_ev, i_ev = min(hit)
        z = sol.y_events[i_ev][0].copy()
        t = t_ev
        info.update(work_actuator=float(z[4]), work_damping=float(z[5]))
        world = np.array([z[0] + x_f, z[1], z[2], z[3]])
        if i_ev == 3:  # maximum compression: start the actuator
            t_mc = t
            info["t_max_compression"] = t
            segment = 1
            continue
        if names[i_ev] is not Status.OK:
            info["failure"] = world
            return finish(names[i_ev])
        # Liftoff: F = 0, residual spring compression is lost in the massless leg.
        la, _ = actuator_profile(t - t_mc, delta_l, p.extension_time)
        delta_lo = 1.0 + float(la) - float(np.hypot(z[0], z[1]))
        info.update(liftoff=world, t_liftoff=t, leg_energy_loss=0.5 * p.stiffness * delta_lo**2)
        break

    z_lo = np.array(info["liftoff"], dtype=float)
    if z_lo[3] <= 0.0:
        info["failure"] = z_lo
        return finish(Status.NO_APEX)
    apex_event = _event(lambda tt, zz: zz[3], -1.0)
    sol = solve_ivp(
        flight, (t, t + z_lo[3] + 1.0), z_lo, method=method, events=apex_event, rtol=rtol, atol=atol, **extra
    )
    keep(sol)
    z_ap1 = sol.y_events[0][0]
    info["t_apex"] = float(sol.t_events[0][0])
    return finish(Status.OK, np.array([z_ap1[0], z_ap1[1], z_ap1[2]]))


# ----------------------------------------------------------------------------------------
# Batched fixed-step simulator
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BatchResult:
    """Outcome of :func:`simulate_batch` for ``n`` hops (same fields as :class:`HopResult`).

    ``status`` holds :class:`Status` codes (``int8``); rows that did not reach a phase are NaN.
    """

    status: NDArray[np.int8]
    next_apex: FloatArray
    touchdown: FloatArray
    liftoff: FloatArray
    failure: FloatArray
    t_touchdown: FloatArray
    t_max_compression: FloatArray
    t_liftoff: FloatArray
    t_apex: FloatArray
    foot_x: FloatArray
    energy0: FloatArray
    energy1: FloatArray
    work_actuator: FloatArray
    work_damping: FloatArray
    leg_energy_loss: FloatArray
    n_steps: int = field(default=0)

    @property
    def valid(self) -> NDArray[np.bool_]:
        """Boolean mask of hops that reached the next apex."""
        return self.status == Status.OK

    def __len__(self) -> int:
        return int(self.status.shape[0])


def _rk4_step(
    t: FloatArray,
    z: FloatArray,
    k1: FloatArray,
    h: FloatArray,
    t_mc: FloatArray,
    dl: FloatArray,
    p: SlipParams,
) -> FloatArray:
    """One classical RK4 step of per-sample size ``h`` (``k1`` = vector field at ``(t, z)``)."""
    half = 0.5 * h
    k2 = _stance_rhs(t + half, z + half * k1, t_mc, dl, p)[0]
    k3 = _stance_rhs(t + half, z + half * k2, t_mc, dl, p)[0]
    k4 = _stance_rhs(t + h, z + h * k3, t_mc, dl, p)[0]
    return z + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


def _hermite(
    z0: FloatArray, z1: FloatArray, f0: FloatArray, f1: FloatArray, h: FloatArray, theta: FloatArray
) -> FloatArray:
    """Cubic Hermite interpolant of a step at fraction ``theta`` (O(h^4) accurate)."""
    t2 = theta * theta
    t3 = t2 * theta
    return (2 * t3 - 3 * t2 + 1) * z0 + (t3 - 2 * t2 + theta) * h * f0 + (-2 * t3 + 3 * t2) * z1 + (t3 - t2) * h * f1


# Event kinds of the batch integrator, in priority order when two land at the same time.
_EV_FALL, _EV_SLIP, _EV_LIFTOFF, _EV_MAXCOMP = 0, 1, 2, 3


def _event_values(
    kind: int, t: FloatArray, z: FloatArray, t_mc: FloatArray, dl: FloatArray, p: SlipParams
) -> FloatArray:
    """Event function oriented so that crossing from ``> 0`` (or ``>= 0``) to the other side fires."""
    if kind == _EV_FALL:
        return z[1]
    if kind == _EV_SLIP:
        return p.friction * z[1] - np.abs(z[0])
    _, ldot, force = _stance_rhs(t, z, t_mc, dl, p)
    if kind == _EV_LIFTOFF:
        return force
    return -ldot


def _locate(
    kind: int,
    t0: FloatArray,
    z0: FloatArray,
    z1: FloatArray,
    f0: FloatArray,
    f1: FloatArray,
    h: FloatArray,
    t_mc: FloatArray,
    dl: FloatArray,
    p: SlipParams,
    iters: int = 48,
) -> FloatArray:
    """Bisection for the crossing time (as a fraction of ``h``) on the Hermite interpolant."""
    lo = np.zeros_like(h)
    hi = np.ones_like(h)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        g = _event_values(kind, t0 + mid * h, _hermite(z0, z1, f0, f1, h, mid), t_mc, dl, p)
        after = g <= 0.0 if kind != _EV_SLIP else g < 0.0
        hi = np.where(after, mid, hi)
        lo = np.where(after, lo, mid)
    return hi


def simulate_batch(
    states: ArrayLike,
    actions: ArrayLike,
    params: SlipParams | None = None,
    *,
    dt: float = 0.01,
) -> BatchResult:
    """Simulate many hops at once (vectorised fixed-step RK4 with per-sample events).

    Flight is integrated in closed form; stance with RK4 of step ``dt`` in
    :math:`[\\sqrt{l_0/g}]`.  Steps are shortened per sample so that none straddles the end
    of the actuator ramp.  When an event function changes sign over a step, its crossing
    time is found by bisection on the step's cubic Hermite interpolant, and the sample is
    re-stepped exactly (RK4) to the earliest crossing.

    Parameters
    ----------
    states : array_like, shape (n, 2)
        Apex states ``[y0, xdot0]``.
    actions : array_like, shape (n, 2)
        ``[alpha, delta_L]``.
    params : SlipParams, optional
        Model parameters.
    dt : float
        Stance step size; 0.01 agrees with the tight-tolerance reference to ~1e-7.
    """
    p = params if params is not None else SlipParams()
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be positive and finite; got {dt!r}")
    s, a = _validate_batch(states, actions)
    n = s.shape[0]
    y0, vx0 = s[:, 0], s[:, 1]
    alpha, dl_all = a[:, 0], a[:, 1]
    cos_a, sin_a = np.cos(alpha), np.sin(alpha)

    def nan(shape: tuple[int, ...]) -> FloatArray:
        return np.full(shape, np.nan)

    status = np.zeros(n, dtype=np.int8)
    touchdown, liftoff, failure = nan((n, 4)), nan((n, 4)), nan((n, 4))
    t_td, t_mc_out, t_lo, t_ap, foot_x = nan(n), nan(n), nan(n), nan(n), nan(n)
    w_act, w_damp, leg_loss = np.zeros(n), np.zeros(n), np.zeros(n)
    next_apex = nan((n, 3))

    # ---- flight 1 (closed form) and touchdown checks
    no_td = y0 < cos_a
    status[no_td] = Status.NO_TOUCHDOWN
    failure[no_td] = np.column_stack([np.zeros(n), y0, vx0, np.zeros(n)])[no_td]
    has_td = ~no_td
    t_fall = np.sqrt(2.0 * np.where(has_td, y0 - cos_a, 0.0))
    t_td[has_td] = t_fall[has_td]
    x_td = vx0 * t_fall
    touchdown[has_td] = np.column_stack([x_td, cos_a, vx0, -t_fall])[has_td]
    foot_x[has_td] = (x_td + sin_a)[has_td]
    ldot_td = -sin_a * vx0 - cos_a * t_fall
    fall_td = has_td & (ldot_td > 0.0)
    slip_td = has_td & ~fall_td & (np.abs(sin_a) > p.friction * cos_a)
    status[fall_td] = Status.FALL
    status[slip_td] = Status.SLIP
    failure[fall_td | slip_td] = touchdown[fall_td | slip_td]

    # ---- stance (fixed-step RK4 over the active subset, compacted as hops finish)
    idx = np.flatnonzero(has_td & ~fall_td & ~slip_td)
    z = np.vstack([-sin_a[idx], cos_a[idx], vx0[idx], -t_fall[idx], np.zeros(idx.size), np.zeros(idx.size)])
    t = t_fall[idx].copy()
    t_stop = t + p.max_stance_time
    t_mc = np.full(idx.size, np.inf)
    dl = dl_all[idx].copy()
    k1, ldot, force = _stance_rhs(t, z, t_mc, dl, p)
    n_steps = 0
    while idx.size:
        n_steps += 1
        ramp_end = t_mc + p.extension_time
        h = np.where((t < ramp_end) & (t + dt > ramp_end), ramp_end - t, dt)
        z_new = _rk4_step(t, z, k1, h, t_mc, dl, p)
        t_new = t + h
        k1_new, ldot_new, force_new = _stance_rhs(t_new, z_new, t_mc, dl, p)

        slip_old = p.friction * z[1] - np.abs(z[0])
        slip_new = p.friction * z_new[1] - np.abs(z_new[0])
        fired = np.stack(
            [
                (z[1] > 0.0) & (z_new[1] <= 0.0),
                (slip_old >= 0.0) & (slip_new < 0.0),
                (force > 0.0) & (force_new <= 0.0),
                np.isinf(t_mc) & (ldot < 0.0) & (ldot_new >= 0.0),
            ]
        )
        any_fired = fired.any(axis=0)
        done_kind = np.full(idx.size, -1)
        if any_fired.any():
            j = np.flatnonzero(any_fired)
            theta = np.full((4, j.size), np.inf)
            for kind in range(4):
                sel = fired[kind, j]
                if sel.any():
                    jj = j[sel]
                    theta[kind, sel] = _locate(
                        kind, t[jj], z[:, jj], z_new[:, jj], k1[:, jj], k1_new[:, jj], h[jj], t_mc[jj], dl[jj], p
                    )
            first = np.argmin(theta, axis=0)  # ties resolve to the lower (higher-priority) kind
            h_ev = theta[first, np.arange(j.size)] * h[j]
            z_ev = _rk4_step(t[j], z[:, j], k1[:, j], h_ev, t_mc[j], dl[j], p)
            t_ev = t[j] + h_ev
            z_new[:, j] = z_ev
            t_new[j] = t_ev
            mc = first == _EV_MAXCOMP
            t_mc[j[mc]] = t_ev[mc]
            k1_ev, ldot_ev, force_ev = _stance_rhs(t_ev, z_ev, t_mc[j], dl[j], p)
            k1_new[:, j], ldot_new[j], force_new[j] = k1_ev, ldot_ev, force_ev
            done_kind[j[~mc]] = first[~mc]

        timeout = (done_kind < 0) & (t_new >= t_stop)
        finished = (done_kind >= 0) | timeout
        if finished.any():
            f = np.flatnonzero(finished)
            g = idx[f]
            zf = z_new[:, f]
            world = np.vstack([zf[0] + foot_x[g], zf[1], zf[2], zf[3]]).T
            w_act[g], w_damp[g] = zf[4], zf[5]
            kinds = done_kind[f]
            codes = np.select(
                [kinds == _EV_FALL, kinds == _EV_SLIP, kinds == _EV_LIFTOFF],
                [Status.FALL, Status.SLIP, Status.OK],
                default=Status.NO_LIFTOFF,
            )
            status[g] = codes
            lo = kinds == _EV_LIFTOFF
            failure[g[~lo]] = world[~lo]
            liftoff[g[lo]] = world[lo]
            t_lo[g[lo]] = t_new[f][lo]
            la, _ = actuator_profile(t_new[f] - t_mc[f], dl[f], p.extension_time)
            delta_lo = 1.0 + la - np.hypot(zf[0], zf[1])
            leg_loss[g[lo]] = 0.5 * p.stiffness * delta_lo[lo] ** 2
            t_mc_out[g] = np.where(np.isfinite(t_mc[f]), t_mc[f], np.nan)
            keep = ~finished
            idx, z_new, t_new, t_stop = idx[keep], z_new[:, keep], t_new[keep], t_stop[keep]
            t_mc, dl = t_mc[keep], dl[keep]
            k1_new, ldot_new, force_new = k1_new[:, keep], ldot_new[keep], force_new[keep]
        z, t, k1, ldot, force = z_new, t_new, k1_new, ldot_new, force_new

    # ---- flight 2 (closed form) to the next apex
    lifted = (status == Status.OK) & np.isfinite(t_lo)
    no_apex = lifted & (liftoff[:, 3] <= 0.0)
    status[no_apex] = Status.NO_APEX
    failure[no_apex] = liftoff[no_apex]
    ok = lifted & ~no_apex
    vy_lo = liftoff[ok, 3]
    next_apex[ok] = np.column_stack(
        [liftoff[ok, 0] + liftoff[ok, 2] * vy_lo, liftoff[ok, 1] + 0.5 * vy_lo**2, liftoff[ok, 2]]
    )
    t_ap[ok] = t_lo[ok] + vy_lo
    energy1 = np.where(ok, apex_energy(next_apex[:, 1], next_apex[:, 2]), np.nan)
    return BatchResult(
        status=status,
        next_apex=next_apex,
        touchdown=touchdown,
        liftoff=liftoff,
        failure=failure,
        t_touchdown=t_td,
        t_max_compression=t_mc_out,
        t_liftoff=t_lo,
        t_apex=t_ap,
        foot_x=foot_x,
        energy0=apex_energy(y0, vx0),
        energy1=energy1,
        work_actuator=w_act,
        work_damping=w_damp,
        leg_energy_loss=leg_loss,
        n_steps=n_steps,
    )


def return_map(
    states: ArrayLike, actions: ArrayLike, params: SlipParams | None = None, *, dt: float = 0.01
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Controlled first return map :math:`\\Phi` on the apex section (eq. 14).

    Returns ``(next, valid)`` with ``next[i] = [dx, y1, xdot1]`` (NaN where invalid) and the
    boolean validity mask.
    """
    res = simulate_batch(states, actions, params, dt=dt)
    return res.next_apex, res.valid
