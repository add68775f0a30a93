"""Why do the margin policies fall? Falls, gait, reward terms and margins along a bundle's episodes.

Usage:
    MUJOCO_GL=egl python benchmarks/bench_fall_analysis.py --bundle anymal_b_v1 --envs 64 --seed 1000 5000 --workers 2 \
        --json docs/comparison/fall_analysis_anymal_b.json --figure docs/comparison/fall_analysis_anymal_b.png

Every policy of the bundle runs one deterministic episode per environment (``--envs``) at each evaluation seed
(``--seed``), with the card's protocol: fixed command (0.75 m/s), 20 s episodes, the environment of the policy's
training run with the learned margin the policies were trained with (the bundle's copy, and each variant's margin
weight), so the per-term rewards are the ones the policy was trained on. Episodes run to their first termination
or the time limit (no autoreset). Measured, per variant (mean ± std over the policies, i.e. training seeds):

* falls: fraction of episodes (overall, per evaluation seed, before and after the first 2 s), time of the fall,
  which termination fired (base contact, thigh contact, base below the height bound, tilt beyond the bound,
  diverged simulation; several can fire at once), which thigh and which of its geoms touched the floor;
* gait before falls: each foot's contact share and the number of feet in contact over the last
  ``--contact-window`` s, against the steps of non-falling episodes after the first second;
* trends: base height, lowest knee height, stance width, tilt, base-frame velocities and angular rates, feet in
  contact and learned margin at fixed times before the fall, against their mean and 5th/95th percentiles in the
  steady gait;
* reward: per-step mean of every weighted term (``info["reward_<term>"]``) and of the total, the margin term's
  share of the return, and how often the margin term sat at its floor (margin clipped at -0.5 m), in falling
  and non-falling episodes and in the last ``--window`` s before falls;
* margins: on a subsample of the visited lambdas (every ``--every``-th step, plus every step of the last
  ``--window`` s before each fall) the learned margin (unclipped) against the extended margin m_x and the
  analytic margin m_a (:func:`margin_rl.stability.analytic.extended.extended_margin_batch`): how often the learned
  margin is positive where m_x is negative, or where m_a is negative or undefined (no Feasible Region);
* posture probe: on ``--probe-states`` steady states per policy, the change of the learned margin and of m_x when
  lambda's CoM is put 5 cm lower over the same feet, or the stance 5 cm wider.

Prints Markdown tables; ``--json`` writes every number, ``--figure`` a summary figure.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from margin_rl.envs.core import MARGIN_CLIP, AnymalCore, SimulationState
from margin_rl.robot import load_robot
from margin_rl.stability.analytic.extended import extended_margin_batch
from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES
from margin_rl.stability.analytic.margin import STATUSES
from margin_rl.stability.learned.model import LearnedMargin
from margin_rl.train.artifacts.bundle import Bundle, BundledRun, load_bundle
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import DEFAULT_FORWARD_VELOCITY, evaluation_config, resolve_env
from margin_rl.train.runs import torch_threads

CAUSES: tuple[str, ...] = ("base_contact", "thigh_contact", "base_too_low", "tilted", "diverged")
"""The termination conditions of ``AnymalCore._terminations``, one flag each."""

LEGS: tuple[str, ...] = ("LF", "RF", "LH", "RH")
WARMUP_S = 1.0  # the reset transient, left out of the non-falling reference (as the card's accelerations)
TREND_OFFSETS_S: tuple[float, ...] = (1.0, 0.5, 0.2, 0.0)  # seconds before the fall step
EARLY_FALL_S = 2.0  # falls this soon after the reset are start-up failures (the baseline's falls cluster there)
STEADY_PERCENTILES: tuple[int, ...] = (5, 95)  # how far the steady gait itself reaches towards fall-step values
PROBE_SHIFT_M = 0.05  # posture probe: CoM this much lower, or stance this much wider
LEFT_LEGS = np.array([leg.startswith("L") for leg in LEGS])
SCATTER_POINTS = 4000  # states per variant drawn away from falls in the learned-vs-m_x panel
LABELLED = "labelled states"
PATTERNS = "most common patterns (pooled share)"
UNSTABLE_STATUSES = (STATUSES.index("infeasible"), STATUSES.index("no_contact"))  # no Feasible Region


# ---------------------------------------------------------------------------------------------------------------------
# rollouts
# ---------------------------------------------------------------------------------------------------------------------
@dataclass
class Episodes:
    """One policy's episodes over all evaluation seeds: per-step arrays (T, N), N = envs x seeds."""

    variant: str
    policy_seed: int
    margin_weight: float
    robot: str
    dt: float
    eval_seed: np.ndarray  # (N,)
    length: np.ndarray  # (N,) policy steps until the episode ended, the ending step included
    fell: np.ndarray  # (N,) terminated by a fall (the card's "fell": terminated and not diverged)
    causes: np.ndarray  # (N, len(CAUSES)) flags at the ending step (all False for time-limit episodes)
    thighs: np.ndarray  # (N, 4) thigh contacts at the ending step
    thigh_geoms: Counter[str]  # thigh geom name -> falls that ended with it on the floor
    reward: np.ndarray  # (T, N)
    terms: dict[str, np.ndarray]  # weighted reward terms (T, N)
    margin_env: np.ndarray  # (T, N) the margin the reward used (learned, clipped to MARGIN_CLIP)
    contacts: np.ndarray  # (T, N, 4) bool
    height: np.ndarray  # (T, N) base height above the terrain [m]
    knee_height: np.ndarray  # (T, N) height of the lowest knee (KFE joint) above the terrain [m]
    stance_width: np.ndarray  # (T, N) info["stance_width"] [m]
    tilt: np.ndarray  # (T, N) angle of the base z axis to the vertical [rad]
    lin_vel: np.ndarray  # (T, N, 3) base frame [m/s]
    ang_vel: np.ndarray  # (T, N, 3) base frame [rad/s]
    lam: np.ndarray  # (T, N, 47)
    learned: np.ndarray | None = None  # (T, N) learned margin, unclipped (NaN after the episode)
    extended: np.ndarray | None = None  # (T, N) m_x on labelled states, NaN elsewhere
    analytic: np.ndarray | None = None  # (T, N) m_a on labelled states, NaN where none or unlabelled
    status: np.ndarray | None = None  # (T, N) analytic status index on labelled states, -1 elsewhere

    @property
    def name(self) -> str:
        """'<variant> s<training seed>', for progress lines."""
        return f"{self.variant} s{self.policy_seed}"

    def alive(self) -> np.ndarray:
        """(T, N) steps inside the episode."""
        return np.arange(self.reward.shape[0])[:, None] < self.length[None, :]

    def before_fall(self, seconds: float) -> np.ndarray:
        """(T, N) the last ``seconds`` of falling episodes, the fall step included."""
        steps = np.arange(self.reward.shape[0])[:, None]
        start = self.length - max(1, round(seconds / self.dt))
        return self.fell[None, :] & (steps >= start[None, :]) & (steps < self.length[None, :])

    def steady(self) -> np.ndarray:
        """(T, N) steps of non-falling episodes after the reset transient: the reference gait."""
        steps = np.arange(self.reward.shape[0])[:, None]
        return self.alive() & ~self.fell[None, :] & (steps >= round(WARMUP_S / self.dt))

    def fall_times(self) -> np.ndarray:
        """Times of the falls within their episodes [s]."""
        return self.length[self.fell] * self.dt


