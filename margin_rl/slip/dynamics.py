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
    :math:`E = \tfrac12 \dot x^2 + y`.  Both stance integrators integrate :math:`W_{act}` and
    :math:`W_{damp}` alongside the state so this identity can be checked.

One hop integrator: :func:`simulate_batch` runs the flights in closed form, the touchdown checks, the
stance (:mod:`margin_rl.slip.stance`) and the liftoff and apex bookkeeping for many hops at once, and
:func:`simulate_hop` is that batch for one hop.  The stance is integrated by ``method``: ``"rk4"``
(vectorised fixed-step RK4 with per-hop event location, step ``dt``; the batch default, for data
generation) or a :func:`scipy.integrate.solve_ivp` method such as ``"DOP853"`` (adaptive, per hop, with
event detection; the single-hop default and the tight-tolerance reference).  The model's pieces
(:class:`Status`, :class:`SlipParams`, :func:`actuator_profile`, :func:`apex_energy`) live in
:mod:`margin_rl.slip.aslip` and are re-exported here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.slip.aslip import SlipParams as SlipParams
from margin_rl.slip.aslip import Status as Status
from margin_rl.slip.aslip import actuator_profile as actuator_profile
from margin_rl.slip.aslip import apex_energy as apex_energy
from margin_rl.slip.stance import FALL, LIFTOFF, SLIP, StanceEnd, integrate_adaptive, integrate_rk4

