"""The Table I sampler of seed 000: random lambda around a robot's nominal stance.

Every distribution of Table I, in one frozen config (:class:`TableI`), vectorised and seeded:

=====================================  =========================================================
feet in contact                        X ~ U(0, 3), read as numpy's ``integers(0, 3)``: X in {0, 1, 2}
                                       lifted feet, equally likely. X = 1 lifts one foot chosen
                                       uniformly (3-contact); X = 2 lifts a diagonal pair (LF+RH or
                                       RF+LH, uniformly), leaving a trot stance (2-contact). Table I
                                       does not say more; this reading produces exactly the 4-, 3-
                                       and 2-contact (diagonal) states the paper's gaits use.
base roll, pitch                       U(-pi/15, pi/15) -> e_g
CoM velocity                           x, y ~ U(-1.25, 1.25), z ~ N(0, 0.2) [m/s]
CoM acceleration                       x, y ~ U(-2.5, 2.5), z ~ U(-1.25, 1.25) [m/s^2]
base angular acceleration              x, y ~ U(-1, 1), z ~ N(0, 0.5) [rad/s^2]
friction coefficient                   mu ~ U(0.2, 0.9)
foot deviation from nominal (H frame)  x ~ U(-0.35, 0.35), y, z ~ U(-0.2, 0.2) [m]
contact normal tilts                   alpha, beta ~ N(0, pi/8): n = Ry(beta) Rx(alpha) e_z
external force, torque                 each component N(0, 50) [N], N(0, 25) [N m]
=====================================  =========================================================

N(m, s) denotes mean m and standard deviation s. The nominal stance is the robot's ``standing``
keyframe with a level base: feet positions relative to the whole-body CoM.

Kinematic feasibility: Table I's foot deviations (35 cm in x, 20 cm in y and z) put most draws
outside the leg workspace (measured: about 93 % of raw draws have at least one unreachable foot on
ANYmal B and C). Such states cannot occur on the robot and have no margin, so by default the sampler
keeps only draws whose four feet are reachable (rejection sampling: the Table I distribution
conditioned on kinematic feasibility), checked with the same IK and CoM fixed point as the analytic
margin. ``reachable_only=False`` returns raw Table I draws.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np

from margin_rl.robot import Robot
from margin_rl.stability.analytic.lambda_state import (
    LAMBDA_DIM,
    N_FEET,
    StabilityState,
    base_rotation_from_gravity_axis,
    from_lambda,
    gravity_axis_from_roll_pitch,
)

SAMPLER_VERSION = 1
"""Bumped whenever the sampler's output for a given seed changes."""

# Diagonal (trot) pairs of lifted feet, indices into LF, RF, LH, RH.
_DIAGONAL_PAIRS = np.array([[0, 3], [1, 2]])
CONTACT_PATTERNS = ("table_i", "any_support")
# The 15 non-empty contact sets as (15, 4) flags, for contact_patterns="any_support".
_NON_EMPTY_SUPPORTS = np.array([[(k >> leg) & 1 for leg in range(N_FEET)] for k in range(1, 2**N_FEET)], dtype=float)


@dataclass(frozen=True)
class TableI:
    """Sampling distributions of seed 000 Table I (uniform half-widths, normal standard deviations)."""

    max_lifted_feet: int = 2  # X ~ integers(0, max_lifted_feet + 1)
    roll_pitch_half_width: float = np.pi / 15  # [rad]
    com_vel_xy_half_width: float = 1.25  # [m/s]
    com_vel_z_std: float = 0.2  # [m/s]
    com_acc_xy_half_width: float = 2.5  # [m/s^2]
    com_acc_z_half_width: float = 1.25  # [m/s^2]
    ang_acc_xy_half_width: float = 1.0  # [rad/s^2]
    ang_acc_z_std: float = 0.5  # [rad/s^2]
    mu_low: float = 0.2
    mu_high: float = 0.9
    foot_x_half_width: float = 0.35  # [m]
    foot_yz_half_width: float = 0.2  # [m]
    normal_tilt_std: float = np.pi / 8  # [rad]
    ext_force_std: float = 50.0  # [N]
    ext_torque_std: float = 25.0  # [N m]
    # "table_i": X lifted feet as above; "any_support": each of the 15 non-empty sets of feet in contact
    # equally likely (front, hind and lateral pairs, single feet: what walking policies visit).
    contact_patterns: str = "table_i"

    def __post_init__(self) -> None:
        if self.max_lifted_feet not in (0, 1, 2):
            raise ValueError(f"max_lifted_feet must be 0, 1 or 2, got {self.max_lifted_feet}")
        if self.contact_patterns not in CONTACT_PATTERNS:
            raise ValueError(f"contact_patterns must be one of {CONTACT_PATTERNS}, got {self.contact_patterns!r}")
        if not self.mu_low > 0 or not self.mu_high > self.mu_low:
            raise ValueError(f"need 0 < mu_low < mu_high, got {self.mu_low}, {self.mu_high}")


