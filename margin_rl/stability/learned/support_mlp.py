r"""Structured learned margin: a network predicts the Feasible Region's support function, the margin is exact.

The analytic margin m_a is the signed distance of the capture point xi to the Feasible Region R (seed 000 eq.
5-7; outside R, minus the Euclidean distance, as ``AnalyticSettings(outside="euclidean")``). R does not depend on
the CoM velocity: only xi does. For any convex set R with support function h_R(u) = max_{p in R} u.p,

    m(xi) = min over unit u of ( h_R(u) - u.xi )

both inside (the distance to the boundary, reached at the normal of the nearest edge) and outside (minus the
distance, reached at u = (xi - p*) / |xi - p*|), and every unit u gives an upper bound. This model learns h_R at
a set of directions from lambda *without* the CoM velocity and computes the rest exactly (frame H of
:mod:`~margin_rl.stability.analytic.lambda_state`: origin at the CoM, z up; lengths in metres)::

    P_i      = p_i - r n_i                                contact point of foot i (sphere radius r)
    z        = - sum_i c_i P_i,z / sum_i c_i                 CoM height over the stance contact points
    xi       = c_dot_xy sqrt(z / g)                         capture point relative to the CoM (eq. 5)
    u_k      = K fixed directions (cos 2 pi k / K, sin 2 pi k / K), then the two unit normals of every pair
               of feet, +-perp(P_b,xy - P_a,xy): a two-foot region is a thin sliver along its feet's line,
               which fixed directions alone resolve badly
    h_k      = max_{i in stance} u_k . P_i,xy [+ u_k . s] + s_h NN_k(lambda without c_dot)
    m        = min_k ( h_k - u_k . xi )

The prior (``prior="polygon"``) is the support function of the stance feet's contact polygon; the network learns
how the conic program moves and shrinks it (the gravito-inertial load, torque limits, friction). ``prior="shifted"``
also moves the polygon by the static load shift s of :mod:`~margin_rl.stability.learned.features`: with the force
the contacts must produce F = m (c_ddot + g e_z) - f_ext, s = ((z F_x - tau_y) / F_z, (z F_y + tau_x) / F_z) (F_z
floored at 0.02 m g), the centre of pressure lies at c_xy - s, so on flat ground with unlimited torques and
friction the region is exactly the polygon translated by s, and the network learns only what torques and friction
take away. Swing feet enter the prior lowered by :data:`SWING_PENALTY`.

Along CoM-velocity sweeps the margin's shape is therefore exact. The finite direction set can only overestimate
the margin (each direction's value is an upper bound): inside, where the nearest edge's normal is not in the set;
outside beyond a vertex, by at most 1 - cos(pi / K) of the distance. Edges along a pair of feet are exact.

``SupportMarginMLP`` exposes the interface :func:`margin_rl.stability.learned.training.fit` trains
(``input_mean``, ``input_std``, ``output_scale``, ``normalized_forward``), so the paper network and this model
are fitted by the same loop on the same data. Mirror symmetry comes from augmentation (``mirror="augment"``):
the direction set is mirror-symmetric, the network is not tied.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import torch
from torch import nn

from margin_rl.network import input_scaling, torch_sequential
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, LAMBDA_SLICES, N_FEET
from margin_rl.stability.learned.mlp_weights import ACTIVATION, ARCHITECTURE

DEFAULT_DIRECTIONS = 32
"""K, the fixed directions (measured: K = 32 costs 0.67 cm of discretisation on two-foot stances without the
pair-aligned directions, K = 64 0.34 cm)."""

SWING_PENALTY = 10.0  # [m] a swing foot's value in the prior's max is lowered by this (exact for 0/1 flags)
HEIGHT_FLOOR = 0.01  # [m] floor of the CoM height in xi (Table I heights are 0.3-0.7 m)
FORCE_FLOOR = 0.02  # floor of F_z in the load shift, as a fraction of m g
PRIORS: tuple[str, ...] = ("polygon", "shifted")
PAIR_EPS = 1e-6  # [m] in |P_b - P_a| of a pair normal: finite where two feet coincide
FOOT_PAIRS: tuple[tuple[int, int], ...] = tuple(itertools.combinations(range(N_FEET), 2))
N_PAIR_DIRECTIONS = 2 * len(FOOT_PAIRS)

_VELOCITY = LAMBDA_SLICES["com_vel"]
TRUNK_INPUTS: tuple[int, ...] = tuple(i for i in range(LAMBDA_DIM) if not _VELOCITY.start <= i < _VELOCITY.stop)
"""lambda's entries the support network sees: all but the CoM velocity (the region does not depend on it)."""