__all__ = [
    "ADAPTIVE_METHODS",
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
_Integrator = Callable[[FloatArray, FloatArray, FloatArray, SlipParams], StanceEnd]
_HOP_SCALARS = (
    "t_touchdown",
    "t_max_compression",
    "t_liftoff",
    "t_apex",
    "foot_x",
    "energy0",
    "energy1",
    "work_actuator",
    "work_damping",
    "leg_energy_loss",
)
_PATH_STEP = 0.01  # the longest time between two recorded path points
ADAPTIVE_METHODS = ("DOP853", "RK45", "RK23", "Radau", "BDF", "LSODA")
"""The :func:`scipy.integrate.solve_ivp` methods a stance can be integrated with (besides ``"rk4"``)."""


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


@dataclass(frozen=True)
class BatchResult:
    """Outcome of :func:`simulate_batch` for ``n`` hops (same fields as :class:`HopResult`).

    ``status`` holds :class:`Status` codes (``int8``); rows that did not reach a phase are NaN.
    ``n_steps``: RK4 steps of the batch, or (adaptive ``method``) accepted solver steps summed over hops.
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

    @classmethod
    def from_batch(cls, result: BatchResult, i: int = 0, path: FloatArray | None = None) -> HopResult:
        """Row ``i`` of a :class:`BatchResult`."""
        arrays = {k: getattr(result, k)[i].copy() for k in ("next_apex", "touchdown", "liftoff", "failure")}
        scalars = {k: float(getattr(result, k)[i]) for k in _HOP_SCALARS}
        return cls(status=Status(int(result.status[i])), **arrays, **scalars, path=path)


def _stance_integrator(method: str, dt: float, rtol: float, atol: float, record_path: bool) -> _Integrator:
    """``integrate(z, t, dl, p) -> StanceEnd`` for ``method`` (module docstring)."""
    if method == "rk4":
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be positive and finite; got {dt!r}")
        return lambda z, t, dl, p: integrate_rk4(z, t, dl, p, dt, record_path)
    if method not in ADAPTIVE_METHODS:
        raise ValueError(f"unknown method {method!r}; known: rk4, {', '.join(ADAPTIVE_METHODS)}")
    return lambda z, t, dl, p: integrate_adaptive(
        z, t, dl, p, method=method, rtol=rtol, atol=atol, record_path=record_path
    )


def _flight_path(t0: float, t1: float, x0: float, y0: float, vx: float, vy: float) -> FloatArray:
    """Rows ``[t, x, y]`` of a ballistic flight from ``t0`` to ``t1``, at most ``_PATH_STEP`` apart."""
    tt = np.append(np.arange(t0, t1, _PATH_STEP), t1)
    tau = tt - t0
    return np.column_stack([tt, x0 + vx * tau, y0 + vy * tau - 0.5 * tau * tau])


def _simulate(
    states: ArrayLike, actions: ArrayLike, p: SlipParams, integrate: _Integrator, record_path: bool = False
) -> tuple[BatchResult, list[FloatArray] | None]:
    """The hops of ``states`` (n, 2) under ``actions`` (n, 2): flights in closed form, touchdown checks, the
    stance by ``integrate`` (:func:`_stance_integrator`), liftoff and apex; and the paths when recorded."""
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

    # ---- stance, from the touchdown state [x - x_f, y, xdot, ydot, W_act = 0, W_damp = 0]
    g = np.flatnonzero(has_td & ~fall_td & ~slip_td)
    z0 = np.vstack([-sin_a[g], cos_a[g], vx0[g], -t_fall[g], np.zeros(g.size), np.zeros(g.size)])
    dl = dl_all[g].copy()
    end = integrate(z0, t_fall[g].copy(), dl, p)
    zf, kinds = end.z, end.kind
    world = np.vstack([zf[0] + foot_x[g], zf[1], zf[2], zf[3]]).T
    w_act[g], w_damp[g] = zf[4], zf[5]
    status[g] = np.select(
        [kinds == FALL, kinds == SLIP, kinds == LIFTOFF], [Status.FALL, Status.SLIP, Status.OK], Status.NO_LIFTOFF
    )
    lo = kinds == LIFTOFF
    failure[g[~lo]] = world[~lo]
    liftoff[g[lo]] = world[lo]
    t_lo[g[lo]] = end.t[lo]
    # Liftoff: F = 0 with the spring still compressed; that energy is lost in the massless leg.
    la, _ = actuator_profile(end.t - end.t_mc, dl, p.extension_time)
    delta_lo = 1.0 + la - np.hypot(zf[0], zf[1])
    leg_loss[g[lo]] = 0.5 * p.stiffness * delta_lo[lo] ** 2
    t_mc_out[g] = np.where(np.isfinite(end.t_mc), end.t_mc, np.nan)

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
    result = BatchResult(
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
        n_steps=end.n_steps,
    )
    if not record_path:
        return result, None
    paths = []
    stance_paths = dict(zip(g.tolist(), end.paths or [], strict=True))
    for i in range(n):
        pieces = [np.array([[0.0, 0.0, y0[i]]])]
        if has_td[i]:
            pieces.append(_flight_path(0.0, t_fall[i], 0.0, y0[i], vx0[i], 0.0))
        if i in stance_paths:
            pieces.append(stance_paths[i] + [0.0, foot_x[i], 0.0])
        if ok[i]:
            x_lo, y_lo, vx_lo, vy = liftoff[i]
            pieces.append(_flight_path(t_lo[i], t_ap[i], x_lo, y_lo, vx_lo, vy))
        paths.append(np.vstack(pieces))
    return result, paths


def simulate_batch(
    states: ArrayLike,
    actions: ArrayLike,
    params: SlipParams | None = None,
    *,
    dt: float = 0.01,
    method: str = "rk4",
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> BatchResult:
    """Simulate many hops at once (module docstring): flights in closed form, stance by ``method``.

    Parameters
    ----------
    states : array_like, shape (n, 2)
        Apex states ``[y0, xdot0]``.
    actions : array_like, shape (n, 2)
        ``[alpha, delta_L]``.
    params : SlipParams, optional
        Model parameters.
    dt : float
        Stance step size of ``method="rk4"`` in :math:`[\\sqrt{l_0/g}]`; 0.01 agrees with the
        tight-tolerance reference to ~1e-7.
    method : str
        ``"rk4"`` (vectorised fixed step, :func:`~margin_rl.slip.stance.integrate_rk4`) or a
        :func:`scipy.integrate.solve_ivp` method (adaptive, per hop,
        :func:`~margin_rl.slip.stance.integrate_adaptive`).
    rtol, atol : float
        Tolerances of an adaptive ``method``.
    """
    p = params if params is not None else SlipParams()
    return _simulate(states, actions, p, _stance_integrator(method, dt, rtol, atol, False))[0]


def simulate_hop(
    state: ArrayLike,
    action: ArrayLike,
    params: SlipParams | None = None,
    *,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    method: str = "DOP853",
    dt: float = 0.01,
    record_path: bool = False,
) -> HopResult:
    """One hop: :func:`simulate_batch` of one, by default with the adaptive reference stance integrator.

    Parameters
    ----------
    state : array_like, shape (2,)
        Apex state ``[y0, xdot0]``.
    action : array_like, shape (2,)
        ``[alpha, delta_L]`` (rad, :math:`[l_0]`).
    params : SlipParams, optional
        Model parameters (paper defaults).
    rtol, atol, method, dt
        As in :func:`simulate_batch` (``method="rk4"`` gives exactly the batch's numbers).
    record_path : bool
        Keep the body path (``HopResult.path``), sampled at most every 0.01 time units (an adaptive
        ``method`` then limits its step to 0.01).
    """
    p = params if params is not None else SlipParams()
    states = np.reshape(np.asarray(state, dtype=float), (1, -1))
    actions = np.reshape(np.asarray(action, dtype=float), (1, -1))
    result, paths = _simulate(states, actions, p, _stance_integrator(method, dt, rtol, atol, record_path), record_path)
    return HopResult.from_batch(result, 0, paths[0] if paths else None)


def return_map(
    states: ArrayLike, actions: ArrayLike, params: SlipParams | None = None, *, dt: float = 0.01
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Controlled first return map :math:`\\Phi` on the apex section (eq. 14).

    Returns ``(next, valid)`` with ``next[i] = [dx, y1, xdot1]`` (NaN where invalid) and the
    boolean validity mask.
    """
    res = simulate_batch(states, actions, params, dt=dt)
    return res.next_apex, res.valid
