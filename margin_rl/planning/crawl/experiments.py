"""Seed 004 §VI on one robot, end to end: the triple-stance tests, the measures along a crawl, loaded and
hindered crawls, and the summary ``crawl.json``.

:func:`run_experiments` runs, per planner (``"heuristic"``, ``"cwc"``, ``"fwp"``):

* §VI-A, :mod:`~margin_rl.planning.crawl.stance_tests`: the displacement and the vertical disturbance
  test from the planner's triple stance;
* the *vertical capacity map* of that triple stance (the model's side of the vertical test): for CoM
  positions on a grid over the support triangle, the downward force on the base origin at which the FWP
  factor reaches zero (bisection on :func:`~margin_rl.planning.crawl.evaluation.fwp_factor`), with the
  three planners' poses on it;
* §VI-C: 12-step crawls with the ``load_kg`` load, with a heavier load (``heavy_load_kg``), with a
  hindered joint (``hindered``) plus the load, and on rough ground (level tiles up to ``rough_max_height``)
  with the load: control steps with a servo at its torque limit, falls, the base-motion durations
  chosen, the planners' solve times and the FWP build times;

and, once, §VI-B: the CWC margin and the FWP factor sampled along the heuristic crawl's triple stances
with and without the load. Every number in ``crawl.json`` is measured here; nothing is carried over.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from margin_rl.atomic import atomic_savez, atomic_write_text
from margin_rl.planning.crawl.evaluation import cwc_margin, fwp_factor
from margin_rl.planning.crawl.gait import CrawlGait, support_triangle, triangle_halfplanes
from margin_rl.planning.crawl.planners import (
    PLANNER_NAMES,
    CrawlPlanner,
    WrenchPolytopePlanner,
    make_planner,
    shrunk_triangle_vertices,
)
from margin_rl.planning.crawl.polytopes import StanceSnapshot
from margin_rl.planning.crawl.simulation import CrawlSimulation, HinderedJoint
from margin_rl.planning.crawl.stance_tests import (
    TESTED_SWING,
    DisplacementTest,
    VerticalDisturbanceTest,
    displacement_test,
    triple_stance,
    vertical_disturbance_test,
)
from margin_rl.planning.crawl.terrain import TileTerrain
from margin_rl.provenance import git_commit
from margin_rl.robot import Robot, load_robot

CRAWL_STEPS = 12
"""Steps (three cycles) of every crawl of §VI-B and §VI-C."""


@dataclass(frozen=True)
class ExperimentSettings:
    """What :func:`run_experiments` runs (frozen; the CLI's options)."""

    robot: str = "anymal_c"
    load_kg: float = 20.0
    heavy_load_fraction: float = 1.25  # the heavier load, as a fraction of the robot's mass
    hindered_leg: str = "LF"
    hindered_joint: int = 2  # KFE
    hindered_fraction: float = 0.6
    rough_max_height: float = 0.05  # tiles of the rough crawl: tops up to this height [m]
    max_vertical_force: float = 2000.0
    capacity_grid: int = 15  # grid points per axis of the vertical capacity map
    steps: int = CRAWL_STEPS


def make_planners(robot: Robot, gait: CrawlGait) -> dict[str, CrawlPlanner]:
    """The three planners, the optimising ones with the time price calibrated on the unloaded first step."""
    reference = CrawlSimulation(robot, gait)
    task = reference.task("LH")
    planners: dict[str, CrawlPlanner] = {}
    for name in PLANNER_NAMES:
        planner = make_planner(name, robot, gait)
        if isinstance(planner, WrenchPolytopePlanner):
            planner.calibrate(task)
        planners[name] = planner
    return planners


def crawl(
    robot: Robot, gait: CrawlGait, planner: CrawlPlanner, steps: int, load_kg: float = 0.0,
    hindered: HinderedJoint | None = None, terrain: TileTerrain | None = None,
) -> tuple[CrawlSimulation, dict[str, Any]]:  # fmt: skip
    """Run ``steps`` crawl steps; returns the simulation and its summary (limits, durations, timings)."""
    sim = CrawlSimulation(robot, gait, load_kg=load_kg, hindered=hindered, terrain=terrain)
    started = len(sim.trace.time)
    error = ""
    try:
        for step in range(steps):
            sim.crawl_step(step, planner)
    except ValueError as exc:  # a pose the planner cannot handle (e.g. the robot fell): reported, not hidden
        error = str(exc)
    trace = sim.trace.arrays()
    at_limit = trace["at_limit"][started:].any(axis=1)
    limits = sim.model.actuator_forcerange[:, 1]
    ratio = np.abs(trace["torque"][started:]) / limits
    base_height = trace["qpos"][started:, 2]
    plans = sim.plans
    summary = {
        "steps_completed": len(plans) if not error else len(plans) - 1,
        "error": error,
        "torque_limit_steps": int(at_limit.sum()),
        "torque_limit_seconds": float(at_limit.sum() * sim.model.opt.timestep),
        "max_torque_ratio": float(ratio.max()),
        "fell": bool(base_height.min() < 0.5 * robot.standing_height),
        "distance_m": float(sim.com()[0] - trace["com"][0][0]),
        "duration_s": float(trace["time"][-1] - trace["time"][started]),
        "base_motion_durations_s": [p.duration for p in plans],
        "solve_ms": [1e3 * p.solve_seconds for p in plans],
        "polytope_ms": [1e3 * p.polytope_seconds for p in plans],
        "iterations": [p.iterations for p in plans],
        "converged": [p.success for p in plans],
    }
    return sim, summary


def along_crawl_measures(sim: CrawlSimulation, every: int = 20) -> dict[str, list[float]]:
    """§VI-B: the CWC margin and the FWP factor at every ``every``-th control step of the swing phases
    (the triple stances) of a finished crawl, re-simulated from the recorded states."""
    trace = sim.trace.arrays()
    times, margins, factors, legs = [], [], [], []
    for k in range(0, len(trace["time"]), every):
        phase = str(trace["phase"][k])
        if not phase.startswith("swing:"):
            continue
        snapshot = sim.replayed_snapshot(trace["qpos"][k], trace["stance"][k])
        times.append(float(trace["time"][k]))
        legs.append(phase.split(":")[1])
        margins.append(cwc_margin(sim.robot, snapshot))
        factors.append(fwp_factor(sim.robot, snapshot))
    return {"time": times, "swing": legs, "cwc_margin": margins, "fwp_factor": factors}


def vertical_capacity(robot: Robot, snapshot: StanceSnapshot, base_offset: np.ndarray, high: float = 4000.0) -> float:
    """Downward force [N] on the base origin (at ``base_offset`` from the CoM) at which s reaches zero
    (bisection to 2 N, s being concave along the push); 0 if the pose is infeasible without it, NaN if a
    foot is out of reach, ``high`` if s never reaches zero."""

    def factor(force: float) -> float:
        d = np.array([0.0, 0.0, -force])
        pushed = replace(
            snapshot, ext_force=snapshot.ext_force + d, ext_torque=snapshot.ext_torque + np.cross(base_offset, d)
        )
        return fwp_factor(robot, pushed)

    at_rest = factor(0.0)
    if math.isnan(at_rest):
        return math.nan
    if at_rest <= 0:
        return 0.0
    if factor(high) > 0:
        return high
    low = 0.0
    while high - low > 2.0:
        mid = 0.5 * (low + high)
        low, high = (mid, high) if factor(mid) > 0 else (low, mid)
    return 0.5 * (low + high)


def capacity_map(sim: CrawlSimulation, grid: int) -> dict[str, Any]:
    """The vertical capacity over CoM positions in the held triple stance's support triangle, shrunk by the
    crawl's stability margin (grid x grid over its bounding box; NaN outside it or out of the legs' reach)."""
    snapshot = sim.snapshot()
    base_offset = sim.base_offset()
    triangle = support_triangle(snapshot.feet[:, :2], TESTED_SWING)
    a, b = triangle_halfplanes(triangle, sim.gait.stability_margin)
    inner = shrunk_triangle_vertices(a, b)
    xs = np.linspace(inner[:, 0].min(), inner[:, 0].max(), grid)
    ys = np.linspace(inner[:, 1].min(), inner[:, 1].max(), grid)
    values = np.full((grid, grid), np.nan)
    for i, y in enumerate(ys):
        for j, x in enumerate(xs):
            if np.all(a @ np.array([x, y]) <= b + 1e-9):
                moved = replace(snapshot, com=np.array([x, y, snapshot.com[2]]))
                values[i, j] = vertical_capacity(sim.robot, moved, base_offset)
    best = np.unravel_index(np.nanargmax(values), values.shape)
    return {
        "x": xs.tolist(), "y": ys.tolist(), "capacity_N": values.tolist(), "triangle": triangle.tolist(),
        "best_com_xy": [float(xs[best[1]]), float(ys[best[0]])], "best_capacity_N": float(np.nanmax(values)),
    }  # fmt: skip


def _finite(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def run_experiments(settings: ExperimentSettings, out: str | Path, log: bool = True) -> dict[str, Any]:
    """Run everything for ``settings.robot``; write ``out/crawl.json`` (and return it) plus the raw series
    the figures are drawn from (``out/crawl_series.npz``)."""
    t_start = time.perf_counter()
    out = Path(out)
    robot = load_robot(settings.robot)
    gait = CrawlGait()
    planners = make_planners(robot, gait)
    heavy_kg = round(settings.heavy_load_fraction * robot.total_mass, 1)
    hindered = HinderedJoint(settings.hindered_leg, settings.hindered_joint, settings.hindered_fraction)
    rough = TileTerrain(max_height=settings.rough_max_height)
    summary: dict[str, Any] = {
        "robot": settings.robot, "settings": asdict(settings), "gait": asdict(gait),
        "time_weights": {n: getattr(p, "time_weight", None) for n, p in planners.items()},
        "heavy_load_kg": heavy_kg, "planners": {}, "commit": git_commit(),
    }  # fmt: skip
    series: dict[str, Any] = {}
    poses: dict[str, list[float]] = {}
    for name, planner in planners.items():

        def say(message: str, name: str = name) -> None:
            if log:
                print(f"[crawl {settings.robot} {name}] {message} ({time.perf_counter() - t_start:.0f} s)", flush=True)

        sim, plan = triple_stance(robot, gait, planner)
        poses[name] = plan.end_com[:2].tolist()
        vertical: VerticalDisturbanceTest = vertical_disturbance_test(sim, max_force=settings.max_vertical_force)
        say(f"vertical test: servo limit at {vertical.limit_force:.0f} N, s = 0 at {vertical.s_zero_force:.0f} N")
        if name == "fwp":
            summary["vertical_capacity_map"] = capacity_map(
                triple_stance(robot, gait, planner)[0], settings.capacity_grid
            )
        sim, _ = triple_stance(robot, gait, planner)
        displacement: DisplacementTest = displacement_test(sim)
        say(
            f"displacement test: LF unloads at {displacement.unload_shift:.3f} m, "
            f"s = 0 at {displacement.s_zero_shift:.3f} m"
        )
        crawls = {}
        for label, load, hind, ground in (
            ("loaded", settings.load_kg, None, None),
            ("heavy", heavy_kg, None, None),
            ("hindered", settings.load_kg, hindered, None),
            ("rough", settings.load_kg, None, rough),
        ):
            crawl_sim, crawl_summary = crawl(robot, gait, planner, settings.steps, load, hind, ground)
            crawls[label] = crawl_summary
            say(f"{label} crawl: {crawl_summary['torque_limit_steps']} control steps at a torque limit")
            trace = crawl_sim.trace.arrays()
            series[f"{name}_{label}_time"] = trace["time"]
            series[f"{name}_{label}_torque_ratio"] = np.max(
                np.abs(trace["torque"]) / crawl_sim.model.actuator_forcerange[:, 1], axis=1
            )
            if label == "loaded":
                series[f"{name}_loaded_qpos"] = trace["qpos"]
        for key, value in asdict(vertical).items():
            series[f"{name}_vertical_{key}"] = value
        for key, value in asdict(displacement).items():
            series[f"{name}_displacement_{key}"] = value
        solve_ms = [t for c in crawls.values() for t in c["solve_ms"]]
        polytope_ms = [t for c in crawls.values() for t in c["polytope_ms"]]
        summary["planners"][name] = {
            "vertical_disturbance_limit_N": _finite(vertical.limit_force),
            "vertical_disturbance_limit_joint": vertical.limit_joint,
            "vertical_distribution_limit_N": _finite(vertical.distribution_limit_force),
            "vertical_s_zero_N": _finite(vertical.s_zero_force),
            "displacement_unload_m": _finite(displacement.unload_shift),
            "displacement_s_zero_m": _finite(displacement.s_zero_shift),
            "triple_stance_com_xy": poses[name],
            "triple_stance_s": vertical.s_start,
            "torque_limit_hits_loaded_crawl": crawls["loaded"]["torque_limit_steps"],
            "torque_limit_hits_heavy_crawl": crawls["heavy"]["torque_limit_steps"],
            "torque_limit_hits_hindered_crawl": crawls["hindered"]["torque_limit_steps"],
            "torque_limit_hits_rough_crawl": crawls["rough"]["torque_limit_steps"],
            "solve_ms_median": float(np.median(solve_ms)),
            "polytope_ms_median": float(np.median(polytope_ms)) if any(polytope_ms) else 0.0,
            "crawls": crawls,
        }
    if "vertical_capacity_map" in summary:
        cmap = summary["vertical_capacity_map"]
        cmap["planner_com_xy"] = poses
    for label, load in (("unloaded", 0.0), ("loaded", settings.load_kg)):
        sim, _ = crawl(robot, gait, planners["heuristic"], settings.steps, load)
        measures = along_crawl_measures(sim)
        for key, value in measures.items():
            series[f"along_{label}_{key}"] = np.asarray(value)
        summary.setdefault("along_heuristic_crawl", {})[label] = {
            "cwc_margin_median": float(np.nanmedian(measures["cwc_margin"])),
            "fwp_factor_median": float(np.nanmedian(measures["fwp_factor"])),
            "samples": len(measures["time"]),
        }
    summary["wall_seconds"] = time.perf_counter() - t_start
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "crawl.json", json.dumps(summary, indent=2, default=float) + "\n")
    atomic_savez(out / "crawl_series.npz", **{k: np.asarray(v) for k, v in series.items()})
    return summary


def write_video(robot_name: str, out: str | Path) -> Path | None:
    """``out/loaded_crawl.mp4``: the heuristic's and the FWP planner's loaded crawls one after the other
    (from ``crawl_series.npz``); None, with a message, where MP4 cannot be written here."""
    from margin_rl.planning.crawl.video import write_crawl_mp4
    from margin_rl.planning.video import VideoUnavailableError

    robot = load_robot(robot_name)
    with np.load(Path(out) / "crawl_series.npz") as series:
        clips = {name: series[f"{name}_loaded_qpos"] for name in ("heuristic", "fwp")}
    try:
        # 20 frames/s at 512 x 288 (multiples of the encoder's 8-pixel blocks): software rendering is slow
        return write_crawl_mp4(
            robot, clips, Path(out) / "loaded_crawl.mp4", robot.mj_model.opt.timestep, fps=20, size=(512, 288)
        )
    except VideoUnavailableError as exc:
        print(f"no MP4: {exc}", file=sys.stderr)
        return None