def termination_flags(core: AnymalCore, state: SimulationState, diverged: np.ndarray) -> np.ndarray:
    """(N, len(CAUSES)): each condition of ``AnymalCore._terminations`` on its own, in :data:`CAUSES` order."""
    bounds = core.config.termination
    height = state.base_pos[:, 2] - core.terrain.height(state.base_pos[:, :2])
    return np.column_stack(
        [
            state.base_contact,
            state.thigh_contacts.any(axis=1),
            height < bounds.min_base_height,
            state.base_rot[:, 2, 2] < np.cos(bounds.max_tilt_rad),
            diverged,
        ]
    )


def thigh_geom_name(model: mujoco.MjModel, geom: int) -> str:
    """A thigh geom by its shape and its position along the thigh (the MJCF leaves them unnamed): on ANYmal the
    thigh runs from the hip (z = 0) to the knee (z = -0.25 m) in its body frame."""
    shape = mujoco.mjtGeom(model.geom_type[geom]).name.removeprefix("mjGEOM_").lower()
    return f"{shape} at z = {model.geom_pos[geom, 2]:+.3f} m"


def floor_thigh_geoms(core: AnymalCore, env: int) -> set[str]:
    """Names (:func:`thigh_geom_name`) of the thigh geoms of environment ``env`` touching the floor now, each once
    (MuJoCo may report several contact points for one geom)."""
    model, data = core.model, core.render_data(env)
    thighs = {model.body(f"{leg}_THIGH").id for leg in core.robot.leg_names}
    floor = model.geom("floor").id
    names = set()
    for contact in data.contact[: data.ncon]:
        pair = (int(contact.geom1), int(contact.geom2))
        if floor in pair:
            other = pair[1] if pair[0] == floor else pair[0]
            if model.geom_bodyid[other] in thighs:
                names.add(thigh_geom_name(model, other))
    return names


def roll_out(bundle: Bundle, run: BundledRun, envs: int, seed: int, velocity: float) -> Episodes:
    """``envs`` deterministic episodes of one policy from evaluation seed ``seed``, each to its first end."""
    policy = load_policy(run.policy)
    # The training run's environment with the bundle's learned-margin weights: the reward the policy was trained on.
    _, base = resolve_env(policy, None, bundle.env_overrides())
    core = AnymalCore(evaluation_config(base, velocity), num_envs=envs, seed=seed, autoreset=False)
    core.reset()
    obs = core.observe_all()
    # Thigh contact ends most falls (measured below); the knees' height says how close the thighs' lower ends are
    # to the floor.
    body_positions = core.batch.bind("xpos")
    knees = np.array([core.model.body(f"{leg}_SHANK").id for leg in core.robot.leg_names])
    steps = core.max_episode_steps
    length = np.full(envs, steps)
    fell = np.zeros(envs, dtype=bool)
    causes = np.zeros((envs, len(CAUSES)), dtype=bool)
    thighs = np.zeros((envs, 4), dtype=bool)
    thigh_geoms: Counter[str] = Counter()
    rows: dict[str, list[np.ndarray]] = {}
    running = np.ones(envs, dtype=bool)
    with torch_threads(1):  # one policy thread: MuJoCo's pool already uses the cores
        for step in range(steps):
            out = core.step(policy(obs))
            # The info holds neither base height, tilt nor the separate termination conditions: read the
            # state the terminations were computed on (no autoreset, so it is still the post-step state).
            state = core._read()
            height = state.base_pos[:, 2] - core.terrain.height(state.base_pos[:, :2])
            knee = body_positions[:, knees]
            row = {
                "reward": out.reward,
                "margin_env": out.info["margin"],
                "contacts": out.info["contacts"] > 0.5,
                "height": height,
                "knee_height": np.min(knee[..., 2] - core.terrain.height(knee[..., :2]), axis=1),
                "stance_width": out.info["stance_width"],
                "tilt": np.arccos(np.clip(state.base_rot[:, 2, 2], -1.0, 1.0)),
                "lin_vel": out.info["base_lin_vel"],
                "ang_vel": state.ang_vel_body,
                "lam": out.info["lambda"],
                **{k: v for k, v in out.info.items() if k.startswith("reward_")},
            }
            for key, value in row.items():
                rows.setdefault(key, []).append(np.array(value, copy=True))
            ended = running & (out.terminated | out.truncated)
            length[ended] = step + 1
            diverged = out.info["diverged"] > 0.5
            fell |= ended & out.terminated & ~diverged
            flags = termination_flags(core, state, diverged)
            causes[ended & out.terminated] = flags[ended & out.terminated]
            thighs[ended & out.terminated] = state.thigh_contacts[ended & out.terminated]
            for env in np.flatnonzero(ended & out.terminated & state.thigh_contacts.any(axis=1)):
                thigh_geoms.update(floor_thigh_geoms(core, int(env)))
            running &= ~ended
            obs = out.observation
    arrays = {k: np.stack(v) for k, v in rows.items()}
    return Episodes(
        variant=run.variant,
        policy_seed=run.seed,
        margin_weight=run.margin_weight,
        robot=core.config.robot,
        dt=core.dt,
        eval_seed=np.full(envs, seed),
        length=length,
        fell=fell,
        causes=causes,
        thighs=thighs,
        thigh_geoms=thigh_geoms,
        reward=arrays.pop("reward"),
        terms={k.removeprefix("reward_"): arrays.pop(k) for k in list(arrays) if k.startswith("reward_")},
        margin_env=arrays.pop("margin_env"),
        contacts=arrays.pop("contacts"),
        height=arrays.pop("height"),
        knee_height=arrays.pop("knee_height"),
        stance_width=arrays.pop("stance_width"),
        tilt=arrays.pop("tilt"),
        lin_vel=arrays.pop("lin_vel"),
        ang_vel=arrays.pop("ang_vel"),
        lam=arrays.pop("lam"),
    )


