r"""The wrench polytopes a crawl planner works in: one per stance, computed once (seed 004 §V, §V-A).

A base-motion phase is planned inside two polytopes of the same contact configuration: the four-foot
stance during the motion and the triple stance the CoM is held in while the next leg swings. Each is
computed once, at a reference configuration (the heuristic plan's end pose, as the paper does:
constant Jacobians :math:`J(q_0)`, quasi-static bias torques), with moments about that pose's CoM
:math:`c_0` in the horizontal frame H (x along the crawl, z up). The planners then rate a wrench by the
pseudo-inverse weights of eq. (27),

.. math:: \lambda = V^{\#} w_{GI} + N_V \lambda_0 \quad\Rightarrow\quad \lambda - \lambda_0 = V^{\#}(w_{GI} - \bar v),
          \qquad \|\lambda - \lambda_0\|_2^2 = (w_{GI} - \bar v)^T (V V^T)^{-1} (w_{GI} - \bar v),

with :math:`V` (6 x n_v) the vertices, :math:`\lambda_0 = \mathbf{1}/n_v` and :math:`\bar v = V\lambda_0` the
vertex centroid (:math:`V^{\#} = V^T (V V^T)^{-1}`, :math:`V V^{\#} = I` for a 6-D polytope). So the
running cost of eq. (28) is a quadratic form in the wrench with the 6 x 6 matrix
:math:`(V V^T)^{-1}`: the number of vertices changes the planner's problem only through that matrix
(Table III's "marginally"). We scale it by :math:`n_v` (the mean square of the *relative* weight
deviation :math:`n_v(\lambda_j - \lambda_{0j})`), so that stances with 700 and 4000 vertices weigh alike.

Kinds: ``"fwp"`` is the Feasible Wrench Polytope (friction and joint-torque limits, eq. 13); ``"cwc"``
is the contact wrench cone bounded at a per-contact force of the robot's own weight (friction only;
the same construction with each leg's torque polytope replaced by the box ``|f_x|, |f_y|, |f_z| <= m g``
in H, which on flat ground caps the normal force), whose eq. (24) factor is the paper's "CWC margin"
(§VI-B). The cap does not grow with a carried load, so that a loaded and an unloaded crawl are rated in
the same polytope.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from margin_rl.robot import Robot
from margin_rl.stability.analytic.contact_problem import ContactProblem, contact_problem
from margin_rl.stability.analytic.lambda_state import StabilityState
from margin_rl.stability.fwp.feasibility import contact_problem_polytope
from margin_rl.stability.fwp.polytope import FeasibleWrenchPolytope, feasible_wrench_polytope

FloatArray = NDArray[np.float64]

POLYTOPE_KINDS: tuple[str, ...] = ("fwp", "cwc")
"""Wrench polytopes a planner can work in: the FWP (friction + torque limits), the bounded CWC (friction)."""


@dataclass(frozen=True)
class StanceSnapshot:
    """A static crawl pose, world frame W (z up, heading +x): what a stance polytope is computed from.

    Attributes:
        com: (3,) CoM [m].
        feet: (4, 3) foot-sphere centres [m], leg order LF RF LH RH.
        stance: (4,) bool, feet on the ground.
        normals: (4, 3) unit terrain normals at the feet.
        mu: friction coefficient.
        ext_force: (3,) known external force on the robot [N] (e.g. a carried load), world frame.
        ext_torque: (3,) its moment about the CoM [N m].
        torque_limits: (4, 3) symmetric joint-torque limits [N m] (the robot's, or a hindered joint's).
    """

    com: FloatArray
    feet: FloatArray
    stance: NDArray[np.bool_]
    normals: FloatArray
    mu: float
    ext_force: FloatArray
    ext_torque: FloatArray
    torque_limits: FloatArray

    def lam(self) -> FloatArray:
        """lambda (47,) of the static pose (zero CoM velocity and acceleration, level base)."""
        zero = np.zeros(3)
        return StabilityState(
            gravity_axis=np.array([0.0, 0.0, 1.0]),
            com_vel=zero,
            com_acc=zero,
            base_ang_acc=zero,
            ext_force=np.asarray(self.ext_force, dtype=float),
            ext_torque=np.asarray(self.ext_torque, dtype=float),
            feet=np.asarray(self.feet, dtype=float) - np.asarray(self.com, dtype=float),
            mu=np.asarray(self.mu, dtype=float),
            contacts=self.stance.astype(float),
            normals=np.asarray(self.normals, dtype=float),
        ).to_lambda()


@dataclass(frozen=True)
class StancePolytope:
    """One stance's wrench polytope and the planner's quadratic form of it (moments about ``reference_com``).

    Attributes:
        kind: ``"fwp"`` or ``"cwc"``.
        reference_com: (3,) CoM c_0 [m, W] the moments are taken about.
        polytope: the V-description (``polytope.vertices`` (n_v, 6) [N, N m]).
        centroid: (6,) vertex centroid v_bar = V lambda_0.
        metric: (6, 6) n_v (V V^T)^{-1}: ``(w - v_bar)^T metric (w - v_bar) = n_v ||lambda - lambda_0||^2``.
        build_seconds: wall-clock time of the V-description (kinematics, cones, Minkowski sum).
    """

    kind: str
    reference_com: FloatArray
    polytope: FeasibleWrenchPolytope
    centroid: FloatArray
    metric: FloatArray
    build_seconds: float

    @property
    def n_vertices(self) -> int:
        return self.polytope.n_vertices

    def weights(self, wrench: np.ndarray) -> FloatArray:
        """lambda of eq. (27) for a wrench (6,): ``V^# w + N_V lambda_0`` (for checks; the planner uses ``metric``)."""
        v = self.polytope.vertices.T
        n_v = v.shape[1]
        pinv = np.linalg.pinv(v)
        lam0 = np.full(n_v, 1.0 / n_v)
        return pinv @ np.asarray(wrench, dtype=float) + (np.eye(n_v) - pinv @ v) @ lam0

    def cost(self, wrench: np.ndarray) -> float:
        """The running cost of eq. (28), squared and scaled: n_v ||lambda - lambda_0||^2 (see the module)."""
        d = np.asarray(wrench, dtype=float) - self.centroid
        return float(d @ self.metric @ d)


