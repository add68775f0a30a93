"""The analytic stability margin as a CasADi function with finite-difference derivatives (benchmark only).

What the learned margin replaces in the trajectory optimisation: ``analytic_margin(robot, lam)`` (an
iterative projection of linear programs, seed 000 Alg. 1) has no derivatives, so its gradient with
respect to lambda is taken by forward differences, one analytic call per varying entry of lambda
(gravity axis, CoM velocity and acceleration, angular acceleration, feet and normals: 36 entries; mu,
contact flags and the external wrench are constants in the planner), with step ``step`` (4e-4 on the
gravity axis, which the analytic margin accepts only within 1e-3 of unit length). States without a margin
(unreachable feet, empty region) read ``UNAVAILABLE`` (-0.5 m, strongly violating) so that IPOPT backs
off from them; their derivative entries are set to zero.
"""

from __future__ import annotations

import numpy as np

from margin_rl.robot import Robot
from margin_rl.stability import LAMBDA_DIM, LAMBDA_SLICES, analytic_margin

UNAVAILABLE = -0.5  # [m] value reported for a state without an analytic margin

_CONSTANT_FIELDS = ("ext_force", "ext_torque", "mu", "contacts")


def varying_entries() -> np.ndarray:
    """Indices of the lambda entries that depend on the planner's decision variables."""
    constant = set()
    for name in _CONSTANT_FIELDS:
        constant.update(range(LAMBDA_SLICES[name].start, LAMBDA_SLICES[name].stop))
    return np.array([i for i in range(LAMBDA_DIM) if i not in constant])


def _value(robot: Robot, lam: np.ndarray) -> float:
    result = analytic_margin(robot, lam)
    return result.margin if result.status == "ok" else UNAVAILABLE


def analytic_margin_function(robot: Robot, step: float):  # -> casadi.Function (47, 1) -> (1, 1)
    """``m_a(lam)`` as a CasADi callback whose Jacobian is forward differences with ``step``."""
    import casadi as ca

    entries = varying_entries()
    # The analytic margin accepts gravity axes within 1e-3 of unit length (and normalises them).
    steps = np.full(LAMBDA_DIM, float(step))
    gravity = LAMBDA_SLICES["gravity_axis"]
    steps[gravity] = min(float(step), 4e-4)

    class _Jacobian(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.construct("analytic_margin_jacobian", {})

        def get_n_in(self) -> int:
            return 2

        def get_n_out(self) -> int:
            return 1

        def get_sparsity_in(self, i: int):
            return ca.Sparsity.dense(LAMBDA_DIM, 1) if i == 0 else ca.Sparsity.dense(1, 1)

        def get_sparsity_out(self, i: int):
            return ca.Sparsity.dense(1, LAMBDA_DIM)

        def eval(self, args):
            lam = np.array(args[0]).ravel()
            base = float(np.array(args[1]).ravel()[0])
            grad = np.zeros(LAMBDA_DIM)
            if base == UNAVAILABLE:
                return [ca.DM(grad).T]
            for i in entries:
                shifted = lam.copy()
                shifted[i] += steps[i]
                value = _value(robot, shifted)
                grad[i] = 0.0 if value == UNAVAILABLE else (value - base) / steps[i]
            return [ca.DM(grad).T]

    class _Margin(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.construct("analytic_margin", {"enable_fd": False})

        def get_n_in(self) -> int:
            return 1

        def get_n_out(self) -> int:
            return 1

        def get_sparsity_in(self, i: int):
            return ca.Sparsity.dense(LAMBDA_DIM, 1)

        def get_sparsity_out(self, i: int):
            return ca.Sparsity.dense(1, 1)

        def eval(self, args):
            return [ca.DM(_value(robot, np.array(args[0]).ravel()))]

        def has_jacobian(self) -> bool:
            return True

        def get_jacobian(self, name, inames, onames, opts):
            self._jac = _Jacobian()  # keep a reference: CasADi does not own Python callbacks
            lam = ca.MX.sym("lam", LAMBDA_DIM)
            out = ca.MX.sym("out", 1)
            return ca.Function(name, [lam, out], [self._jac(lam, out)], inames, onames)

    return _Margin()