def join(parts: Sequence[Episodes]) -> Episodes:
    """One policy's episodes of several evaluation seeds as one set (environments side by side)."""
    first = parts[0]

    def cat(name: str, axis: int) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in parts], axis=axis)

    return Episodes(
        variant=first.variant,
        policy_seed=first.policy_seed,
        margin_weight=first.margin_weight,
        robot=first.robot,
        dt=first.dt,
        eval_seed=cat("eval_seed", 0),
        length=cat("length", 0),
        fell=cat("fell", 0),
        causes=cat("causes", 0),
        thighs=cat("thighs", 0),
        thigh_geoms=sum((p.thigh_geoms for p in parts), Counter()),
        reward=cat("reward", 1),
        terms={k: np.concatenate([p.terms[k] for p in parts], axis=1) for k in first.terms},
        margin_env=cat("margin_env", 1),
        contacts=cat("contacts", 1),
        height=cat("height", 1),
        knee_height=cat("knee_height", 1),
        stance_width=cat("stance_width", 1),
        tilt=cat("tilt", 1),
        lin_vel=cat("lin_vel", 1),
        ang_vel=cat("ang_vel", 1),
        lam=cat("lam", 1),
    )


# ---------------------------------------------------------------------------------------------------------------------
# margins
# ---------------------------------------------------------------------------------------------------------------------
def add_learned(episodes: Episodes, model: LearnedMargin) -> None:
    """The learned margin, unclipped, on every step inside the episodes."""
    alive = episodes.alive()
    learned = np.full(alive.shape, np.nan)
    learned[alive] = np.asarray(model(episodes.lam[alive]))
    episodes.learned = learned


def labelled_steps(episodes: Episodes, every: int, window_s: float) -> np.ndarray:
    """(T, N) states to label: every ``every``-th step, and every step of the window before each fall."""
    steps = np.arange(episodes.reward.shape[0])[:, None]
    return episodes.alive() & (((steps + 1) % every == 0) | episodes.before_fall(window_s))


def add_labels(all_episodes: Sequence[Episodes], every: int, window_s: float, workers: int) -> int:
    """m_x, m_a and the analytic status on the labelled states of every policy (one batch); returns the count."""
    masks = [labelled_steps(e, every, window_s) for e in all_episodes]
    lams = np.concatenate([e.lam[m] for e, m in zip(all_episodes, masks, strict=True)])
    labels = extended_margin_batch(load_robot(all_episodes[0].robot), lams, workers=workers)
    start = 0
    for episodes, mask in zip(all_episodes, masks, strict=True):
        part = slice(start, start + int(mask.sum()))
        start = part.stop
        episodes.extended, episodes.analytic = np.full(mask.shape, np.nan), np.full(mask.shape, np.nan)
        episodes.status = np.full(mask.shape, -1, dtype=np.int16)
        episodes.extended[mask] = labels.margin[part]
        episodes.status[mask] = labels.status[part]
        defined = labels.status[part] == STATUSES.index("ok")
        episodes.analytic[mask] = np.where(defined, labels.analytic.margin[part], np.nan)
    return len(lams)


def lower_com(lams: np.ndarray, drop: float) -> np.ndarray:
    """lambda with the CoM ``drop`` metres lower over the same feet (feet are relative to the CoM in H)."""
    out = lams.copy()
    feet = out[:, LAMBDA_SLICES["feet"]].reshape(-1, len(LEGS), 3)
    feet[..., 2] += drop
    out[:, LAMBDA_SLICES["feet"]] = feet.reshape(len(out), -1)
    return out


def widen_stance(lams: np.ndarray, extra: float) -> np.ndarray:
    """lambda with the left feet ``extra / 2`` further left and the right feet as much further right."""
    out = lams.copy()
    feet = out[:, LAMBDA_SLICES["feet"]].reshape(-1, len(LEGS), 3)
    feet[..., 1] += np.where(LEFT_LEGS, 0.5 * extra, -0.5 * extra)
    out[:, LAMBDA_SLICES["feet"]] = feet.reshape(len(out), -1)
    return out


PROBES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    f"CoM {100 * PROBE_SHIFT_M:g} cm lower": lambda lams: lower_com(lams, PROBE_SHIFT_M),
    f"stance {100 * PROBE_SHIFT_M:g} cm wider": lambda lams: widen_stance(lams, PROBE_SHIFT_M),
}
"""Posture changes applied to visited states: does each margin reward them?"""