LOCOMOTION = TableI(
    roll_pitch_half_width=0.72,
    com_vel_z_std=0.3,
    com_acc_xy_half_width=11.0,
    com_acc_z_half_width=17.5,
    ang_acc_xy_half_width=240.0,
    ang_acc_z_std=30.0,
    mu_high=1.1,
    foot_x_half_width=0.65,
    foot_yz_half_width=0.45,
    ext_force_std=75.0,
    contact_patterns="any_support",
)
"""Table I widened to the states walking policies visit.

The ranges cover the 0.5-99.5 percentiles of lambda measured over rollouts of walking policies of ANYmal B
(the bundled policies, both variants) and C (two 5M-step policies, with and without the margin term), on flat
and rough ground, over the command range, with pushes and friction randomisation
(``benchmarks/studies/bench_locomotion_distribution.py``,
``docs/learned_margin/locomotion_distribution_anymal_{b,c}.json``): base tilts up to 41 deg, CoM
accelerations of -10..+17 m/s^2 vertically, base angular accelerations of +-235 rad/s^2 about x, friction up
to 1.0 (the environments' default), feet crossed or spread by up to 0.63 m, pushes of 150 N, and every set of
feet in contact. The finite-difference accelerations of the environments are what makes the angular ranges
this wide (``benchmarks/studies/bench_acceleration_estimates.py``).

The ranges are right, the density is not (measured, BENCHMARKS.md): independent uniform draws over them are
infeasible 97-98 % of the time on ANYmal B and C (Table I: 42 % on B), because extreme accelerations together
admit no equilibrium, while the rollouts' extremes are rare and correlated. Use it to check coverage, not yet
as a training distribution; :func:`sample_around_states` draws around recorded rollout states instead
(59 % labelled ok on ANYmal B, like Table I)."""

DISTRIBUTIONS: dict[str, TableI] = {"table_i": TableI(), "locomotion": LOCOMOTION}
"""The state distributions a dataset can be drawn from, by name (``dataset generate --distribution``)."""


def nominal_feet(robot: Robot) -> np.ndarray:
    """(4, 3) foot-sphere centres relative to the CoM at the standing pose with a level base [m]."""
    q = robot.standing_joint_pos
    return robot.foot_positions(q) - robot.com_position(q)


def standing_state(robot: Robot, **overrides: np.ndarray) -> np.ndarray:
    """lambda (47,) of ``robot`` standing still at its nominal stance on flat ground.

    Level base, zero CoM velocity and accelerations, no external wrench, the four feet of
    :func:`nominal_feet` in contact, flat normals and mu = 0.8; keyword arguments replace any
    :class:`~margin_rl.stability.analytic.lambda_state.StabilityState` field (e.g. ``com_vel=...``).

    Raises:
        TypeError: an override that is not a lambda field.
    """
    unknown = set(overrides) - {f.name for f in fields(StabilityState)}
    if unknown:
        raise TypeError(f"unknown lambda fields {sorted(unknown)}")
    values = dict(
        gravity_axis=np.array([0.0, 0.0, 1.0]),
        com_vel=np.zeros(3),
        com_acc=np.zeros(3),
        base_ang_acc=np.zeros(3),
        ext_force=np.zeros(3),
        ext_torque=np.zeros(3),
        feet=nominal_feet(robot),
        mu=np.array(0.8),
        contacts=np.ones(N_FEET),
        normals=np.tile([0.0, 0.0, 1.0], (N_FEET, 1)),
    )
    values.update({k: np.asarray(v, dtype=float) for k, v in overrides.items()})
    return StabilityState(**values).to_lambda()


