"""Benchmark: which robot parts cost what on the rough heightfield, and the speed of colliding fewer of them.

Usage:
    python benchmarks/speed/bench_terrain_contacts.py [--robot anymal_c] [--num-envs 128] [--steps 200]
        [--rounds 3] [--json PATH]

Why: the rough env's target is 80 % of the flat env's speed on ``mujoco.batch``, and collision detection against the
heightfield is most of a rough physics step (BENCHMARKS, "Rough terrain in MuJoCo"). Today every collision geom of the
robot is tested against the terrain (44 on ANYmal C). Some of the field's MuJoCo rough-terrain tasks collide only the
feet with the ground (MuJoCo Playground's "feetonly" scenes); others keep every part (mjlab). This measures what each
robot part costs before the environments' collision set is chosen.

The parts, read from the MJCF by name (:mod:`margin_rl.robot.mjcf_names`): the foot spheres, the shanks' other geoms,
the thighs', the hips' and the base's. Collision sets are cumulative: feet; feet and shanks; feet, shanks and thighs;
every geom (today). A set is built by moving the heightfield to its own collision bit and giving it only to the
set's geoms (``contype``/``conaffinity``), so that nothing else about the model changes.

Reported, for each set:

* collision detection [us per world]: ``mj_collision`` alone on the same recorded states (a rollout of the full
  model: robots dropped at random places over the tiles, the env's decimation, random servo targets around the
  standing keyframe, every 4th policy step), medians of interleaved rounds: the cost of the parts, state for state;
* contacts per world on those states, and the share of states where a part outside the set touches the ground (what
  that set would not see: with random servo targets a lower bound of a walking policy's, which meets step edges);
* env-steps/s on ``mujoco.batch`` (the runner of ``bench_terrain_geoms.py``: same places and actions), medians of
  interleaved rounds, and the ratio to the flat scene's plane measured in the same rounds.
"""

from __future__ import annotations

import copy
import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: benchmarks.harness
sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_terrain_geoms: the drop points and the runner

import mujoco
import numpy as np
from bench_terrain_geoms import rough_workload, runner

from benchmarks.harness import interleave, machine_line, print_table, summarise, write_record
from margin_rl.envs.scene import build_model
from margin_rl.envs.terrain import flat_terrain
from margin_rl.robot import mjcf_names as names
from margin_rl.robot.model import LEGS

PARTS: tuple[str, ...] = ("feet", "shanks", "thighs", "hips", "base")
"""The robot's parts, from the ground up; the collision sets are their cumulative unions."""

TERRAIN_BIT = 2
"""The collision bit a set's geoms and the heightfield share (the MJCF's geoms use bit 1)."""


def robot_parts(model: mujoco.MjModel) -> dict[str, list[int]]:
    """Part -> the ids of its collision geoms (``contype`` or ``conaffinity`` set), read by the MJCF's names: the foot
    spheres, the shank bodies' other geoms, then the shanks' parent bodies (thighs), theirs (hips), and the base."""
    colliding = {g for g in range(model.ngeom) if model.geom_contype[g] or model.geom_conaffinity[g]}
    feet = {model.geom(names.foot_geom(leg)).id for leg in LEGS}
    shanks = {model.body(names.shank_body(leg)).id for leg in LEGS}
    thighs = {int(model.body_parentid[b]) for b in shanks}
    hips = {int(model.body_parentid[b]) for b in thighs}
    bodies = {"shanks": shanks, "thighs": thighs, "hips": hips, "base": {model.body(names.BASE_BODY).id}}
    parts = {"feet": sorted(feet)}
    for part, ids in bodies.items():
        parts[part] = sorted(g for g in colliding - feet if int(model.geom_bodyid[g]) in ids)
    return parts


def colliding_only(model: mujoco.MjModel, geoms: list[int]) -> mujoco.MjModel:
    """A copy of ``model`` whose floor collides with ``geoms`` only (see the module docstring)."""
    result = copy.copy(model)
    floor = result.geom(names.FLOOR_GEOM).id
    result.geom_contype[floor], result.geom_conaffinity[floor] = 0, TERRAIN_BIT
    for g in geoms:
        result.geom_contype[g] |= TERRAIN_BIT
    return result