def posture_probe(groups: dict[str, list[Episodes]], model: LearnedMargin, states: int, workers: int) -> dict[str, Any]:
    """Change in the learned margin and in m_x when a labelled steady-gait state is lowered or widened
    (:data:`PROBES`), on up to ``states`` states per policy (fixed random subsample); m_x of the changed states
    is labelled here."""
    rng = np.random.default_rng(0)
    picked: list[tuple[str, Episodes, np.ndarray]] = []
    for policies in groups.values():
        for e in policies:
            candidates = np.flatnonzero((e.steady() & (e.status >= 0)).ravel())
            chosen = rng.choice(candidates, size=min(states, len(candidates)), replace=False)
            picked.append((e.variant, e, chosen))
    base = np.concatenate([e.lam.reshape(-1, e.lam.shape[-1])[i] for _, e, i in picked])
    robot = load_robot(picked[0][1].robot)
    out: dict[str, Any] = {}
    for name, change in PROBES.items():
        moved = change(base)
        moved_x = extended_margin_batch(robot, moved, workers=workers).margin
        moved_l = np.asarray(model(moved))
        per_policy: dict[str, dict[str, list[float]]] = {}
        start = 0
        for variant, e, chosen in picked:
            part = slice(start, start + len(chosen))
            start = part.stop
            d_learned = moved_l[part] - e.learned.ravel()[chosen]
            d_extended = moved_x[part] - e.extended.ravel()[chosen]
            rows = per_policy.setdefault(variant, {})
            for key, delta in (("learned", d_learned), ("m_x", d_extended)):
                finite = delta[np.isfinite(delta)]
                rows.setdefault(f"{key} change [m]", []).append(float(finite.mean()) if finite.size else math.nan)
                rows.setdefault(f"{key} rises (share)", []).append(
                    float((finite > 0).mean()) if finite.size else math.nan
                )
        keys = next(iter(per_policy.values()))
        out[name] = {k: {v: spread(per_policy[v][k]) for v in per_policy} for k in keys}
        out[name]["states per policy"] = {
            v: spread([float(len(c)) for w, _, c in picked if w == v]) for v in per_policy
        }
    return out


# ---------------------------------------------------------------------------------------------------------------------
# statistics
# ---------------------------------------------------------------------------------------------------------------------
def spread(values: Sequence[float]) -> dict[str, Any]:
    """Mean ± std (population, as the card) over the policies that gave a finite value, and the values."""
    finite = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    return {
        "mean": float(finite.mean()) if finite.size else math.nan,
        "std": float(finite.std()) if finite.size else math.nan,
        "policies": int(finite.size),
        "sum": float(finite.sum()),
        "per_policy": [float(v) if v is not None and math.isfinite(v) else None for v in values],
    }


def masked_mean(values: np.ndarray, mask: np.ndarray) -> float:
    """Mean of ``values`` where ``mask`` holds and the value is finite; NaN when there is none."""
    chosen = values[mask]
    chosen = chosen[np.isfinite(chosen)]
    return float(chosen.mean()) if chosen.size else math.nan


def across(groups: dict[str, list[Episodes]], metric: Callable[[Episodes], float]) -> dict[str, dict[str, Any]]:
    """Variant -> :func:`spread` of ``metric`` over its policies."""
    return {variant: spread([metric(e) for e in policies]) for variant, policies in groups.items()}


def at_fall(episodes: Episodes, values: np.ndarray, seconds_before: float) -> np.ndarray:
    """``values`` (T, N) at ``seconds_before`` the fall step of each falling episode (NaN before the start)."""
    index = episodes.length[episodes.fell] - 1 - round(seconds_before / episodes.dt)
    columns = np.flatnonzero(episodes.fell)
    out = np.full(len(columns), np.nan)
    ok = index >= 0
    out[ok] = values[index[ok], columns[ok]]
    return out


def masked_percentile(values: np.ndarray, mask: np.ndarray, q: float) -> float:
    """``q``-th percentile of the finite masked ``values``; NaN when there is none."""
    chosen = values[mask]
    chosen = chosen[np.isfinite(chosen)]
    return float(np.percentile(chosen, q)) if chosen.size else math.nan


def mean_at_fall(episodes: Episodes, values: np.ndarray, seconds_before: float) -> float:
    """Mean over the falls of :func:`at_fall` (the falls too early to look that far back left out)."""
    picked = at_fall(episodes, values, seconds_before)
    picked = picked[np.isfinite(picked)]
    return float(picked.mean()) if picked.size else math.nan


def pattern_codes(contacts: np.ndarray) -> np.ndarray:
    """Contact sets (..., 4) as integers 0..15 (bit i: leg i of :data:`LEGS` in contact)."""
    return (contacts.astype(np.int64) << np.arange(len(LEGS))).sum(axis=-1)


def pattern_name(code: int) -> str:
    """'LF+RH' style name of a contact-set code, 'none' for a flight phase."""
    names = [leg for i, leg in enumerate(LEGS) if code >> i & 1]
    return "+".join(names) if names else "none"


def pattern_shares(codes: np.ndarray, top: int | None = None) -> dict[str, float]:
    """Share of each contact set among ``codes``, most common first (the ``top`` first only)."""
    counts = np.bincount(codes, minlength=2 ** len(LEGS))
    order = [int(c) for c in np.argsort(-counts, kind="stable") if counts[c]][:top]
    return {pattern_name(c): float(counts[c] / counts.sum()) for c in order}