def reachable(robot: Robot, lam: np.ndarray, com_iterations: int = 10) -> np.ndarray:
    """Which states have all four feet inside their leg workspace and joint limits: (N,) bool.

    Same test as the analytic margin's step 2 (IK of p_B = R_HB^T p_H + c_B with the CoM offset c_B
    found by fixed-point iteration), batched with the closed-form CoM.
    """
    st = from_lambda(lam)
    R = base_rotation_from_gravity_axis(st.gravity_axis)
    feet = np.einsum("...fi,...ij->...fj", st.feet, R)  # R^T p_H, row-wise
    solution, _ = robot.inverse_kinematics_com_relative(feet, iterations=com_iterations)
    return solution.reachable.all(axis=-1)


def sample_states(
    robot: Robot,
    n: int,
    seed: int | np.random.SeedSequence,
    table: TableI | None = None,
    reachable_only: bool = True,
) -> np.ndarray:
    """Draw ``n`` lambda vectors (n, 47) from Table I around ``robot``'s nominal stance.

    Args:
        robot: the robot whose standing pose defines the nominal feet.
        n: number of samples (>= 0).
        seed: an int or ``numpy.random.SeedSequence`` for ``numpy.random.default_rng``; the same
            (robot, n, seed, table) gives the same samples. A shorter draw is *not* a prefix of a
            longer one: draw shards with their own seeds.
        table: the distributions; Table I of the paper if omitted.
        reachable_only: keep only kinematically feasible draws (see the module docstring).
    """
    if int(n) != n or n < 0:
        raise ValueError(f"n must be a non-negative integer, got {n!r}")
    n = int(n)
    t = TableI() if table is None else table
    rng = np.random.default_rng(seed)
    if not reachable_only:
        return _draw(robot, n, rng, t)
    # Oversample: about 7 % of raw draws are reachable.
    return _reachable_draws(robot, n, lambda k: _draw(robot, k, rng, t), min_batch=1024, oversample=16)


def _reachable_draws(
    robot: Robot, n: int, draw: Callable[[int], np.ndarray], min_batch: int, oversample: int
) -> np.ndarray:
    """``n`` kinematically feasible states (n, 47) from ``draw(k)`` (k raw states), by rejection.

    Each round draws ``max(min_batch, oversample * missing)`` states and keeps the reachable ones, in order.
    """
    kept: list[np.ndarray] = []
    count = 0
    while count < n:
        batch = draw(max(min_batch, oversample * (n - count)))
        batch = batch[reachable(robot, batch)]
        kept.append(batch[: n - count])
        count += len(kept[-1])
    return np.concatenate(kept) if kept else np.zeros((0, LAMBDA_DIM))


def _draw(robot: Robot, n: int, rng: np.random.Generator, t: TableI) -> np.ndarray:

    def uniform(half_width: float, size: tuple[int, ...] | int) -> np.ndarray:
        return rng.uniform(-half_width, half_width, size=size)

    if t.contact_patterns == "any_support":
        contacts = _NON_EMPTY_SUPPORTS[rng.integers(0, len(_NON_EMPTY_SUPPORTS), size=n)]
    else:
        contacts = np.ones((n, N_FEET))
        lifted = rng.integers(0, t.max_lifted_feet + 1, size=n)
        one = np.nonzero(lifted == 1)[0]
        contacts[one, rng.integers(0, N_FEET, size=one.size)] = 0.0
        two = np.nonzero(lifted == 2)[0]
        pairs = _DIAGONAL_PAIRS[rng.integers(0, 2, size=two.size)]
        contacts[two[:, None], pairs] = 0.0

    roll = uniform(t.roll_pitch_half_width, n)
    pitch = uniform(t.roll_pitch_half_width, n)
    com_vel = np.column_stack([uniform(t.com_vel_xy_half_width, (n, 2)), rng.normal(0, t.com_vel_z_std, n)])
    com_acc = np.column_stack([uniform(t.com_acc_xy_half_width, (n, 2)), uniform(t.com_acc_z_half_width, n)])
    ang_acc = np.column_stack([uniform(t.ang_acc_xy_half_width, (n, 2)), rng.normal(0, t.ang_acc_z_std, n)])
    mu = rng.uniform(t.mu_low, t.mu_high, size=n)
    deviation = np.concatenate(
        [uniform(t.foot_x_half_width, (n, N_FEET, 1)), uniform(t.foot_yz_half_width, (n, N_FEET, 2))], axis=-1
    )
    feet = nominal_feet(robot) + deviation
    alpha = rng.normal(0, t.normal_tilt_std, (n, N_FEET))
    beta = rng.normal(0, t.normal_tilt_std, (n, N_FEET))
    normals = np.stack([np.cos(alpha) * np.sin(beta), -np.sin(alpha), np.cos(alpha) * np.cos(beta)], axis=-1)
    state = StabilityState(
        gravity_axis=gravity_axis_from_roll_pitch(roll, pitch),
        com_vel=com_vel,
        com_acc=com_acc,
        base_ang_acc=ang_acc,
        ext_force=rng.normal(0, t.ext_force_std, (n, 3)),
        ext_torque=rng.normal(0, t.ext_torque_std, (n, 3)),
        feet=feet,
        mu=mu,
        contacts=contacts,
        normals=normals,
    )
    return state.to_lambda()


