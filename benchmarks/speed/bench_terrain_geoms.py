"""Benchmark: the rough terrain as a heightfield (today) against the same terrain as box geoms, on ``mujoco.batch``.

Usage:
    python benchmarks/speed/bench_terrain_geoms.py [--robot anymal_c] [--num-envs 128] [--steps 200] [--rounds 3]
        [--json PATH]

Why: on a heightfield each foot sphere touching the ground gets up to three contacts (one per prism it overlaps),
where a plane or a box top gives one, and the rough env steps at about half the flat env's speed (BENCHMARKS,
"Rough ground"). Before the terrain is described once and built either way, this measures what boxes would buy.

Three models of one robot, stepped the same way (the env's decimation, the same seeded random servo targets around the
standing keyframe, ``mjSTAGE_ACC`` after each step as the env asks, robots dropped from 2 cm above the ground either
at the same random places over the tiles, where a walking policy's feet meet edges and steps, or on the tiles' flat
spawn pads, where the environments reset them):

* ``plane``: the flat scene (the speed the rough terrain is measured against);
* ``heightfield``: the environments' rough terrain (``EnvConfig(terrain="rough")``'s grid, its MuJoCo hfield);
* ``boxes``: the same grid as axis-aligned boxes standing on z = 0, one per maximal rectangle of grid cells of one
  height (greedy merge), a cell's top the highest of its four nodes. Step-like tiles (stairs, bricks, side steps,
  obstacles) are exact up to their risers (vertical here, one cell wide and sloped in the heightfield); inclines
  become 5 cm terraces (rises of at most 1.3 cm at 15 degrees), more boxes than tilted ones would need, so this model's
  speed is a lower bound for a box terrain.

Reported: env-steps/s (medians of interleaved rounds, and the ratio to the plane), the number of boxes, and from a
128-step MjData rollout of 8 robots with the same actions, one thread: contacts per world, the time of one
``mj_step`` and of the collision detection inside it (``mj_collision`` re-run on the same state).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness

import mujoco
import numpy as np
from mujoco import batch

from benchmarks.harness import interleave, machine_line, parser, print_table, summarise, write_record
from margin_rl.envs.config import EnvConfig
from margin_rl.envs.scene import build_model
from margin_rl.envs.terrain import Terrain, flat_terrain, rough_terrain
from margin_rl.robot import Robot, load_robot
from margin_rl.robot import mjcf_names as names


def cell_rectangles(cells: np.ndarray) -> list[tuple[int, int, int, int, float]]:
    """Maximal rectangles (r0, r1, c0, c1, height) covering a grid of cell heights, inclusive bounds, greedily: from
    the first uncovered cell in row-major order, extend along the row, then down while the whole span matches."""
    rows, cols = cells.shape
    covered = np.zeros(cells.shape, dtype=bool)
    rectangles = []
    for r in range(rows):
        c = 0
        while c < cols:
            if covered[r, c]:
                c += 1
                continue
            height = cells[r, c]
            c1 = c
            while c1 + 1 < cols and not covered[r, c1 + 1] and cells[r, c1 + 1] == height:
                c1 += 1
            r1 = r
            while (
                r1 + 1 < rows and not covered[r1 + 1, c : c1 + 1].any() and np.all(cells[r1 + 1, c : c1 + 1] == height)
            ):
                r1 += 1
            covered[r : r1 + 1, c : c1 + 1] = True
            rectangles.append((r, r1, c, c1, float(height)))
            c = c1 + 1
    return rectangles


def box_model(robot_xml: str, terrain: Terrain) -> tuple[mujoco.MjModel, int]:
    """The robot on ``terrain``'s grid as boxes (module docstring); returns the model and its number of boxes."""
    h = terrain.heights
    cells = np.maximum.reduce([h[:-1, :-1], h[1:, :-1], h[:-1, 1:], h[1:, 1:]])
    res, (x0, y0) = terrain.resolution, terrain.origin
    geoms = []
    for k, (r0, r1, c0, c1, top) in enumerate(cell_rectangles(np.round(cells, 6))):
        cx, cy = x0 + (c0 + c1 + 1) * res / 2, y0 + (r0 + r1 + 1) * res / 2
        hx, hy, hz = (c1 - c0 + 1) * res / 2, (r1 - r0 + 1) * res / 2, max(top, 1e-3) / 2
        name = f' name="{names.FLOOR_GEOM}"' if k == 0 else ""
        geoms.append(
            f'<geom{name} type="box" pos="{cx:.4f} {cy:.4f} {hz:.4f}" size="{hx:.4f} {hy:.4f} {hz:.4f}" '
            'contype="1" conaffinity="1" condim="3" friction="1.0 0.005 0.0001" priority="1"/>'
        )
    xml = f"""
<mujoco model="boxes">
  <include file="{robot_xml}"/>
  <worldbody>
    {chr(10).join(geoms)}
  </worldbody>
</mujoco>"""
    return mujoco.MjModel.from_xml_string(xml), len(geoms)


def drop_points(terrain: Terrain, count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, 3) random places over the tiles (the grid inside its flat border), at the ground's height."""
    n = terrain.heights.shape[0] if terrain.heights is not None else 1
    inner = (n - 1) * terrain.resolution / 2 - 16.0  # the default border is flat ground
    xy = rng.uniform(-inner, inner, size=(count, 2))
    return np.column_stack([xy, terrain.height(xy)])