# ---------------------------------------------------------------------------------------------------------------------
# the analyses (each returns a JSON-ready dict)
# ---------------------------------------------------------------------------------------------------------------------
def fall_summary(groups: dict[str, list[Episodes]], seeds: Sequence[int]) -> dict[str, Any]:
    """Fall fraction (overall and per evaluation seed), time of the falls and the termination causes."""

    def fraction(seed: int | None) -> Callable[[Episodes], float]:
        def metric(e: Episodes) -> float:
            chosen = np.ones_like(e.fell) if seed is None else e.eval_seed == seed
            return float(e.fell[chosen].mean())

        return metric

    def timed(early: bool) -> Callable[[Episodes], float]:
        def metric(e: Episodes) -> float:
            soon = e.length * e.dt <= EARLY_FALL_S
            return float(np.mean(e.fell & (soon if early else ~soon)))

        return metric

    def cause_share(i: int) -> Callable[[Episodes], float]:
        return lambda e: float(e.causes[e.fell, i].mean()) if e.fell.any() else math.nan

    pooled = {}
    for variant, policies in groups.items():
        times = np.concatenate([e.fall_times() for e in policies])
        episode_s = policies[0].reward.shape[0] * policies[0].dt
        combos = Counter(
            "+".join(c for c, f in zip(CAUSES, flags, strict=True) if f) or "?"
            for e in policies
            for flags in e.causes[e.fell]
        )
        thighs = np.concatenate([e.thighs[e.fell] for e in policies]).sum(axis=0) if len(times) else np.zeros(4)
        pooled[variant] = {
            "episodes": int(sum(len(e.fell) for e in policies)),
            "falls": len(times),
            "fall_time_s": _quantiles(times),
            "falls_within_first_s": {f"{s:g}": int(np.sum(times <= s)) for s in (1.0, 2.0, 5.0)},
            "fall_time_histogram_s": np.histogram(times, bins=np.arange(0.0, episode_s + 1.0, 1.0))[0].tolist(),
            "cause_combinations": dict(combos.most_common()),
            "thigh_contacts_at_fall": dict(zip(LEGS, thighs.astype(int).tolist(), strict=True)),
            "thigh_geoms_on_floor_at_fall": dict(sum((e.thigh_geoms for e in policies), Counter()).most_common()),
        }
    return {
        "fraction": across(groups, fraction(None)),
        "fraction_per_eval_seed": {str(s): across(groups, fraction(s)) for s in seeds},
        f"fraction_within_{EARLY_FALL_S:g}_s": across(groups, timed(early=True)),
        f"fraction_after_{EARLY_FALL_S:g}_s": across(groups, timed(early=False)),
        "fall_time_s_median": across(groups, lambda e: float(np.median(e.fall_times())) if e.fell.any() else math.nan),
        "cause_share": {c: across(groups, cause_share(i)) for i, c in enumerate(CAUSES)},
        "pooled": pooled,
    }


def _quantiles(values: np.ndarray) -> dict[str, float]:
    """Min, quartiles and max of ``values``; empty when there are none."""
    if not len(values):
        return {}
    q = np.percentile(values, [0, 25, 50, 75, 100])
    return dict(zip(("min", "p25", "median", "p75", "max"), q.tolist(), strict=True))


def gait_summary(groups: dict[str, list[Episodes]], window_s: float) -> dict[str, Any]:
    """Foot contact shares and feet-in-contact counts before falls and in the steady gait."""
    windows: dict[str, Callable[[Episodes], np.ndarray]] = {
        f"last {window_s:g} s before fall": lambda e: e.before_fall(window_s),
        "steady (non-falling, after 1 s)": Episodes.steady,
    }
    out: dict[str, Any] = {}
    for label, window in windows.items():
        entry: dict[str, Any] = {}
        for i, leg in enumerate(LEGS):
            entry[f"{leg} in contact"] = across(groups, lambda e, i=i, w=window: masked_mean(e.contacts[..., i], w(e)))
        for k in range(len(LEGS) + 1):
            entry[f"{k} feet in contact"] = across(
                groups, lambda e, k=k, w=window: masked_mean((e.contacts.sum(axis=-1) == k).astype(float), w(e))
            )
        entry[PATTERNS] = {
            variant: pattern_shares(np.concatenate([pattern_codes(e.contacts[window(e)]) for e in policies]), top=6)
            for variant, policies in groups.items()
        }
        out[label] = entry
    out["pattern at the fall step (pooled share)"] = {
        variant: pattern_shares(
            np.concatenate([pattern_codes(e.contacts[e.length[e.fell] - 1, np.flatnonzero(e.fell)]) for e in policies])
        )
        for variant, policies in groups.items()
    }
    return out


def trend_summary(groups: dict[str, list[Episodes]]) -> dict[str, Any]:
    """Base state and learned margin at fixed times before the fall, and their steady-gait means."""
    quantities: dict[str, Callable[[Episodes], np.ndarray]] = {
        "base height [m]": lambda e: e.height,
        "lowest knee height [m]": lambda e: e.knee_height,
        "stance width [m]": lambda e: e.stance_width,
        "tilt [deg]": lambda e: np.degrees(e.tilt),
        "forward velocity [m/s]": lambda e: e.lin_vel[..., 0],
        "|lateral velocity| [m/s]": lambda e: np.abs(e.lin_vel[..., 1]),
        "vertical velocity [m/s]": lambda e: e.lin_vel[..., 2],
        "|roll rate| [rad/s]": lambda e: np.abs(e.ang_vel[..., 0]),
        "|pitch rate| [rad/s]": lambda e: np.abs(e.ang_vel[..., 1]),
        "|yaw rate| [rad/s]": lambda e: np.abs(e.ang_vel[..., 2]),
        "feet in contact": lambda e: e.contacts.sum(axis=-1).astype(float),
        "learned margin [m]": lambda e: e.learned,
    }
    out: dict[str, Any] = {}
    for name, values in quantities.items():
        row = {"steady": across(groups, lambda e, v=values: masked_mean(v(e), e.steady()))}
        for q in STEADY_PERCENTILES:
            row[f"steady, {q}th percentile"] = across(
                groups, lambda e, v=values, q=q: masked_percentile(v(e), e.steady(), q)
            )
        for offset in TREND_OFFSETS_S:
            row[f"{offset:g} s before fall"] = across(groups, lambda e, v=values, o=offset: mean_at_fall(e, v(e), o))
        out[name] = row
    return out


def reward_summary(groups: dict[str, list[Episodes]], window_s: float) -> dict[str, Any]:
    """Per-step means of every reward term and the total, the margin term's share of the return, and how
    often the margin sat at its clip floor, per class of steps."""
    classes: dict[str, Callable[[Episodes], np.ndarray]] = {
        "non-falling episodes": lambda e: e.alive() & ~e.fell[None, :],
        "falling episodes": lambda e: e.alive() & e.fell[None, :],
        f"last {window_s:g} s before fall": lambda e: e.before_fall(window_s),
    }
    terms = list(next(iter(groups.values()))[0].terms)
    out: dict[str, Any] = {}
    for label, steps in classes.items():
        entry = {f"{t} per step": across(groups, lambda e, t=t, s=steps: masked_mean(e.terms[t], s(e))) for t in terms}
        entry["total per step"] = across(groups, lambda e, s=steps: masked_mean(e.reward, s(e)))
        entry["margin term / return"] = across(groups, lambda e, s=steps: _share(e.terms["margin"], e.reward, s(e)))
        entry["margin at clip floor (share of steps)"] = across(
            groups, lambda e, s=steps: masked_mean((e.margin_env <= MARGIN_CLIP[0]).astype(float), s(e))
        )
        entry["return per episode"] = across(groups, lambda e, s=steps: _episode_return(e, s(e)))
        out[label] = entry
    return out