@dataclass(frozen=True)
class RolloutJitter:
    """How :func:`sample_around_states` perturbs recorded states.

    Each continuous lambda entry gets Gaussian noise of ``noise_fraction`` times that entry's standard
    deviation over the recorded states (so the perturbation follows each field's own scale: newtons for the
    push, rad/s^2 for the angular acceleration); the gravity axis and the normals are renormalised to unit
    length, mu is kept >= ``min_mu``, and each contact flag flips with probability ``contact_flip``.
    """

    noise_fraction: float = 0.1
    contact_flip: float = 0.05
    min_mu: float = 0.05

    def __post_init__(self) -> None:
        if not (np.isfinite(self.noise_fraction) and self.noise_fraction >= 0):
            raise ValueError(f"RolloutJitter.noise_fraction must be finite and >= 0, got {self.noise_fraction}")
        if not 0 <= self.contact_flip <= 1:
            raise ValueError(f"RolloutJitter.contact_flip must be in [0, 1], got {self.contact_flip}")
        if not self.min_mu > 0:
            raise ValueError(f"RolloutJitter.min_mu must be > 0, got {self.min_mu}")


def _perturb(states: np.ndarray, n: int, rng: np.random.Generator, jitter: RolloutJitter) -> np.ndarray:
    """``n`` states drawn uniformly from ``states`` (M, 47) and perturbed by ``jitter``."""
    base = states[rng.integers(0, len(states), size=n)]
    scale = jitter.noise_fraction * states.std(axis=0)
    out = from_lambda(base + rng.normal(size=base.shape) * scale)
    contacts = from_lambda(base).contacts
    flips = rng.random(contacts.shape) < jitter.contact_flip
    perturbed = StabilityState(
        gravity_axis=out.gravity_axis / np.linalg.norm(out.gravity_axis, axis=-1, keepdims=True),
        com_vel=out.com_vel,
        com_acc=out.com_acc,
        base_ang_acc=out.base_ang_acc,
        ext_force=out.ext_force,
        ext_torque=out.ext_torque,
        feet=out.feet,
        mu=np.maximum(out.mu, jitter.min_mu),
        contacts=np.where(flips, 1.0 - contacts, contacts),
        normals=out.normals / np.linalg.norm(out.normals, axis=-1, keepdims=True),
    )
    return perturbed.to_lambda()


def sample_around_states(
    robot: Robot,
    states: np.ndarray,
    n: int,
    seed: int | np.random.SeedSequence,
    jitter: RolloutJitter | None = None,
    reachable_only: bool = True,
) -> np.ndarray:
    """Draw ``n`` lambda vectors (n, 47) around recorded states, e.g. ``info["lambda"]`` of policy rollouts.

    The draws follow the recorded states' joint distribution (their correlated extremes, contact sets and
    friction), unlike independent ranges (:data:`LOCOMOTION`, 97 % infeasible), and explore around them by
    :class:`RolloutJitter`. ``reachable_only`` keeps the kinematically feasible draws, as :func:`sample_states`.
    """
    if int(n) != n or n < 0:
        raise ValueError(f"n must be a non-negative integer, got {n!r}")
    recorded = np.asarray(states, dtype=float)
    if recorded.ndim != 2 or recorded.shape[1] != LAMBDA_DIM or len(recorded) < 2:
        raise ValueError(f"states must have shape (M, {LAMBDA_DIM}) with M >= 2, got {recorded.shape}")
    if not np.all(np.isfinite(recorded)):
        raise ValueError("states contain NaN or inf; record finite lambdas (e.g. drop diverged steps)")
    jitter = RolloutJitter() if jitter is None else jitter
    rng = np.random.default_rng(seed)
    n = int(n)
    if not reachable_only:
        return _perturb(recorded, n, rng, jitter)
    # Most perturbed rollout states stay reachable: a small oversampling suffices.
    return _reachable_draws(robot, n, lambda k: _perturb(recorded, k, rng, jitter), min_batch=256, oversample=2)