def recorded_states(
    model: mujoco.MjModel, places: np.ndarray, steps: int, decimation: int, scale: float, rng: np.random.Generator
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(qpos, qvel) every 4th policy step of one-world rollouts from each of ``places`` with random servo targets."""
    key = model.key(names.STANDING_KEYFRAME).id
    states = []
    for place in places:
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, key)
        data.qpos[0:2] = place[:2]
        data.qpos[2] = place[2] + model.key_qpos[key][names.BASE_POSITION_QPOS][2] + 0.02
        for step in range(steps):
            data.ctrl[:] = model.key_ctrl[key] + scale * rng.uniform(-0.3, 0.3, size=model.nu)
            for _ in range(decimation):
                mujoco.mj_step(model, data)
            if step % 4 == 0:
                states.append((data.qpos.copy(), data.qvel.copy()))
    return states


def collision_timer(model: mujoco.MjModel, states: list[tuple[np.ndarray, np.ndarray]]) -> Callable[[int], float]:
    """A runner: ``mj_collision`` on every state, microseconds per state."""
    data = mujoco.MjData(model)

    def run(_round: int) -> float:
        elapsed = 0.0
        for qpos, qvel in states:
            data.qpos[:], data.qvel[:] = qpos, qvel
            mujoco.mj_kinematics(model, data)
            t0 = time.perf_counter()
            mujoco.mj_collision(model, data)
            elapsed += time.perf_counter() - t0
        return 1e6 * elapsed / len(states)

    return run


def touching(model: mujoco.MjModel, states: list[tuple[np.ndarray, np.ndarray]], parts: dict[str, list[int]]):
    """Mean contacts per state, and per part the share of states where one of its geoms touches the floor."""
    data = mujoco.MjData(model)
    floor = model.geom(names.FLOOR_GEOM).id
    part_of = {g: part for part, geoms in parts.items() for g in geoms}
    counts, touched = [], {part: 0 for part in parts}
    for qpos, qvel in states:
        data.qpos[:], data.qvel[:] = qpos, qvel
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        counts.append(data.ncon)
        hit = set()
        for contact in data.contact[: data.ncon]:
            other = contact.geom2 if contact.geom1 == floor else contact.geom1
            if floor in (contact.geom1, contact.geom2) and other in part_of:
                hit.add(part_of[other])
        for part in hit:
            touched[part] += 1
    return float(np.mean(counts)), {part: n / len(states) for part, n in touched.items()}


def main() -> None:
    work = rough_workload(__doc__)
    args, config, robot, terrain, places, actions, rng = (
        work.args, work.config, work.robot, work.terrain, work.places, work.actions, work.rng
    )  # fmt: skip
    full = build_model(robot, terrain, config.terrain_config)
    parts = robot_parts(full)
    sets: dict[str, mujoco.MjModel] = {}
    for k in range(1, len(PARTS)):
        label = " + ".join(PARTS[:k])
        geoms = [g for part in PARTS[:k] for g in parts[part]]
        sets[f"{label} ({len(geoms)} geoms)"] = colliding_only(full, geoms)
    sets[f"every part ({sum(map(len, parts.values()))} geoms, today)"] = full
    states = recorded_states(full, places[:16], 128, config.decimation, config.action_scale, rng)
    collision = {
        name: summarise(v)
        for name, v in interleave(
            {name: collision_timer(model, states) for name, model in sets.items()}, args.rounds, alternate=True
        ).items()
    }
    contacts, touched = touching(full, states, parts)
    per_set_contacts = {name: touching(model, states, parts)[0] for name, model in sets.items()}
    plane_name = "plane (flat scene)"
    speed_models = {plane_name: (build_model(robot, flat_terrain(), config.terrain_config), np.zeros_like(places))}
    speed_models.update({name: (model, places) for name, model in sets.items()})
    rates = {
        name: summarise(v)
        for name, v in interleave(
            {
                name: runner(model, where, actions, config.decimation, config.action_scale)
                for name, (model, where) in speed_models.items()
            },
            args.rounds,
            alternate=True,
        ).items()
    }
    plane = rates[plane_name].median
    print(machine_line())
    print(
        f"{args.robot}, {len(states)} recorded states, {args.num_envs} worlds x {args.steps} policy steps, "
        f"{args.rounds} interleaved rounds"
    )
    print(
        "states where the part touches the ground (full model): "
        + ", ".join(f"{part} {share:.1%}" for part, share in touched.items())
        + f"; contacts per state {contacts:.1f}\n"
    )
    print_table(
        ("terrain collides with", "collision [us/world]", "contacts/world", "env-steps/s (median)", "of the plane"),
        [
            (
                name,
                f"{collision[name].median:.1f}" if name in collision else "",
                f"{per_set_contacts[name]:.1f}" if name in per_set_contacts else "",
                f"{r.median:,.0f}",
                f"{r.median / plane:.2f}",
            )
            for name, r in rates.items()
        ],
    )
    write_record(
        args.json,
        "terrain_contacts",
        args,
        {
            "parts": {part: [full.geom(g).name or str(g) for g in geoms] for part, geoms in parts.items()},
            "collision_us": collision,
            "contacts_per_world": per_set_contacts,
            "touching_share": touched,
            "env_steps_per_s": rates,
        },
    )


if __name__ == "__main__":
    main()
