"""The fall analysis's data: every step of every episode of a bundle's policies, and the margins of their states.

:func:`roll_out` runs one policy's deterministic episodes on a batched ANYmal core (the card's protocol) and keeps,
per step and environment, the step info the analysis reads (reward terms, margin, contacts, stance width, base
velocity, lambda, the termination causes ``info["termination_<cause>"]``) and four quantities of the simulator's
state (base height and lowest knee above the terrain, tilt, base angular velocity), recorded with the package's
:class:`~margin_rl.train.analysis.episodes.Recorder`. Where each episode ends and whether it fell come from the
package's :class:`~margin_rl.train.metrics.EpisodeStatistics`, as ``evaluate`` computes them. :func:`add_learned`
and :func:`add_labels` rate the recorded states with the learned margin and with m_x and m_a.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from margin_rl.envs.core import AnymalCore, StepOutput
from margin_rl.envs.terminations import CAUSE_NAMES, info_key
from margin_rl.robot import load_robot, quat_wxyz_to_matrix
from margin_rl.robot.mjcf_names import shank_body
from margin_rl.stability.analytic.extended import extended_margin_batch
from margin_rl.stability.analytic.margin import STATUSES
from margin_rl.stability.learned.model import LearnedMargin
from margin_rl.train.analysis.episodes import Recorder
from margin_rl.train.artifacts.bundle import Bundle, BundledRun
from margin_rl.train.artifacts.policies import load_policy
from margin_rl.train.commands.evaluate import evaluation_config, resolve_env
from margin_rl.train.metrics import EpisodeStatistics, split_episodes, summarize
from margin_rl.train.runs import torch_threads

CAUSES: tuple[str, ...] = CAUSE_NAMES
"""The environment's termination causes, each reported per step as ``info["termination_<cause>"]``."""

LEGS: tuple[str, ...] = ("LF", "RF", "LH", "RH")
WARMUP_S = 1.0  # the reset transient, left out of the non-falling reference (as the card's accelerations)


# ---------------------------------------------------------------------------------------------------------------------
# one policy's episodes
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
    thighs: np.ndarray  # (N, 4) thighs on the terrain at the ending step (falls only)
    thigh_geoms: Counter[str]  # thigh geom name -> falls that ended with it on the terrain
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
    evaluation: list[dict[str, float]]  # each episode's metrics (margin_rl.train.metrics), in environment order
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

    def summary(self) -> dict[str, dict[str, float]]:
        """Mean and std over the episodes of every episode metric (as ``evaluate`` reports them)."""
        return summarize(self.evaluation)


# ---------------------------------------------------------------------------------------------------------------------
# the simulator's state beyond the step info
# ---------------------------------------------------------------------------------------------------------------------
def live_state(core: AnymalCore) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The live ``qpos``, ``qvel`` and body ``xpos`` arrays (num_envs, ...) of the core's simulations."""
    physics = core.physics  # the core's physics seam
    return physics.qpos, physics.qvel, physics.xpos


def thigh_geom_name(model: mujoco.MjModel, geom: int) -> str:
    """A thigh geom by its shape and its position along the thigh (the MJCF leaves them unnamed): on ANYmal the
    thigh runs from the hip (z = 0) to the knee (z = -0.25 m) in its body frame."""
    shape = mujoco.mjtGeom(model.geom_type[geom]).name.removeprefix("mjGEOM_").lower()
    return f"{shape} at z = {model.geom_pos[geom, 2]:+.3f} m"


def thighs_on_terrain(core: AnymalCore, env: int) -> tuple[np.ndarray, set[str]]:
    """Which legs' thighs of environment ``env`` touch the terrain now ((4,) bool, :data:`LEGS` order; the world
    body, as the environment's thigh-contact sensors), and the names (:func:`thigh_geom_name`) of the touching
    thigh geoms, each once (MuJoCo may report several contact points for one geom)."""
    model, data = core.model, core.render_data(env)
    # The thigh is the shank's parent body in the kinematic tree.
    shanks = [model.body(shank_body(leg)).id for leg in core.robot.leg_names]
    thigh_leg = {int(model.body_parentid[shank]): i for i, shank in enumerate(shanks)}
    legs, names = np.zeros(len(LEGS), dtype=bool), set()
    for contact in data.contact[: data.ncon]:
        pair = (int(contact.geom1), int(contact.geom2))
        for geom, other in (pair, pair[::-1]):
            body = int(model.geom_bodyid[geom])
            if body in thigh_leg and model.geom_bodyid[other] == 0:
                legs[thigh_leg[body]] = True
                names.add(thigh_geom_name(model, geom))
    return legs, names