def stance_polytope(
    robot: Robot, snapshot: StanceSnapshot, kind: str, n_faces: int = 4, problem: ContactProblem | None = None
) -> StancePolytope:
    """The ``kind`` polytope of ``snapshot``'s stance, at its pose (IK, Jacobians and bias torques there).

    ``problem``: the snapshot's contact problem where the caller has it already
    (``contact_problem(robot, snapshot.lam()[None])[0]``).

    Raises:
        ValueError: unknown ``kind``; a pose the robot cannot reach or with fewer than three stance feet
            (the polytope would not be 6-D and the pseudo-inverse cost would not exist).
    """
    if kind not in POLYTOPE_KINDS:
        raise ValueError(f"unknown polytope kind {kind!r}; choose from {', '.join(POLYTOPE_KINDS)}")
    if int(np.count_nonzero(snapshot.stance)) < 3:
        raise ValueError("a crawl stance polytope needs at least three feet on the ground")
    t0 = time.perf_counter()
    if problem is None:
        problem = contact_problem(robot, snapshot.lam()[None])[0]
    if problem.status not in ("ok", "infeasible"):  # "infeasible" = CoM below the feet: irrelevant here
        raise ValueError(f"the crawl pose is not a valid stance ({problem.status}): {problem.message}")
    if kind == "fwp":
        polytope = contact_problem_polytope(problem, n_faces=n_faces, torque_limits=snapshot.torque_limits)
    else:  # friction only: the torque polytope replaced by a force cap of the robot's weight per contact
        cap = robot.total_mass * robot.gravity
        polytope = feasible_wrench_polytope(
            problem.contact_points, problem.normals, problem.stance, problem.mu,
            np.broadcast_to(np.eye(3), (4, 3, 3)), np.full((4, 3), cap), np.zeros((4, 3)), n_faces=n_faces,
        )  # fmt: skip
    if polytope.dim != 6 or polytope.n_vertices == 0:
        raise ValueError(f"the {kind} polytope of this stance is not 6-D (dim {polytope.dim}): check the feet")
    v = polytope.vertices.T
    centroid = v.mean(axis=1)
    metric = v.shape[1] * np.linalg.inv(v @ v.T)
    return StancePolytope(
        kind, np.asarray(snapshot.com, dtype=float).copy(), polytope, centroid, 0.5 * (metric + metric.T),
        time.perf_counter() - t0,
    )  # fmt: skip
