"""What a step asks of the terrain under the robot, in one lookup: the ground under the base, the knees, the feet's
normal stencils and soles, the height scan's points (:class:`GroundQueries`). On a device every terrain lookup is some
thirty operations (kernel launches from Python), whatever the number of points, so a step gathers all its points,
looks them up once and splits the heights; each part equals the query made alone, bit for bit (a height is computed
point by point)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from margin_rl.arrays import namespace, reshaped, rotate, split_columns
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.observations import HEIGHT_SCAN_CLIP
from margin_rl.envs.step_data import SimulationState
from margin_rl.envs.terrain import (
    STEP_EDGE_RISE,
    Terrain,
    spread_of_heights,
    spread_stencil,
    vertical_normals,
)


@dataclass(frozen=True)
class GroundQueries:
    """The terrain lookups of a step (module docstring); ``scan_offsets`` (P, 3): the height scan's points in the
    heading frame, an array of the core's kind."""

    terrain: Terrain
    foot_radius: float  # [m], the sole disc an edge touchdown is judged on
    standing_height: float  # [m], the height scan's zero
    scan_offsets: Any

    def heights(self, state: SimulationState, config: EnvConfig) -> dict[str, Any]:
        """The ground heights [m] the step of ``config`` looks up: under the base ("base", (N,)), the knees
        ("knees", (N, 4): with the knee-clearance term), the feet's normal stencils ("normals", (N, 4, 4): with
        terrain normals in lambda) and soles ("soles", (N, 4, 9)) on rough ground, and the height scan's points
        ("scan", (N, P): with the scan)."""
        terrain = self.terrain
        feet_xy = state.feet[..., :2]
        groups = {"base": ((), lambda: state.base_pos[:, :2])}  # name: (shape, its points (N, *shape, 2))
        if "knee_clearance" in config.reward_weights:
            groups["knees"] = ((4,), lambda: state.knees[..., :2])
        if not terrain.is_flat:
            if config.margin_normals != "vertical":
                groups["normals"] = ((4, 4), lambda: terrain.normal_stencil(feet_xy))
            groups["soles"] = ((4, 9), lambda: spread_stencil(feet_xy, self.foot_radius))
        if config.height_scan:
            groups["scan"] = self._scan_group(state)
        return self.lookup(groups, state.base_pos)

    def reset_heights(self, state: SimulationState, config: EnvConfig, foot_offsets: Any) -> dict[str, Any]:
        """The ground heights [m] a reset's first observations look up, in one lookup: the height scan's points
        ("scan", (N, P): with the scan) and, for the critic, the points ``foot_offsets`` (K, 2) around each foot
        ("around_feet", (N, 4, K): with privileged observations; :meth:`heights_around`)."""
        groups = {}
        if config.height_scan:
            groups["scan"] = self._scan_group(state)
        if config.privileged_observations:
            shape = (4, int(foot_offsets.shape[0]))
            groups["around_feet"] = (shape, lambda: around_points(state.feet, foot_offsets))
        return self.lookup(groups, state.base_pos)

    def lookup(self, groups: dict[str, tuple[tuple[int, ...], Any]], reference: Any) -> dict[str, Any]:
        """The ground heights [m] under named groups of points, looked up at once: ``groups``: name -> (shape,
        a function returning its points (n, *shape, 2), called only on rough ground); returns name -> (n, *shape).
        ``reference``: an (n, ...) array of the core's kind and device (flat ground's zeros)."""
        if not groups:
            return {}
        xp, n = namespace(reference), int(reference.shape[0])
        shapes = {name: shape for name, (shape, _) in groups.items()}
        sizes = [math.prod(shape) for shape in shapes.values()]
        if self.terrain.is_flat:  # the ground is at 0 everywhere: nothing to look up
            heights = xp.zeros((n, sum(sizes)), dtype=xp.float64, device=reference.device)
        else:
            points = [
                reshaped(points(), (n, size, 2)) for (_, points), size in zip(groups.values(), sizes, strict=True)
            ]
            heights = self.terrain.height(xp.concat(points, axis=1))
        pieces = split_columns(heights, sizes) if len(sizes) > 1 else (heights,)
        return {name: reshaped(piece, (n, *shape)) for (name, shape), piece in zip(shapes.items(), pieces, strict=True)}

    def _scan_group(self, state: SimulationState) -> tuple[tuple[int, ...], Any]:
        """The height scan's points as a group of :meth:`lookup`: ((P,), a function returning them)."""
        return (int(self.scan_offsets.shape[0]),), lambda: self.scan_points(state)

    def scan_points(self, state: SimulationState) -> Any:
        """(N, P, 2) the height scan's points (around the base, turned with its yaw) [m]."""
        xp, n = namespace(state.base_pos), int(state.base_pos.shape[0])
        offsets = xp.broadcast_to(self.scan_offsets, (n, *self.scan_offsets.shape))
        return (state.base_pos[:, None, :] + rotate(state.heading_rot, offsets))[..., :2]

    def height_scan(self, state: SimulationState, heights: Any = None) -> Any:
        """(N, P) base height above the terrain at the scan points (``heights`` (N, P) the ground there, looked up
        here if None) minus the robot's standing height, clipped to +-HEIGHT_SCAN_CLIP [m]."""
        if heights is None:
            heights = self.terrain.height(self.scan_points(state))
        below = state.base_pos[:, None, 2] - heights - self.standing_height
        return namespace(below).clip(below, -HEIGHT_SCAN_CLIP, HEIGHT_SCAN_CLIP)

    def heights_around(self, points: Any, offsets: Any, ground: Any = None) -> Any:
        """(N, k K) the height of ``points`` (N, k, 3) above the ground at each of ``offsets`` (K, 2) [m] around them
        (the critic's terrain around the feet); ``ground`` (N, k, K): the ground there where it was looked up
        already (:meth:`reset_heights`)."""
        if ground is None:
            ground = self.terrain.height(around_points(points, offsets))
        heights = points[:, :, None, 2] - ground
        return namespace(heights).reshape(heights, (int(points.shape[0]), -1))

    def contact_normals(self, state: SimulationState, ground: dict[str, Any]) -> Any:
        """(N, 4, 3) world-frame normals under the feet (the terrain's, from the step's ``ground`` heights, or
        vertical where it looked none up: vertical by choice, or flat ground)."""
        if "normals" not in ground:
            return vertical_normals(state.feet[..., :2])
        return self.terrain.normal_from_heights(ground["normals"])

    def edge_touchdowns(self, touchdown: Any, ground: dict[str, Any]) -> Any:
        """(N, 4) touchdowns on a step edge: the ground under the sole spreads by more than STEP_EDGE_RISE; none on
        flat ground."""
        if "soles" not in ground:
            return namespace(touchdown).zeros_like(touchdown)
        return touchdown & (spread_of_heights(ground["soles"]) > STEP_EDGE_RISE)


def around_points(points: Any, offsets: Any) -> Any:
    """(N, k, K, 2) the horizontal points ``offsets`` (K, 2) [m] around each of ``points`` (N, k, 3)."""
    return points[:, :, None, :2] + offsets[None, None]
