"""Steps 1-4 of the analytic margin: lambda -> IK -> Jacobians, bias torques, contact points, ICP, wrench.

One type, :class:`ContactProblem`, describes what both stability criteria need about states of a robot (the
Feasible Region of :mod:`~margin_rl.stability.analytic.margin` and seed 004's Feasible Wrench Polytope). It
is batch-first: :func:`contact_problem` builds the problems of N states at once, and one state is a batch of
one (``contact_problem(robot, lams)[i]`` is the problem of state i, with the leading axis dropped). The
maths (see the :mod:`~margin_rl.stability.analytic.margin` docstring):

1. the base orientation in the horizontal frame H from lambda's gravity axis;
2. the joint angles by analytic IK of every foot, with the fixed point on the CoM offset; each state stops
   at its own first iterate within ``com_tol``, so a state's joint angles never depend on the other states
   of its batch (:func:`_ik_com_relative_per_state`);
3. the foot Jacobians in H, the bias torques and the centroidal angular-momentum rate (Pinocchio, one call
   per state that has a region to solve);
4. the foot-sphere contact points, the CoM height above the stance contact points, the ICP (eq. 5) and the
   gravito-inertial wrench about the CoM.

The base rotations, the IK, the contact points, heights, capture points and wrenches are numpy operations
over the whole batch (one state's IK is dominated by numpy's per-call overhead, so a batch costs about as
much as one state).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from margin_rl.robot import Robot
from margin_rl.stability.analytic.lambda_state import (
    LAMBDA_DIM,
    base_rotation_from_gravity_axis,
    check_lambda,
    from_lambda,
)
from margin_rl.stability.geometry.contact import (
    DEFAULT_CONTACT_TORQUE_LIMIT,
    CentroidalLoad,
    ContactSet,
    LegLimits,
)

__all__ = ["ContactProblem", "contact_problem"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

SHARED_FIELDS = ("torque_limits", "mass", "gravity", "leg_names")
"""Fields that are the robot's, the same for every state of a batch (never indexed by a state)."""


@dataclass(frozen=True)
class ContactProblem:
    """The contact problems of states of a robot, frame H of each state (origin at its CoM, z up).

    Per-state fields have a leading batch axis of N states, or none for a single state (``problem[i]``).
    ``no_contact``, ``unreachable`` and ``below_feet`` (the CoM not above its stance feet: infeasible) mark
    the states without a region to solve, in that order of precedence; :attr:`solvable` is the rest.
    Entries of states that are not solvable may hold NaN (Jacobians, bias torques and angular-momentum
    rates are only computed for solvable states; joint angles are NaN on unreachable legs).
    """

    no_contact: BoolArray  # (N,)
    unreachable: BoolArray  # (N,)
    below_feet: BoolArray  # (N,)
    reachable: BoolArray  # (N, 4) each foot within its leg's workspace and joint limits
    contact_points: FloatArray  # (N, 4, 3) foot-sphere contact points relative to the CoM [m]
    normals: FloatArray  # (N, 4, 3) unit terrain normals
    stance: BoolArray  # (N, 4)
    mu: FloatArray  # (N,) friction coefficient
    jacobians: FloatArray  # (N, 4, 3, 3) foot Jacobians w.r.t. each leg's joints, in H [m/rad]
    leg_bias: FloatArray  # (N, 4, 3) bias torques delta_i [N m] (eq. 2)
    com_acc: FloatArray  # (N, 3) [m/s^2]
    ang_momentum_rate: FloatArray  # (N, 3) L_dot about the CoM [N m]
    ext_force: FloatArray  # (N, 3) [N]
    ext_torque: FloatArray  # (N, 3) [N m]
    com_vel: FloatArray  # (N, 3) [m/s]
    wrench: FloatArray  # (N, 6) gravito-inertial wrench (force, moment about the CoM) [N, N m]
    com_height: FloatArray  # (N,) CoM height above the stance contact points [m]
    capture_point: FloatArray  # (N, 2) ICP relative to the CoM [m], eq. (5)
    joint_pos: FloatArray  # (N, 12) [rad]
    base_rotation: FloatArray  # (N, 3, 3) R_HB
    torque_limits: FloatArray  # (4, 3) symmetric limits [N m] (the robot's)
    mass: float  # [kg]
    gravity: float  # [m/s^2]
    leg_names: tuple[str, ...]

    @property
    def solvable(self) -> BoolArray:
        """Where a region (or polytope) is to be solved: a contact, reachable feet, the CoM above them."""
        return ~(self.no_contact | self.unreachable | self.below_feet)

    def __len__(self) -> int:
        if np.ndim(self.no_contact) == 0:
            raise TypeError("a single state's ContactProblem has no length; index a batch to get one")
        return len(self.no_contact)

    def __getitem__(self, index: int | slice | np.ndarray) -> ContactProblem:
        """The problems of states ``index`` (an int drops the batch axis: one state's problem)."""
        if np.ndim(self.no_contact) == 0:
            raise TypeError("a single state's ContactProblem cannot be indexed further")
        values = {
            f.name: getattr(self, f.name) if f.name in SHARED_FIELDS else getattr(self, f.name)[index]
            for f in fields(self)
        }
        return ContactProblem(**values)

    @property
    def status(self) -> str:
        """One state's status: ``"ok"``, ``"no_contact"``, ``"unreachable"`` or ``"infeasible"``."""
        if bool(self.no_contact):
            return "no_contact"
        if bool(self.unreachable):
            return "unreachable"
        return "infeasible" if bool(self.below_feet) else "ok"

    @property
    def message(self) -> str:
        """Why one state has no region to solve ("" when it has one)."""
        status = self.status
        if status == "no_contact":
            return "no foot in contact"
        if status == "unreachable":
            legs = [leg for leg, ok in zip(self.leg_names, self.reachable.tolist(), strict=True) if not ok]
            return f"unreachable feet: {', '.join(legs)}"
        if status == "infeasible":
            return f"CoM is not above the stance feet (height {float(self.com_height):.3f} m)"
        return ""

    def contact_set(
        self, friction: str | tuple[str, int] = "cone", contact_torque_limit: float = DEFAULT_CONTACT_TORQUE_LIMIT
    ) -> ContactSet:
        """One state's contacts (points, normals, stance, mu) with a friction model and w_M of eq. (3)."""
        mu = float(self.mu)
        return ContactSet(self.contact_points, self.normals, self.stance, mu, friction, contact_torque_limit)

    def leg_limits(self) -> LegLimits:
        """One state's leg Jacobians, symmetric torque limits and bias torques."""
        return LegLimits(self.jacobians, self.torque_limits, self.leg_bias)

    def load(self) -> CentroidalLoad:
        """One state's mass, CoM acceleration, angular-momentum rate, external wrench and gravity."""
        return CentroidalLoad(
            self.mass, self.com_acc, self.ang_momentum_rate, self.ext_force, self.ext_torque, self.gravity
        )