def runner(
    model: mujoco.MjModel, places: np.ndarray, actions: np.ndarray, decimation: int, scale: float
) -> Callable[[int], float]:
    key = model.key(names.STANDING_KEYFRAME).id
    sims = batch.Batch(model, nsim=len(places), nthread=0)
    qpos, ctrl = sims.bind("qpos"), sims.bind("ctrl")
    start_height = model.key_qpos[key][names.BASE_POSITION_QPOS][2] + 0.02

    def run(_round: int) -> float:
        sims.reset(keyframe=key)
        qpos[:, 0:2] = places[:, :2]
        qpos[:, 2] = places[:, 2] + start_height
        sims.forward()
        t0 = time.perf_counter()
        for a in actions:
            ctrl[:] = model.key_ctrl[key] + scale * a
            sims.step(nstep=decimation, stage=mujoco.mjtStage.mjSTAGE_ACC)
        return len(places) * len(actions) / (time.perf_counter() - t0)

    return run


def single_world_profile(
    model: mujoco.MjModel, places: np.ndarray, actions: np.ndarray, decimation: int, scale: float
) -> dict[str, float]:
    """Contacts per world, and the time of one ``mj_step`` and of one ``mj_collision`` (the collision detection
    alone, re-run on the same state) [us], means over a 128-policy-step MjData rollout of each of the first 8 places."""
    key = model.key(names.STANDING_KEYFRAME).id
    counts, step_s, collision_s, calls = [], 0.0, 0.0, 0
    for i in range(min(8, len(places))):
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, key)
        data.qpos[0:2] = places[i, :2]
        data.qpos[2] = places[i, 2] + model.key_qpos[key][2] + 0.02
        for a in actions[:128, i]:
            data.ctrl[:] = model.key_ctrl[key] + scale * a
            for _ in range(decimation):
                t0 = time.perf_counter()
                mujoco.mj_step(model, data)
                t1 = time.perf_counter()
                mujoco.mj_collision(model, data)
                collision_s += time.perf_counter() - t1
                step_s += t1 - t0
                calls += 1
            counts.append(data.ncon)
    return {
        "contacts": float(np.mean(counts)),
        "step_us": 1e6 * step_s / calls,
        "collision_us": 1e6 * collision_s / calls,
    }


@dataclass(frozen=True)
class RoughWorkload:
    """What the rough-terrain benchmarks step: the command line's settings, the environments' rough terrain of seed 0
    for ``args.robot``, random drop places over its tiles and seeded random servo offsets (``rng`` continues the
    draws)."""

    args: argparse.Namespace
    config: EnvConfig
    robot: Robot
    terrain: Terrain
    places: np.ndarray  # (num_envs, 3)
    actions: np.ndarray  # (steps, num_envs, 12)
    rng: np.random.Generator


def rough_workload(doc: str | None) -> RoughWorkload:
    """Parse the rough-terrain benchmarks' options (``--robot``, ``--num-envs``, ``--steps``, ``--rounds``, ``--json``;
    ``doc`` the help text) and build their workload."""
    args_parser = parser(doc)
    args_parser.add_argument("--robot", default="anymal_c")
    args_parser.add_argument("--num-envs", type=int, default=128)
    args_parser.add_argument("--steps", type=int, default=200)
    args_parser.add_argument("--rounds", type=int, default=3)
    args = args_parser.parse_args()
    config = EnvConfig(robot=args.robot, terrain="rough")
    terrain = rough_terrain(config.terrain_config, 0)
    rng = np.random.default_rng(0)
    places = drop_points(terrain, args.num_envs, rng)
    actions = rng.uniform(-0.3, 0.3, size=(args.steps, args.num_envs, 12))
    return RoughWorkload(args, config, load_robot(args.robot), terrain, places, actions, rng)


def main() -> None:
    work = rough_workload(__doc__)
    args, config, robot, terrain, places, actions, rng = (
        work.args, work.config, work.robot, work.terrain, work.places, work.actions, work.rng
    )  # fmt: skip
    t0 = time.perf_counter()
    boxes, count = box_model(Path(robot.xml_path).as_posix(), terrain)
    build_s = time.perf_counter() - t0
    heightfield = build_model(robot, terrain, config.terrain_config)
    pads = terrain.spawn_points[rng.integers(0, len(terrain.spawn_points), size=args.num_envs)]
    models = {
        "plane (flat scene)": (build_model(robot, flat_terrain(), config.terrain_config), np.zeros_like(places)),
        "heightfield, random places over the tiles": (heightfield, places),
        f"boxes ({count:,} geoms), random places over the tiles": (boxes, places),
        "heightfield, spawn pads": (heightfield, pads),
        f"boxes ({count:,} geoms), spawn pads": (boxes, pads),
    }
    runners = {
        name: runner(model, where, actions, config.decimation, config.action_scale)
        for name, (model, where) in models.items()
    }
    rates = {name: summarise(values) for name, values in interleave(runners, args.rounds).items()}
    profiles = {
        name: single_world_profile(model, where, actions, config.decimation, config.action_scale)
        for name, (model, where) in models.items()
    }
    plane = rates[next(iter(rates))].median
    print(machine_line())
    print(f"{args.robot}, {args.num_envs} worlds, {args.steps} policy steps, {args.rounds} interleaved rounds")
    print(f"box model built in {build_s:.1f} s\n")
    print_table(
        ("ground", "env-steps/s (median)", "range", "of the plane", "contacts/world", "mj_step [us]", "collision [us]"),
        [
            (
                name,
                f"{r.median:,.0f}",
                f"{r.low:,.0f}–{r.high:,.0f}",
                f"{r.median / plane:.2f}",
                f"{profiles[name]['contacts']:.1f}",
                f"{profiles[name]['step_us']:.1f}",
                f"{profiles[name]['collision_us']:.1f}",
            )
            for name, r in rates.items()
        ],
    )
    write_record(
        args.json,
        "terrain_geoms",
        args,
        {"env_steps_per_s": rates, "single_world": profiles, "boxes": count, "box_model_build_s": build_s},
    )


if __name__ == "__main__":
    main()