def _share(term: np.ndarray, reward: np.ndarray, mask: np.ndarray) -> float:
    """Sum of ``term`` over the masked steps divided by the sum of the reward (signed)."""
    total = float(reward[mask].sum())
    return float(term[mask].sum()) / total if mask.any() and total != 0 else math.nan


def _episode_return(episodes: Episodes, mask: np.ndarray) -> float:
    """Mean undiscounted return of the episodes that have masked steps, over those steps."""
    per_episode = np.where(mask, episodes.reward, 0.0).sum(axis=0)
    chosen = mask.any(axis=0)
    return float(per_episode[chosen].mean()) if chosen.any() else math.nan


def _learned_positive(e: Episodes) -> np.ndarray:
    return e.learned > 0


def _extended_negative(e: Episodes) -> np.ndarray:
    return e.extended < 0


def _no_region(e: Episodes) -> np.ndarray:
    return np.isin(e.status, UNSTABLE_STATUSES)


def _analytic_unstable(e: Episodes) -> np.ndarray:
    """m_a < 0, or no m_a because the state has no Feasible Region (infeasible load, no contact)."""
    return _no_region(e) | (e.analytic < 0)


MARGIN_CONDITIONS: dict[str, Callable[[Episodes], np.ndarray]] = {
    "learned > 0": _learned_positive,
    "m_x < 0": _extended_negative,
    "learned > 0 and m_x < 0": lambda e: _learned_positive(e) & _extended_negative(e),
    "learned > 0 and (m_a < 0 or undefined)": lambda e: _learned_positive(e) & _analytic_unstable(e),
    "m_a undefined (no Feasible Region)": _no_region,
    "sign agreement learned vs m_x": lambda e: (e.learned >= 0) == (e.extended >= 0),
}
"""Shares of labelled states reported by :func:`margin_summary` (each a (T, N) condition)."""

MARGIN_MEANS: dict[str, Callable[[Episodes], np.ndarray]] = {
    "learned mean [m]": lambda e: e.learned,
    "m_x mean [m]": lambda e: e.extended,
    "m_a mean where defined [m]": lambda e: e.analytic,
    "learned - m_x mean [m]": lambda e: e.learned - e.extended,
}


def _share_where(condition: np.ndarray, mask: np.ndarray) -> float:
    return float(condition[mask].mean()) if mask.any() else math.nan


def margin_summary(groups: dict[str, list[Episodes]], window_s: float, weight: float) -> dict[str, Any]:
    """Learned margin against m_x and m_a on the labelled states, before falls and elsewhere; ``weight``: the
    margin weight of the reward (what each margin would have paid per step)."""
    classes: dict[str, Callable[[Episodes], np.ndarray]] = {
        f"last {window_s:g} s before fall": lambda e: e.before_fall(window_s),
        "falling episodes, earlier": lambda e: e.alive() & e.fell[None, :] & ~e.before_fall(window_s),
        "non-falling episodes": lambda e: e.alive() & ~e.fell[None, :],
    }
    paid: dict[str, Callable[[Episodes], np.ndarray]] = {
        f"{weight:g} x clip(learned): the margin term at weight {weight:g}": lambda e: (
            weight * np.clip(e.learned, *MARGIN_CLIP)
        ),
        f"{weight:g} x clip(m_x): the same term with m_x": lambda e: weight * np.clip(e.extended, *MARGIN_CLIP),
    }
    out: dict[str, Any] = {}
    for label, steps in classes.items():

        def labelled(e: Episodes, steps: Callable[[Episodes], np.ndarray] = steps) -> np.ndarray:
            return steps(e) & (e.status >= 0)

        entry = {LABELLED: across(groups, lambda e, m=labelled: float(m(e).sum()))}
        for name, condition in MARGIN_CONDITIONS.items():
            entry[name] = across(groups, lambda e, c=condition, m=labelled: _share_where(c(e), m(e)))
        for name, values in {**MARGIN_MEANS, **paid}.items():
            entry[name] = across(groups, lambda e, v=values, m=labelled: masked_mean(v(e), m(e)))
        out[label] = entry
    return out


# ---------------------------------------------------------------------------------------------------------------------
# output
# ---------------------------------------------------------------------------------------------------------------------
def cell(stats: dict[str, Any], total: int, digits: int = 3) -> str:
    """'mean ± std', with '(k/n policies)' when fewer than all policies gave a value; '–' when none did."""
    if not stats["policies"]:
        return "–"
    text = f"{stats['mean']:.{digits}g} ± {stats['std']:.2g}"
    return text if stats["policies"] == total else f"{text} ({stats['policies']}/{total})"


def print_table(title: str, rows: dict[str, dict[str, dict[str, Any]]], variants: Sequence[str], total: int) -> None:
    """``rows``: row label -> variant -> spread; one column per variant."""
    print(f"\n{title}\n\n| | " + " | ".join(variants) + " |\n|---|" + "---|" * len(variants))
    for label, by_variant in rows.items():
        if label == LABELLED:  # a count: the total over the policies says more than its spread
            print(f"| {label} (all policies) | " + " | ".join(f"{by_variant[v]['sum']:,.0f}" for v in variants) + " |")
        else:
            print(f"| {label} | " + " | ".join(cell(by_variant[v], total) for v in variants) + " |")