def contact_problem(robot: Robot, lams: np.ndarray, com_iterations: int = 10, com_tol: float = 3e-5) -> ContactProblem:
    """The contact problems of states ``lams`` (steps 1-4 of the module docstring).

    Args:
        robot: from :func:`margin_rl.load_robot`.
        lams: (N, 47) lambda; one state is ``lam[None]`` (then take ``[0]``).
        com_iterations, com_tol: the CoM fixed point's iteration cap and tolerance [m].

    Raises:
        ValueError: lambda of the wrong shape or with NaN/inf (names the field), a non-unit gravity
            axis, contact flags other than 0/1 or mu <= 0 (names the first such state).
    """
    lams = check_lambda(lams, "lams")
    if lams.ndim != 2:
        raise ValueError(f"lams must have shape (N, {LAMBDA_DIM}) (one state: lam[None]), got {lams.shape}")
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

    # IK of every state with the CoM-offset fixed point (feet rows R^T p_H).
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

    # Gravito-inertial wrench about the CoM (geometry.contact.gravito_inertial_wrench with com = 0, per state):
    # F = m (c_ddot - g_vec) - f_ext, M = L_dot - tau_ext.
    wrench = np.empty((n_states, 6))
    wrench[:, :3] = robot.total_mass * (st.com_acc - np.array([0.0, 0.0, -robot.gravity])) - st.ext_force
    wrench[:, 3:] = ang_momentum_rate - st.ext_torque
    return ContactProblem(
        no_contact=no_contact,
        unreachable=unreachable,
        below_feet=below_feet,
        reachable=reachable,
        contact_points=contact_points,
        normals=normals,
        stance=stance,
        mu=np.asarray(st.mu, dtype=float),
        jacobians=jacobians,
        leg_bias=leg_bias,
        com_acc=st.com_acc,
        ang_momentum_rate=ang_momentum_rate,
        ext_force=st.ext_force,
        ext_torque=st.ext_torque,
        com_vel=st.com_vel,
        wrench=wrench,
        com_height=com_height,
        capture_point=capture_point,
        joint_pos=joint_pos,
        base_rotation=rotations,
        torque_limits=robot.torque_limits.reshape(len(robot.legs), 3),
        mass=robot.total_mass,
        gravity=robot.gravity,
        leg_names=tuple(robot.leg_names),
    )


def _ik_com_relative_per_state(
    robot: Robot, feet_rel_com: FloatArray, iterations: int, tol: float
) -> tuple[FloatArray, BoolArray]:
    """The CoM fixed point of ``robot.inverse_kinematics_com_relative`` for each state as if alone:
    ``(joint_pos (N, 12), reachable (N, 4))``.

    The robot's batched fixed point stops when the *largest* residual of the batch is below ``tol``, so
    a state's joint angles would depend on the other states of its batch (by up to ``tol``; the focused
    projection turns such changes into margin changes up to focus_tol and, on states near a torque
    limit, beyond: 0.54 mm measured). Here each state stops at its own first iterate within ``tol``, with
    numpy over the states still iterating, and each CoM is Pinocchio's (``Robot.com_position_each``), so a
    state's result is the same in any batch, a batch of one included, to rounding (the small matrix products of
    the Newton step round differently in the last bit for 1 and for N rows on a few states in a thousand).
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
        residual = robot.com_position_each(ik.joint_pos) - com[active]
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