def fixed_directions(count: int) -> np.ndarray:
    """(count, 2) unit vectors at angles 2 pi k / count: a set closed under the mirror y -> -y."""
    if count < 3:
        raise ValueError(f"the support model needs at least 3 fixed directions, got {count}")
    angles = 2.0 * math.pi * np.arange(count) / count
    return np.stack([np.cos(angles), np.sin(angles)], axis=1)


class SupportMarginMLP(nn.Module):
    """m(lambda) = min_k (h_k(lambda) - u_k(lambda) . xi(lambda)) with h_k = prior + network (module docstring).

    ``forward(lam)``: raw lambda (..., 47) -> margin (...) [m]; ``support(lam)``: (directions (..., D, 2),
    support values (..., D) [m], capture point (..., 2) [m]) with D = K + 12. The network is the paper's
    hidden layers (256-128-128, softsign) from the 44 entries of lambda without the CoM velocity to D outputs
    scaled by ``support_scale`` [m].
    """

    def __init__(
        self,
        input_mean: np.ndarray,
        input_std: np.ndarray,
        output_mean: float,
        output_std: float,
        foot_radius: float,
        gravity: float,
        directions: int = DEFAULT_DIRECTIONS,
        support_scale: float = 0.1,
        hidden: tuple[int, ...] = ARCHITECTURE[1:-1],
        prior: str = "polygon",
        mass: float = 1.0,
    ) -> None:
        super().__init__()
        if not (foot_radius >= 0 and gravity > 0 and support_scale > 0 and mass > 0):
            raise ValueError(
                f"foot_radius >= 0, gravity > 0, mass > 0 and support_scale > 0 needed, got {foot_radius}, "
                f"{gravity}, {mass}, {support_scale}"
            )
        if prior not in PRIORS:
            raise ValueError(f"prior must be one of {PRIORS}, got {prior!r}")
        self.foot_radius, self.gravity, self.support_scale = float(foot_radius), float(gravity), float(support_scale)
        self.prior, self.mass = prior, float(mass)
        self.n_fixed = int(directions)
        self.trunk = torch_sequential(
            (len(TRUNK_INPUTS), *hidden, directions + N_PAIR_DIRECTIONS), ACTIVATION, dtype=torch.float32
        )
        self.register_buffer("fixed", torch.as_tensor(fixed_directions(directions), dtype=torch.float32))
        self.register_buffer("trunk_inputs", torch.as_tensor(TRUNK_INPUTS, dtype=torch.long))
        self.register_buffer("input_mean", torch.as_tensor(input_mean, dtype=torch.float32))
        self.register_buffer("input_std", torch.as_tensor(input_std, dtype=torch.float32))
        self.register_buffer("output_scale", torch.tensor([output_mean, output_std], dtype=torch.float32))

    def _geometry(
        self, lam: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(contact points xy (..., 4, 2), stance flags (..., 4), capture point (..., 2), directions (..., D, 2),
        CoM height (...))."""
        feet = lam[..., LAMBDA_SLICES["feet"]].unflatten(-1, (N_FEET, 3))
        normals = lam[..., LAMBDA_SLICES["normals"]].unflatten(-1, (N_FEET, 3))
        contacts = lam[..., LAMBDA_SLICES["contacts"]]
        points = feet - self.foot_radius * normals
        height = -(contacts * points[..., 2]).sum(-1) / contacts.sum(-1).clamp_min(1.0)
        height = height.clamp_min(HEIGHT_FLOOR)  # exact above 1 cm, as the analytic margin's LIP height
        xi = lam[..., _VELOCITY][..., :2] * torch.sqrt(height / self.gravity)[..., None]
        xy = points[..., :2]
        pair_normals = []
        for a, b in FOOT_PAIRS:
            w = xy[..., b, :] - xy[..., a, :]
            n = torch.stack([w[..., 1], -w[..., 0]], dim=-1) / torch.sqrt((w * w).sum(-1) + PAIR_EPS**2)[..., None]
            pair_normals += [n, -n]
        fixed = self.fixed.expand(*lam.shape[:-1], self.n_fixed, 2)
        directions = torch.cat([fixed, torch.stack(pair_normals, dim=-2)], dim=-2)
        return xy, contacts, xi, directions, height

    def load_shift(self, lam: torch.Tensor, height: torch.Tensor) -> torch.Tensor:
        """s (..., 2) [m]: where the static load moves the feasible CoM region (module docstring)."""
        m, g = self.mass, self.gravity
        acc, force_ext = lam[..., LAMBDA_SLICES["com_acc"]], lam[..., LAMBDA_SLICES["ext_force"]]
        torque = lam[..., LAMBDA_SLICES["ext_torque"]]
        force = m * acc - force_ext
        fz = (force[..., 2] + m * g).clamp_min(FORCE_FLOOR * m * g)
        return torch.stack(
            [(height * force[..., 0] - torque[..., 1]) / fz, (height * force[..., 1] + torque[..., 0]) / fz], dim=-1
        )

    def support(self, lam: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(directions (..., D, 2), learned support values h (..., D) [m], capture point xi (..., 2) [m])."""
        x = (lam - self.input_mean) / self.input_std
        return self._support(lam, x)

    def _support(self, lam: torch.Tensor, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        xy, contacts, xi, directions, height = self._geometry(lam)
        # prior_k = max over stance feet of u_k . P_i: (..., D, 4) values, swing feet pushed down
        values = torch.einsum("...dj,...ij->...di", directions, xy) - SWING_PENALTY * (1.0 - contacts)[..., None, :]
        prior = values.amax(-1)
        if self.prior == "shifted":
            prior = prior + (directions * self.load_shift(lam, height)[..., None, :]).sum(-1)
        residual = self.trunk(x[..., self.trunk_inputs])
        return directions, prior + self.support_scale * residual, xi

    def margin_from(self, lam: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        directions, h, xi = self._support(lam, x)
        return (h - (directions * xi[..., None, :]).sum(-1)).amin(-1)

    def normalized_forward(self, x: torch.Tensor) -> torch.Tensor:
        """The margin in normalised units from normalised lambda (what the training loss sees)."""
        lam = x * self.input_std + self.input_mean
        return (self.margin_from(lam, x) - self.output_scale[0]) / self.output_scale[1]

    def forward(self, lam: torch.Tensor) -> torch.Tensor:
        return self.margin_from(lam, (lam - self.input_mean) / self.input_std)


def build_support_model(
    lam_train: np.ndarray,
    margin_train: np.ndarray,
    foot_radius: float,
    gravity: float,
    directions: int = DEFAULT_DIRECTIONS,
    prior: str = "polygon",
    mass: float = 1.0,
) -> SupportMarginMLP:
    """A fresh support model whose normalisation is fitted on ``lam_train`` (N, 47) and ``margin_train`` (N,)
    (``mass`` [kg]: the robot's, for ``prior="shifted"``)."""
    if lam_train.ndim != 2 or lam_train.shape[1] != LAMBDA_DIM or len(margin_train) != len(lam_train):
        raise ValueError(
            f"lam_train (N, {LAMBDA_DIM}) and margin_train (N,) needed, got {lam_train.shape}, {margin_train.shape}"
        )
    input_mean, input_std = input_scaling(lam_train)
    return SupportMarginMLP(
        input_mean=input_mean,
        input_std=input_std,
        output_mean=float(margin_train.mean()),
        output_std=float(margin_train.std()),
        foot_radius=foot_radius,
        gravity=gravity,
        directions=directions,
        prior=prior,
        mass=mass,
    )