def print_report(report: dict[str, Any], variants: Sequence[str], total: int) -> None:
    """Every table of the report, one column per variant (``total``: policies per variant)."""
    falls = report["falls"]
    rows = {"fall fraction": falls["fraction"]}
    rows |= {f"fall fraction, eval seed {s}": v for s, v in falls["fraction_per_eval_seed"].items()}
    rows[f"falling within the first {EARLY_FALL_S:g} s"] = falls[f"fraction_within_{EARLY_FALL_S:g}_s"]
    rows[f"falling after {EARLY_FALL_S:g} s"] = falls[f"fraction_after_{EARLY_FALL_S:g}_s"]
    rows["median fall time [s]"] = falls["fall_time_s_median"]
    rows |= {f"falls with {c}": v for c, v in falls["cause_share"].items()}
    print_table("## Falls (mean ± std over policies)", rows, variants, total)
    for variant, pooled in falls["pooled"].items():
        print(
            f"\n{variant}: {pooled['falls']} falls in {pooled['episodes']} episodes; fall time {pooled['fall_time_s']}"
        )
        print(f"  causes {pooled['cause_combinations']}; thighs at fall {pooled['thigh_contacts_at_fall']}")
        print(f"  thigh geoms on the floor at the fall step: {pooled['thigh_geoms_on_floor_at_fall']}")
        print(f"  fall-time histogram (1 s bins) {pooled['fall_time_histogram_s']}")
        print(f"  falls within the first 1 / 2 / 5 s: {list(pooled['falls_within_first_s'].values())}")
    for window, entry in report["gait"].items():
        if window.startswith("pattern"):
            print(f"\n{window}: {entry}")
            continue
        shares_only = {k: v for k, v in entry.items() if k != PATTERNS}
        print_table(f"## Gait: {window}", shares_only, variants, total)
        for variant, shares in entry[PATTERNS].items():
            print(f"{variant} patterns: " + ", ".join(f"{p} {s:.0%}" for p, s in shares.items()))
    for name, row in report["trends"].items():
        print_table(f"## Trend: {name}", row, variants, total)
    for label, entry in report["rewards"].items():
        print_table(f"## Reward per step: {label}", entry, variants, total)
    for label, entry in report["margins"].items():
        print_table(f"## Learned vs extended/analytic margin: {label}", entry, variants, total)
    for label, entry in report["posture_probe"].items():
        print_table(f"## Posture probe on steady-gait states: {label}", entry, variants, total)


def display_path(path: Path) -> str:
    """``path`` relative to the working directory where it lies inside it (the repository root), else absolute."""
    resolved = path.resolve()
    return str(resolved.relative_to(Path.cwd())) if resolved.is_relative_to(Path.cwd()) else str(resolved)