def step_row(core: AnymalCore, out: StepOutput, knees: np.ndarray) -> dict[str, np.ndarray]:
    """What the analysis keeps of one step, every environment (copies: the core reuses its arrays)."""
    qpos, qvel, xpos = live_state(core)
    info = out.info
    ground = core.terrain.height
    knee = xpos[:, knees]
    tilt_cos = quat_wxyz_to_matrix(qpos[:, 3:7])[:, 2, 2]
    row = {
        "reward": out.reward,
        "margin_env": info["margin"],
        "contacts": info["contacts"] > 0.5,
        "height": qpos[:, 2] - ground(qpos[:, :2]),
        "knee_height": np.min(knee[..., 2] - ground(knee[..., :2]), axis=1),
        "stance_width": info["stance_width"],
        "tilt": np.arccos(np.clip(tilt_cos, -1.0, 1.0)),
        "lin_vel": info["base_lin_vel"],
        "ang_vel": qvel[:, 3:6],  # the free joint's angular velocity is in the base frame
        "lam": info["lambda"],
        **{k: v for k, v in info.items() if k.startswith("reward_")},
    }
    return {key: np.array(value, copy=True) for key, value in row.items()}


# ---------------------------------------------------------------------------------------------------------------------
# rollouts
# ---------------------------------------------------------------------------------------------------------------------
def roll_out(bundle: Bundle, run: BundledRun, envs: int, seed: int, velocity: float) -> Episodes:
    """``envs`` deterministic episodes of one policy from evaluation seed ``seed``, each to its first end."""
    policy = load_policy(run.policy)
    # The training run's environment with the bundle's learned-margin weights: the reward the policy was trained on.
    _, base = resolve_env(policy, None, bundle.env_overrides())
    core = AnymalCore(evaluation_config(base, velocity), num_envs=envs, seed=seed, autoreset=False)
    core.reset()
    obs = core.observe_all()
    # Thigh contact ends most falls; the knees' height says how close the thighs' lower ends are to the floor.
    knees = np.array([core.model.body(shank_body(leg)).id for leg in core.robot.leg_names])
    statistics = EpisodeStatistics(envs, core.dt, warmup_steps=round(WARMUP_S / core.dt))
    recorder = Recorder()
    first: dict[int, dict[str, float]] = {}  # each environment's first episode (metrics, ending)
    causes = np.zeros((envs, len(CAUSES)), dtype=bool)
    thighs = np.zeros((envs, len(LEGS)), dtype=bool)
    thigh_geoms: Counter[str] = Counter()
    with torch_threads(1):  # one policy thread: MuJoCo's pool already uses the cores
        for _ in range(core.max_episode_steps):
            out = core.step(policy(obs))
            recorder.add(step_row(core, out, knees))
            # Without autoreset an ended environment keeps reporting its end: only its first one counts.
            for episode in split_episodes(statistics.update(out.reward, out.info, out.terminated, out.truncated)):
                env = int(episode.pop("env"))
                if env in first:
                    continue
                first[env] = episode
                if out.terminated[env]:
                    causes[env] = [out.info[info_key(cause)][env] > 0.5 for cause in CAUSES]
                    thighs[env], names = thighs_on_terrain(core, env)
                    thigh_geoms.update(names)
            obs = out.observation
        running = np.array([env for env in range(envs) if env not in first], dtype=np.int64)
        for episode in split_episodes(statistics.close(running, out.info)):  # only if the time limit is off
            first[int(episode.pop("env"))] = episode
    arrays = recorder.arrays()
    evaluation = [first[env] for env in range(envs)]
    return Episodes(
        variant=run.variant,
        policy_seed=run.seed,
        margin_weight=run.margin_weight,
        robot=core.config.robot,
        dt=core.dt,
        eval_seed=np.full(envs, seed),
        length=np.array([int(e["length"]) for e in evaluation]),
        fell=np.array([e["fell"] > 0.5 for e in evaluation]),
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
        evaluation=evaluation,
    )


PER_STEP: tuple[str, ...] = (
    "reward", "margin_env", "contacts", "height", "knee_height", "stance_width", "tilt", "lin_vel", "ang_vel", "lam"
)  # fmt: skip
PER_EPISODE: tuple[str, ...] = ("eval_seed", "length", "fell", "causes", "thighs")


def join(parts: Sequence[Episodes]) -> Episodes:
    """One policy's episodes of several evaluation seeds as one set (environments side by side)."""
    first = parts[0]
    fields: dict[str, Any] = {name: np.concatenate([getattr(p, name) for p in parts], axis=0) for name in PER_EPISODE}
    fields |= {name: np.concatenate([getattr(p, name) for p in parts], axis=1) for name in PER_STEP}
    return Episodes(
        variant=first.variant,
        policy_seed=first.policy_seed,
        margin_weight=first.margin_weight,
        robot=first.robot,
        dt=first.dt,
        thigh_geoms=sum((p.thigh_geoms for p in parts), Counter()),
        terms={k: np.concatenate([p.terms[k] for p in parts], axis=1) for k in first.terms},
        evaluation=[e for p in parts for e in p.evaluation],
        **fields,
    )


# ---------------------------------------------------------------------------------------------------------------------
# margins of the visited states
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
