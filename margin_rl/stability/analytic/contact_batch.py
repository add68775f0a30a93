"""Steps 1-4 of the analytic margin for many states at once: lambda -> IK -> Jacobians, bias, contacts, ICP.

The batched counterpart of :func:`margin_rl.stability.analytic.margin.contact_problem` for labelling data sets:
the base rotations, the IK with its CoM fixed point, the contact points, CoM heights, capture points and
the gravito-inertial wrenches are numpy operations over the whole batch (one state's IK is dominated
by numpy's per-call overhead, so a batch costs about as much as one state); only the Jacobians, bias
torques and angular-momentum rates stay one Pinocchio call per state, and only for the states that have
a region to solve. The maths are those of ``contact_problem`` (see the
:mod:`~margin_rl.stability.analytic.margin` docstring); the results agree to rounding (each state's CoM fixed
point stops where it would alone).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from margin_rl.robot import Robot
from margin_rl.stability.analytic.lambda_state import (
    LAMBDA_DIM,
    base_rotation_from_gravity_axis,
    check_lambda,
    from_lambda,
)

__all__ = ["ContactBatch", "contact_batch"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class ContactBatch:
    """The contact problems of N states, frame H of each state (origin at its CoM, z up).

    ``no_contact``, ``unreachable`` and ``below_feet`` (the CoM not above its stance feet: infeasible)
    mark the states without a region to solve, in that order of precedence; ``solvable`` is the rest.
    Arrays of states that are not solvable may hold NaN (Jacobians and bias torques are only computed
    for solvable states).
    """

    no_contact: BoolArray  # (N,)
    unreachable: BoolArray  # (N,)
    below_feet: BoolArray  # (N,)
    contact_points: FloatArray  # (N, 4, 3) foot-sphere contact points relative to the CoM [m]
    normals: FloatArray  # (N, 4, 3) unit terrain normals
    stance: BoolArray  # (N, 4)
    mu: FloatArray  # (N,)
    jacobians: FloatArray  # (N, 4, 3, 3) foot Jacobians w.r.t. each leg's joints, in H
    torque_limits: FloatArray  # (4, 3) symmetric limits [N m] (the robot's)
    leg_bias: FloatArray  # (N, 4, 3) delta_i [N m]
    wrench: FloatArray  # (N, 6) gravito-inertial wrench (force, moment about the CoM) [N, N m]
    com_height: FloatArray  # (N,) CoM height above the stance contact points [m]
    capture_point: FloatArray  # (N, 2) ICP relative to the CoM [m], eq. (5)
    joint_pos: FloatArray  # (N, 12) [rad] (NaN where unreachable)

    @property
    def solvable(self) -> BoolArray:
        return ~(self.no_contact | self.unreachable | self.below_feet)


def contact_batch(robot: Robot, lams: np.ndarray, com_iterations: int = 10, com_tol: float = 3e-5) -> ContactBatch:
    """The contact problems of many states (steps 1-4 of :func:`~margin_rl.stability.analytic.margin.analytic_margin`).

    Args:
        robot: from :func:`margin_rl.load_robot`.
        lams: (N, 47) lambda.
        com_iterations, com_tol: the CoM fixed point's iteration cap and tolerance [m].

    Raises:
        ValueError: lambda of the wrong shape or with NaN/inf (names the field), a non-unit gravity
            axis, contact flags other than 0/1 or mu <= 0 (names the first such state).
    """
    lams = check_lambda(lams, "lams")
    if lams.ndim != 2:
        raise ValueError(f"lams must have shape (N, {LAMBDA_DIM}), got {lams.shape}")
    st = from_lambda(lams)
    bad_flags = ~((st.contacts == 0.0) | (st.contacts == 1.0)).all(axis=1)
    if bad_flags.any():
        i = int(np.flatnonzero(bad_flags)[0])
        raise ValueError(f"lambda contacts must be 0 or 1, got {st.contacts[i].tolist()} in state {i}")
    if not (st.mu > 0).all():
        i = int(np.flatnonzero(~(st.mu > 0))[0])
        raise ValueError(f"lambda mu must be positive, got {float(st.mu[i])} in state {i}")
    n_states = lams.shape[0]
    rotations = base_rotation_from_gravity_axis(st.gravity_axis)  # (N, 3, 3)
    stance = st.contacts.astype(bool)
    no_contact = ~stance.any(axis=1)

    # IK of every state with the CoM-offset fixed point (feet rows R^T p_H, as contact_problem).
    joint_pos, reachable = _ik_com_relative_per_state(robot, st.feet @ rotations, com_iterations, com_tol)
    unreachable = ~no_contact & ~reachable.all(axis=1)

    normals = st.normals / np.linalg.norm(st.normals, axis=-1, keepdims=True)
    contact_points = st.feet - robot.foot_radius * normals
    n_stance = stance.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):  # no-contact states: 0 / 0
        com_height = -np.where(stance, contact_points[..., 2], 0.0).sum(axis=1) / n_stance
    below_feet = ~no_contact & ~unreachable & ~(com_height > 0)
    solvable = ~(no_contact | unreachable | below_feet)
    # Eq. (5) with c_xy = 0: xi = c_dot_xy sqrt(z / g) (NaN for states without a region).
    with np.errstate(invalid="ignore"):
        capture_point = st.com_vel[:, :2] * np.sqrt(np.where(solvable, com_height, np.nan) / robot.gravity)[:, None]

    jacobians = np.full((n_states, len(robot.legs), 3, 3), np.nan)
    leg_bias = np.full((n_states, len(robot.legs), 3), np.nan)
    ang_momentum_rate = np.full((n_states, 3), np.nan)
    for i in np.flatnonzero(solvable):
        jacobians[i], dynamics = robot.jacobians_and_dynamics(
            joint_pos[i], base_rotation=rotations[i], com_acc=st.com_acc[i], base_ang_acc=st.base_ang_acc[i]
        )
        leg_bias[i], ang_momentum_rate[i] = dynamics.bias_torques, dynamics.ang_momentum_rate

    # Gravito-inertial wrench about the CoM (contact.gravito_inertial_wrench with com = 0, per state):
    # F = m (c_ddot - g_vec) - f_ext, M = L_dot - tau_ext.
    wrench = np.empty((n_states, 6))
    wrench[:, :3] = robot.total_mass * (st.com_acc - np.array([0.0, 0.0, -robot.gravity])) - st.ext_force
    wrench[:, 3:] = ang_momentum_rate - st.ext_torque
    return ContactBatch(
        no_contact=no_contact,
        unreachable=unreachable,
        below_feet=below_feet,
        contact_points=contact_points,
        normals=normals,
        stance=stance,
        mu=np.asarray(st.mu, dtype=float),
        jacobians=jacobians,
        torque_limits=robot.torque_limits.reshape(len(robot.legs), 3),
        leg_bias=leg_bias,
        wrench=wrench,
        com_height=com_height,
        capture_point=capture_point,
        joint_pos=joint_pos,
    )


def _ik_com_relative_per_state(
    robot: Robot, feet_rel_com: FloatArray, iterations: int, tol: float
) -> tuple[FloatArray, BoolArray]:
    """``robot.inverse_kinematics_com_relative`` of each state as if alone: ``(joint_pos (N, 12), reachable (N, 4))``.

    The robot's batched fixed point stops when the *largest* residual of the batch is below ``tol``, so
    a state's joint angles would depend on the other states of its batch (by up to ``tol``; the focused
    projection turns such changes into margin changes up to focus_tol and, on states near a torque
    limit, beyond: 0.54 mm measured). Here each state stops at its own first iterate within ``tol``,
    exactly the single-state iteration, with numpy over the states still iterating.
    """
    n_states, n_legs = feet_rel_com.shape[0], feet_rel_com.shape[1]
    # The robot's linearisation of the CoM in the feet at the standing pose: the Newton matrix, the
    # per-foot sensitivities and the offset of the first-order initial guess (Robot's cached property).
    newton, sensitivity, offset = robot.com_fixed_point_linearisation
    com = (offset + np.einsum("fij,...fj->...i", sensitivity, feet_rel_com)) @ newton.T
    joint_pos = np.full((n_states, 3 * n_legs), np.nan)
    reachable = np.zeros((n_states, n_legs), dtype=bool)
    active = np.arange(n_states)
    for _ in range(iterations):
        if active.size == 0:
            return joint_pos, reachable
        ik = robot.inverse_kinematics(feet_rel_com[active] + com[active, None, :], clip=True)
        residual = robot.com_positions(ik.joint_pos) - com[active]
        done = np.abs(residual).max(axis=1) < tol
        finished = active[done]
        joint_pos[finished] = np.where(np.repeat(ik.reachable[done], 3, axis=-1), ik.joint_pos[done], np.nan)
        reachable[finished] = ik.reachable[done]
        # Newton step on c = F(c) (see Robot.inverse_kinematics_com_relative) for the others.
        com[active[~done]] += residual[~done] @ newton.T
        active = active[~done]
    if active.size:
        ik = robot.inverse_kinematics(feet_rel_com[active] + com[active, None, :])
        joint_pos[active], reachable[active] = ik.joint_pos, ik.reachable
    return joint_pos, reachable
