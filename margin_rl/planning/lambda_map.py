"""lambda (seed 000 eq. 4) of a planned base state, as a CasADi function with exact derivatives.

Inputs of one node (world frame W: z up; units m, rad, s):

* c, v, a: CoM position, velocity and acceleration (the base trajectory's cubic polynomials);
* (phi, theta, psi): roll, pitch, yaw of the base, R_WB = Rz(psi) Ry(theta) Rx(phi) (Z-Y-X, as
  :mod:`margin_rl.stability.analytic.lambda_state`), with their first and second time derivatives;
* the four foot-sphere centres f_i and terrain normals n_i in W, the contact flags, mu.

lambda, with H the horizontal frame (origin at the CoM, yaw psi; R_WH = Rz(psi)):

* e_g = 3rd row of R_WB = (-sin theta, cos theta sin phi, cos theta cos phi);
* c_dot_H = Rz^T v,  c_ddot_H = Rz^T a;
* base angular acceleration in H. With omega_W = Rz omega_H and
  omega_H = (cos theta phi_dot, theta_dot, psi_dot - sin theta phi_dot) (Euler-rate map in H),
  Rz^T omega_dot_W = d(omega_H)/dt + psi_dot e_z x omega_H, i.e.
  ( -sin theta theta_dot phi_dot + cos theta phi_ddot - psi_dot theta_dot,
    theta_ddot + psi_dot cos theta phi_dot,
    psi_ddot - cos theta theta_dot phi_dot - sin theta phi_ddot );
* p_i = Rz^T (f_i - c) (feet relative to the CoM, eq. 10's dp_i/dc = -1 before the rotation);
* n_i,H = Rz^T n_i; no external wrench.

Second output: the range-of-motion residual of each foot in the base frame,
R_WB^T (f_i - c) + c_B - f_i,nominal (4 x 3) [m], which the planner bounds by the box half-extents.
"""

from __future__ import annotations

import numpy as np

from margin_rl.stability import LAMBDA_DIM


def rotation_zyx(rpy):  # casadi SX (3,) -> SX (3, 3)
    """R_WB = Rz(psi) Ry(theta) Rx(phi) of roll-pitch-yaw (phi, theta, psi) [rad]."""
    import casadi as ca

    phi, theta, psi = rpy[0], rpy[1], rpy[2]
    cph, sph, cth, sth, cps, sps = ca.cos(phi), ca.sin(phi), ca.cos(theta), ca.sin(theta), ca.cos(psi), ca.sin(psi)
    Rz = ca.vertcat(ca.horzcat(cps, -sps, 0), ca.horzcat(sps, cps, 0), ca.horzcat(0, 0, 1))
    Ry = ca.vertcat(ca.horzcat(cth, 0, sth), ca.horzcat(0, 1, 0), ca.horzcat(-sth, 0, cth))
    Rx = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, cph, -sph), ca.horzcat(0, sph, cph))
    return ca.mtimes([Rz, Ry, Rx])


def node_function(com_offset_base: np.ndarray, nominal_feet_base: np.ndarray):  # -> casadi.Function
    """The SX function ``(c, rpy, v, rpy_rate, a, rpy_acc, feet, normals, contacts, mu) -> (lam, rom)``.

    ``feet`` and ``normals`` are (12,) stacks LF, RF, LH, RH of world vectors; ``lam`` is (47,) in
    :data:`margin_rl.stability.LAMBDA_FIELDS` order; ``rom`` is (12,) (see the module docstring).
    """
    import casadi as ca

    c, rpy, v, rate, a, acc = (ca.SX.sym(n, 3) for n in ("c", "rpy", "v", "rpy_rate", "a", "rpy_acc"))
    feet, normals = ca.SX.sym("feet", 12), ca.SX.sym("normals", 12)
    contacts, mu = ca.SX.sym("contacts", 4), ca.SX.sym("mu", 1)
    phi, theta, psi = rpy[0], rpy[1], rpy[2]
    dphi, dtheta, dpsi = rate[0], rate[1], rate[2]
    cth, sth, cps, sps = ca.cos(theta), ca.sin(theta), ca.cos(psi), ca.sin(psi)
    RzT = ca.vertcat(ca.horzcat(cps, sps, 0), ca.horzcat(-sps, cps, 0), ca.horzcat(0, 0, 1))
    gravity_axis = ca.vertcat(-sth, cth * ca.sin(phi), cth * ca.cos(phi))
    ang_acc = ca.vertcat(
        -sth * dtheta * dphi + cth * acc[0] - dpsi * dtheta,
        acc[1] + dpsi * cth * dphi,
        acc[2] - cth * dtheta * dphi - sth * acc[0],
    )
    R = rotation_zyx(rpy)
    feet_h, normals_h, rom = [], [], []
    for i in range(4):
        rel = feet[3 * i : 3 * i + 3] - c
        feet_h.append(ca.mtimes(RzT, rel))
        normals_h.append(ca.mtimes(RzT, normals[3 * i : 3 * i + 3]))
        rom.append(ca.mtimes(R.T, rel) + ca.DM(com_offset_base) - ca.DM(nominal_feet_base[i]))
    lam = ca.vertcat(
        gravity_axis,
        ca.mtimes(RzT, v),
        ca.mtimes(RzT, a),
        ang_acc,
        ca.DM.zeros(6),
        *feet_h,
        mu,
        contacts,
        *normals_h,
    )
    assert lam.shape[0] == LAMBDA_DIM
    return ca.Function(
        "node_lambda",
        [c, rpy, v, rate, a, acc, feet, normals, contacts, mu],
        [lam, ca.vertcat(*rom)],
        ["c", "rpy", "v", "rpy_rate", "a", "rpy_acc", "feet", "normals", "contacts", "mu"],
        ["lam", "rom"],
    )


def hermite(p0, v0, p1, v1, dt: float, tau: float):
    """Cubic Hermite segment on [0, dt] through (p0, v0) and (p1, v1): value, rate and second
    derivative at tau in [0, dt]. Works for numpy arrays and CasADi expressions alike (linear in the
    node values: the coefficients are numbers once dt and tau are)."""
    s = tau / dt
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    e00, e10, e01, e11 = 12 * s - 6, 6 * s - 4, -12 * s + 6, 6 * s - 2
    value = h00 * p0 + h10 * dt * v0 + h01 * p1 + h11 * dt * v1
    rate = (d00 * p0 + d10 * dt * v0 + d01 * p1 + d11 * dt * v1) / dt
    second = (e00 * p0 + e10 * dt * v0 + e01 * p1 + e11 * dt * v1) / dt**2
    return value, rate, second
