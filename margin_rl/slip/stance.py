r"""Stance-phase integrators of the aSLIP hop (:mod:`margin_rl.slip.dynamics` does the rest of the hop).

Both take hops at touchdown, the states ``z = [x - x_f, y, xdot, ydot, W_act, W_damp]`` (6, n) at times
``t`` (n,), and integrate :func:`~margin_rl.slip.aslip.stance_rhs` until each hop's first stance event
(fall :math:`y = 0`, slip :math:`|x - x_f| = \mu y`, liftoff :math:`F = 0`) or ``max_stance_time``; maximum
compression (:math:`\dot l = 0` from below) starts the actuator and integration goes on. They return a
:class:`StanceEnd`:

* :func:`integrate_rk4`: vectorised fixed-step RK4 over all hops at once.  Steps are shortened per hop so
  that none straddles the end of the actuator ramp; when an event function changes sign over a step, its
  crossing is found by bisection on the step's cubic Hermite interpolant and the hop is re-stepped exactly
  (RK4) to the earliest crossing.  Fast (data generation); step 0.01 agrees with the reference to ~1e-7.
* :func:`integrate_adaptive`: :func:`scipy.integrate.solve_ivp` per hop with event detection, in segments
  split at the actuator profile's kinks (so the adaptive steps never cross a jump of the second
  derivative).  Slow and accurate: the reference.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from margin_rl.slip.aslip import SlipParams, stance_rhs

__all__ = ["FALL", "LIFTOFF", "MAX_COMPRESSION", "SLIP", "TIMEOUT", "StanceEnd", "integrate_adaptive", "integrate_rk4"]

FloatArray = NDArray[np.float64]

# Event kinds, in priority order when two land at the same time (RK4); TIMEOUT: none before max_stance_time.
FALL, SLIP, LIFTOFF, MAX_COMPRESSION = 0, 1, 2, 3
TIMEOUT = -1


@dataclass(frozen=True)
class StanceEnd:
    """How each hop's stance ended.

    ``kind`` (n,): FALL, SLIP, LIFTOFF or TIMEOUT; ``z`` (6, n) and ``t`` (n,): the state and time there;
    ``t_mc`` (n,): maximum compression (inf where not reached); ``n_steps``: RK4 steps of the batch, or
    accepted solver steps summed over hops; ``paths``: per hop, rows ``[t, x - x_f, y]`` of the stance
    (when recorded).
    """

    kind: NDArray[np.int64]
    z: FloatArray
    t: FloatArray
    t_mc: FloatArray
    n_steps: int
    paths: list[FloatArray] | None = None


# ---------------------------------------------------------------------------- fixed-step RK4, vectorised


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
    k2 = stance_rhs(t + half, z + half * k1, t_mc, dl, p)[0]
    k3 = stance_rhs(t + half, z + half * k2, t_mc, dl, p)[0]
    k4 = stance_rhs(t + h, z + h * k3, t_mc, dl, p)[0]
    return z + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


def _hermite(
    z0: FloatArray, z1: FloatArray, f0: FloatArray, f1: FloatArray, h: FloatArray, theta: FloatArray
) -> FloatArray:
    """Cubic Hermite interpolant of a step at fraction ``theta`` (O(h^4) accurate)."""
    t2 = theta * theta
    t3 = t2 * theta
    return (2 * t3 - 3 * t2 + 1) * z0 + (t3 - 2 * t2 + theta) * h * f0 + (-2 * t3 + 3 * t2) * z1 + (t3 - t2) * h * f1


def _event_values(
    kind: int, t: FloatArray, z: FloatArray, t_mc: FloatArray, dl: FloatArray, p: SlipParams
) -> FloatArray:
    """Event function oriented so that crossing from ``> 0`` (or ``>= 0``) to the other side fires."""
    if kind == FALL:
        return z[1]
    if kind == SLIP:
        return p.friction * z[1] - np.abs(z[0])
    _, ldot, force = stance_rhs(t, z, t_mc, dl, p)
    if kind == LIFTOFF:
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
        after = g <= 0.0 if kind != SLIP else g < 0.0
        hi = np.where(after, mid, hi)
        lo = np.where(after, lo, mid)
    return hi


def integrate_rk4(
    z: FloatArray, t: FloatArray, dl: FloatArray, p: SlipParams, dt: float, record_path: bool = False
) -> StanceEnd:
    """Fixed-step RK4 of step ``dt`` over the hops ``z`` (6, n) from ``t`` (n,) with actuator extensions
    ``dl`` (n,), compacting the active set as hops finish (module docstring)."""
    n = z.shape[1]
    kind_end, z_end, t_end, t_mc_end = np.full(n, TIMEOUT), np.empty((6, n)), np.empty(n), np.full(n, np.inf)
    trace = [(np.arange(n), t.copy(), z[0].copy(), z[1].copy())] if record_path else []
    idx = np.arange(n)
    t_stop = t + p.max_stance_time
    t_mc = np.full(n, np.inf)
    k1, ldot, force = stance_rhs(t, z, t_mc, dl, p)
    n_steps = 0
    while idx.size:
        n_steps += 1
        ramp_end = t_mc + p.extension_time
        h = np.where((t < ramp_end) & (t + dt > ramp_end), ramp_end - t, dt)
        z_new = _rk4_step(t, z, k1, h, t_mc, dl, p)
        t_new = t + h
        k1_new, ldot_new, force_new = stance_rhs(t_new, z_new, t_mc, dl, p)

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
        done_kind = np.full(idx.size, TIMEOUT)
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
            mc = first == MAX_COMPRESSION
            t_mc[j[mc]] = t_ev[mc]
            k1_ev, ldot_ev, force_ev = stance_rhs(t_ev, z_ev, t_mc[j], dl[j], p)
            k1_new[:, j], ldot_new[j], force_new[j] = k1_ev, ldot_ev, force_ev
            done_kind[j[~mc]] = first[~mc]
        if record_path:
            trace.append((idx, t_new.copy(), z_new[0].copy(), z_new[1].copy()))

        finished = (done_kind != TIMEOUT) | (t_new >= t_stop)
        if finished.any():
            f = np.flatnonzero(finished)
            g = idx[f]
            kind_end[g], z_end[:, g], t_end[g], t_mc_end[g] = done_kind[f], z_new[:, f], t_new[f], t_mc[f]
            keep = ~finished
            idx, z_new, t_new, t_stop = idx[keep], z_new[:, keep], t_new[keep], t_stop[keep]
            t_mc, dl = t_mc[keep], dl[keep]
            k1_new, ldot_new, force_new = k1_new[:, keep], ldot_new[keep], force_new[keep]
        z, t, k1, ldot, force = z_new, t_new, k1_new, ldot_new, force_new
    paths = None
    if record_path:
        rows = np.concatenate([r[0] for r in trace])
        columns = [np.concatenate([r[k] for r in trace]) for k in (1, 2, 3)]
        paths = [np.column_stack([c[rows == i] for c in columns]) for i in range(n)]
    return StanceEnd(kind_end, z_end, t_end, t_mc_end, n_steps, paths)


# ---------------------------------------------------------------------------- adaptive reference, per hop

_EventFn = Callable[[float, FloatArray], float]


def _event(fun: _EventFn, direction: float) -> _EventFn:
    """Mark a scalar function as a terminal solve_ivp event with the given direction."""

    def wrapped(t: float, z: FloatArray) -> float:
        return fun(t, z)

    wrapped.terminal = True  # type: ignore[attr-defined]
    wrapped.direction = direction  # type: ignore[attr-defined]
    return wrapped


def _adaptive_one(
    z: FloatArray, t: float, delta_l: float, p: SlipParams, options: dict[str, object], record_path: bool
) -> tuple[int, FloatArray, float, float, int, FloatArray | None]:
    """One hop's stance: (kind, z, t, t_mc, solver steps, path rows [t, x - x_f, y] or None)."""
    t_stop = t + p.max_stance_time
    t_mc = np.inf
    segment = 0  # compression (L_a = 0) until max compression, the actuator ramp, then constant extension
    steps, pieces = 0, []
    while True:
        mc_known = np.isfinite(t_mc)

        def rhs(tt: float, zz: FloatArray, _t_mc: float = t_mc) -> FloatArray:
            return stance_rhs(tt, zz, _t_mc, delta_l, p)[0]

        events = [
            _event(lambda tt, zz, _t_mc=t_mc: float(stance_rhs(tt, zz, _t_mc, delta_l, p)[2]), -1.0),
            _event(lambda tt, zz: p.friction * zz[1] - abs(zz[0]), -1.0),
            _event(lambda tt, zz: zz[1], -1.0),
        ]
        kinds = [LIFTOFF, SLIP, FALL]
        if not mc_known:
            events.append(_event(lambda tt, zz: float(stance_rhs(tt, zz, np.inf, delta_l, p)[1]), 1.0))
            kinds.append(MAX_COMPRESSION)
            seg_end = t_stop
        elif segment == 1:
            seg_end = min(t_mc + p.extension_time, t_stop)
        else:
            seg_end = t_stop
        sol = solve_ivp(rhs, (t, seg_end), z, events=events, **options)  # type: ignore[arg-type]
        steps += sol.t.size - 1
        if record_path:
            pieces.append(np.column_stack([sol.t, sol.y[0], sol.y[1]]))
        path = np.vstack(pieces) if record_path else None
        hit = [(float(te[0]), i) for i, te in enumerate(sol.t_events) if te.size]
        if not hit:
            t, z = float(sol.t[-1]), sol.y[:, -1].copy()
            if t >= t_stop:
                return TIMEOUT, z, t, t_mc, steps, path
            segment += 1
            continue
        t, i = min(hit)  # the earliest event; ties go to the first listed
        z = sol.y_events[i][0].copy()
        if kinds[i] != MAX_COMPRESSION:
            return kinds[i], z, t, t_mc, steps, path
        t_mc = t  # start the actuator
        segment = 1


def integrate_adaptive(
    z: FloatArray,
    t: FloatArray,
    dl: FloatArray,
    p: SlipParams,
    *,
    method: str = "DOP853",
    rtol: float = 1e-10,
    atol: float = 1e-12,
    record_path: bool = False,
) -> StanceEnd:
    """:func:`scipy.integrate.solve_ivp` (``method``, ``rtol``, ``atol``) per hop, with events (module
    docstring); ``record_path`` also limits the step to 0.01 so that the path is finely sampled."""
    n = z.shape[1]
    kind_end, z_end, t_end, t_mc_end = np.full(n, TIMEOUT), np.empty((6, n)), np.empty(n), np.full(n, np.inf)
    options: dict[str, object] = {"method": method, "rtol": rtol, "atol": atol}
    if record_path:
        options["max_step"] = 0.01
    paths, n_steps = [], 0
    for j in range(n):
        kind, z_end[:, j], t_end[j], t_mc_end[j], steps, path = _adaptive_one(
            z[:, j].copy(), float(t[j]), float(dl[j]), p, options, record_path
        )
        kind_end[j] = kind
        n_steps += steps
        paths.append(path)
    return StanceEnd(kind_end, z_end, t_end, t_mc_end, n_steps, paths if record_path else None)