def to_json(value: Any) -> Any:
    """JSON-ready copy: NaN becomes null, numpy scalars plain numbers."""
    if isinstance(value, dict):
        return {str(k): to_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_json(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def aligned(episodes: Episodes, values: np.ndarray, horizon: int) -> np.ndarray:
    """(falls, horizon + 1) ``values`` over the ``horizon`` steps up to each fall step (NaN before the start)."""
    return np.stack([at_fall(episodes, values, k * episodes.dt) for k in range(horizon, -1, -1)], axis=1)


def column_means(traces: np.ndarray) -> np.ndarray:
    """Mean of each column over its finite entries; NaN for a column without any."""
    finite = np.isfinite(traces)
    sums = np.where(finite, traces, 0.0).sum(axis=0)
    return np.where(finite.any(axis=0), sums / np.maximum(finite.sum(axis=0), 1), np.nan)


def plot(groups: dict[str, list[Episodes]], report: dict[str, Any], window_s: float, path: Path) -> None:
    """Fall times, reward terms per class, base state and margins before falls, contacts, learned vs m_x."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from margin_rl.plotting import save_figure

    colours = {"with margin": "tab:red", "without margin": "tab:blue"}
    fig, axes = plt.subplots(2, 3, figsize=(16, 9))
    ax = axes[0, 0]
    for variant, pooled in report["falls"]["pooled"].items():
        counts = pooled["fall_time_histogram_s"]
        ax.step(np.arange(len(counts)), counts, where="post", label=variant, color=colours.get(variant))
    ax.set(xlabel="time of the fall in the episode [s] (1 s bins)", ylabel="falls (all policies, seeds)")
    ax.set_title("When the falls happen")
    ax.legend()

    ax = axes[0, 1]
    classes = list(report["rewards"])
    terms = [k for k in next(iter(report["rewards"].values())) if k.endswith("per step")]
    width = 0.8 / (len(classes) * len(groups))
    for j, (variant, label) in enumerate((v, c) for v in groups for c in classes):
        means = [report["rewards"][label][t][variant]["mean"] for t in terms]
        stds = [report["rewards"][label][t][variant]["std"] for t in terms]
        ax.bar(
            np.arange(len(terms)) + j * width,
            means,
            width,
            yerr=stds,
            label=f"{variant}: {label}",
            color=colours.get(variant),
            alpha=0.35 + 0.65 * (classes.index(label) + 1) / len(classes),
        )
    ax.set_xticks(np.arange(len(terms)) + 0.4 - width / 2, [t.removesuffix(" per step") for t in terms])
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set(ylabel="reward per step (mean ± std over policies)")
    ax.set_title("Weighted reward terms")
    ax.legend(fontsize=7)

    horizon = round(window_s / next(iter(groups.values()))[0].dt) - 1  # the window's steps, fall step included
    offsets = -np.arange(horizon, -1, -1) * next(iter(groups.values()))[0].dt
    for ax, name, values in (
        (axes[0, 2], "base height [m]", lambda e: e.height),
        (axes[1, 0], "lowest knee height [m]", lambda e: e.knee_height),
    ):
        for variant, policies in groups.items():
            traces = np.concatenate([aligned(e, values(e), horizon) for e in policies])
            if len(traces):
                ax.plot(
                    offsets,
                    column_means(traces),
                    color=colours.get(variant),
                    label=f"{variant} ({len(traces)} falls)",
                )
            steady = report["trends"][name]["steady"][variant]["mean"]
            ax.axhline(steady, color=colours.get(variant), ls=":", lw=1)
        ax.set(xlabel="time to the fall [s]", ylabel=name)
        ax.set_title(f"{name} before falls (dotted: steady gait)")
        ax.legend(fontsize=8)

    ax = axes[1, 1]
    for variant, policies in groups.items():
        learned = np.concatenate([aligned(e, e.learned, horizon) for e in policies])
        extended = np.concatenate([aligned(e, e.extended, horizon) for e in policies])
        if len(learned):
            ax.plot(offsets, column_means(learned), color=colours.get(variant), label=f"{variant}: learned")
            ax.plot(offsets, column_means(extended), color=colours.get(variant), ls="--", label=f"{variant}: m_x")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set(xlabel="time to the fall [s]", ylabel="margin [m] (mean over falls)")
    ax.set_title("Learned margin (the reward's) vs extended margin m_x")
    ax.legend(fontsize=8)

    ax = axes[1, 2]
    for variant, policies in groups.items():
        fall = np.concatenate([e.before_fall(window_s) for e in policies], axis=1)
        learned = np.concatenate([e.learned for e in policies], axis=1)
        extended = np.concatenate([e.extended for e in policies], axis=1)
        labelled = np.isfinite(extended) & np.isfinite(learned)
        # A fixed subsample of the other states, so that the few pre-fall states stay visible on top.
        rest = np.flatnonzero((labelled & ~fall).ravel())
        rest = np.random.default_rng(0).choice(rest, size=min(SCATTER_POINTS, len(rest)), replace=False)
        ax.scatter(extended.ravel()[rest], learned.ravel()[rest], s=2, alpha=0.15, color=colours.get(variant))
        ax.scatter(
            extended[labelled & fall],
            learned[labelled & fall],
            s=5,
            alpha=0.5,
            marker="x",
            color=colours.get(variant),
            label=f"{variant}: last {window_s:g} s before falls",
        )
    lim = (-1.2, 0.6)
    ax.plot(lim, lim, "k", lw=0.5)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set(xlim=lim, xlabel="extended margin m_x [m]", ylabel="learned margin [m]")
    ax.set_title("Learned vs m_x (dots: elsewhere, crosses: before falls)")
    ax.legend(fontsize=8)
    save_figure(fig, path)


# ---------------------------------------------------------------------------------------------------------------------
# main
# ---------------------------------------------------------------------------------------------------------------------
def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--bundle", default="anymal_b_v1", help="shipped bundle name or folder")
    parser.add_argument("--envs", type=int, default=32, help="episodes (parallel environments) per policy and seed")
    parser.add_argument("--seed", type=int, nargs="+", default=[1000, 5000], help="evaluation seeds")
    parser.add_argument("--forward-velocity", type=float, default=DEFAULT_FORWARD_VELOCITY, help="command [m/s]")
    parser.add_argument("--every", type=int, default=5, help="label every n-th policy step with m_x and m_a")
    parser.add_argument("--window", type=float, default=1.0, help="seconds before a fall: labelled densely [s]")
    parser.add_argument("--contact-window", type=float, default=0.5, help="seconds before a fall for the gait [s]")
    parser.add_argument("--probe-states", type=int, default=300, help="steady states per policy for the posture probe")
    parser.add_argument("--workers", type=int, default=1, help="processes for the analytic labels")
    parser.add_argument("--json", type=Path, help="write every number here")
    parser.add_argument("--figure", type=Path, help="write the summary figure here (.png)")
    args = parser.parse_args(argv)
    for name in ("envs", "every", "workers", "probe_states"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be an integer >= 1, got {getattr(args, name)}")
    for name in ("window", "contact_window", "forward_velocity"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            parser.error(f"--{name.replace('_', '-')} must be a finite number > 0, got {value}")
    if len(set(args.seed)) != len(args.seed):
        parser.error(f"--seed values must differ, got {args.seed}")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        bundle = load_bundle(args.bundle)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if bundle.margin_weights is None:
        print(f"error: bundle {bundle.name} carries no learned-margin weights (card format 1)", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    model = LearnedMargin.load(bundle.margin_weights)
    everything: list[Episodes] = []
    for run in bundle.runs:
        parts = [roll_out(bundle, run, args.envs, seed, args.forward_velocity) for seed in args.seed]
        everything.append(join(parts))
        add_learned(everything[-1], model)
        print(f"{everything[-1].name}: {int(everything[-1].fell.sum())} falls in {len(everything[-1].fell)} episodes")
    rollout_s = time.perf_counter() - t0
    labels = add_labels(everything, args.every, args.window, args.workers)
    label_s = time.perf_counter() - t0 - rollout_s
    groups: dict[str, list[Episodes]] = {}
    for e in everything:
        groups.setdefault(e.variant, []).append(e)
    weight = max(e.margin_weight for e in everything)
    report = {
        "falls": fall_summary(groups, args.seed),
        "gait": gait_summary(groups, args.contact_window),
        "trends": trend_summary(groups),
        "rewards": reward_summary(groups, args.window),
        "margins": margin_summary(groups, args.window, weight),
        "posture_probe": posture_probe(groups, model, args.probe_states, args.workers),
    }
    total = max(len(v) for v in groups.values())
    print(
        f"\nbundle {bundle.name}: {len(everything)} policies x {len(args.seed)} seeds x {args.envs} episodes; "
        f"rollouts {rollout_s:.0f} s, {labels:,} states labelled in {label_s:.0f} s"
    )
    print_report(report, list(groups), total)
    if args.figure:
        plot(groups, report, args.window, args.figure)
        print(f"\nfigure: {args.figure}")
    runtime_s = time.perf_counter() - t0
    if args.json:
        record = {
            "command": "python " + " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]]),
            "bundle": bundle.name,
            "learned_margin": display_path(bundle.margin_weights),
            "learned_margin_sha256": model.card.get("sha256"),
            "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
            "policies": [
                {
                    "variant": e.variant,
                    "seed": e.policy_seed,
                    "margin_weight": e.margin_weight,
                    "episodes": len(e.fell),
                    "falls": int(e.fell.sum()),
                    "fall_times_s": e.fall_times().tolist(),
                    "fall_causes": {c: int(e.causes[e.fell, i].sum()) for i, c in enumerate(CAUSES)},
                    "thigh_contacts_at_fall": dict(zip(LEGS, e.thighs[e.fell].sum(axis=0).tolist(), strict=True)),
                }
                for e in everything
            ],
            "labelled_states": labels,
            "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
            "runtime_s": {"rollouts": rollout_s, "labels": label_s, "total": runtime_s},
            **report,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(to_json(record), indent=1) + "\n")
        print(f"json: {args.json}")
    print(f"total {runtime_s:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
