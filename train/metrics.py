"""Episode metrics, computed in one place for training logs, ``evaluate`` and ``compare``.

:class:`EpisodeStatistics` keeps per-environment running sums over the current episode of the per-step
quantities that :meth:`margin_rl.envs.core.AnymalCore.step` reports in ``info``, and returns the metrics of
every episode that ends. Metric names and units:

===============================  ==========================================================================
``return``                       sum of the reward over the episode
``length``                       policy steps; ``duration_s`` the same in seconds
``reward/<term>``                sum over the episode of each weighted reward term (``info["reward_<term>"]``)
``margin_mean``, ``margin_min``  stability margin [m]: mean and minimum over the episode
``margin_negative_fraction``     fraction of steps with a negative margin (outside the feasible region)
``lin_acc_rms_{x,y,z}``          RMS of the base (CoM) linear acceleration per base-frame axis [m/s²]
``lin_acc_peak_{x,y,z}``         peak of its absolute value [m/s²]; ``lin_acc_rms`` RMS of its norm
``ang_acc_rms_{x,y,z}`` ...      the same for the base angular acceleration [rad/s²]
``velocity_error_mean``          mean |v_cmd − ẋ| of the heading velocity [m/s]
``forward_velocity_mean``        mean heading velocity ẋ in the base frame [m/s]
``stance_width_mean``            mean lateral foot spread in the heading frame [m]
``base_height_mean``             mean height of the base origin above the terrain under it [m]
``edge_landing_fraction``        share of the episode's foot touchdowns on a step edge (``info["edge_touchdowns"]``
                                 over ``info["touchdowns"]``; 0 on flat ground, NaN without a touchdown)
``torque_rms``                   RMS of the joint torques over the joints and the episode [N m]
``torque_limit_fraction``        share of the episode's steps with a joint at its actuator's force limit
``margin_reward_share``          |sum of the margin term| over the sum of every term's |sum| (``reward/<term>``):
                                 the margin term's share of the episode's reward (absent without a margin term)
``fell``, ``diverged``           1 if the episode ended in a fall / a diverged simulation, else 0
``termination/<cause>``          1 if the cause held on the episode's last step (``info["termination_<cause>"]``;
                                 the causes of :mod:`margin_rl.envs.terminations`, several may hold at once)
``timed_out``                    1 if the episode reached its time limit
===============================  ==========================================================================

Averaged over episodes (as :func:`summarize` and the training logs do), ``termination/<cause>`` is the fraction
of episodes that cause ended; TensorBoard shows it as ``Episode_Termination/<cause>`` (:func:`tensorboard_tags`).

Acceleration statistics skip the first ``warmup_steps`` of each episode (the landing after a reset) when
asked to; training logs use every step. An episode that ends within the warm-up has no acceleration sample
left: its acceleration metrics are NaN, and :func:`not_computed` gives the reason a report prints instead.

:func:`summarize` and :func:`summary_table` turn episodes into reports.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from array_api_compat import device as device_of

from margin_rl.arrays import like, namespace, to_numpy
from margin_rl.envs.reset_rows import ResetRows
from margin_rl.envs.terminations import CAUSE_NAMES, info_key

AXES: tuple[str, ...] = ("x", "y", "z")
TERMINATION_KEYS: tuple[str, ...] = ("fell", "diverged", "timed_out")

SUMMARY_METRICS: dict[str, str] = {
    "velocity_error_mean": "velocity tracking error [m/s]",
    "lin_acc_rms": "base linear acceleration RMS [m/s²]",
    "ang_acc_rms": "base angular acceleration RMS [rad/s²]",
    "stance_width_mean": "stance width [m]",
    "margin_mean": "stability margin [m]",
    "fell": "falls [fraction of episodes]",
}
"""The comparison table's columns: metric name -> label with unit."""
TERRAIN_METRICS: dict[str, str] = {
    "edge_landing_fraction": "feet landing on step edges [fraction of touchdowns]",
    **{
        f"termination/{cause}": f"ended by {cause.replace('_', ' ')} [fraction of episodes]"
        for cause in CAUSE_NAMES
        if cause != "diverged"  # the simulator's failure, not the policy's: never a fall (``fell``)
    },
}
"""Further comparison columns where the evaluation terrain is not flat: the causes of the falls (several may end one
episode) and the touchdowns on step edges. On flat ground nearly every fall is a tilt or a base contact and no foot
meets an edge, so the flat tables leave them out."""
METRIC_LABELS: dict[str, str] = {**SUMMARY_METRICS, **TERRAIN_METRICS}
"""Every comparison column, in table order: metric name -> label with unit."""


def comparison_metrics(terrain: str) -> dict[str, str]:
    """The comparison's columns for an evaluation on ``terrain`` (``EnvConfig.terrain``): :data:`SUMMARY_METRICS`,
    and :data:`TERRAIN_METRICS` too where the terrain is not flat."""
    return dict(SUMMARY_METRICS) if terrain == "flat" else dict(METRIC_LABELS)


def table_metrics(variants: Mapping[str, Mapping[str, Any]]) -> dict[str, str]:
    """The columns of a comparison report: the :data:`METRIC_LABELS` entries its variants have a mean of (a report
    made before the terrain columns existed has the summary columns only)."""
    present = {key for variant in variants.values() for key in variant.get("mean", {})}
    return {key: label for key, label in METRIC_LABELS.items() if key in present}


ACCELERATION_PREFIXES: tuple[str, ...] = ("lin_acc_", "ang_acc_")


def reward_terms(info: Mapping[str, np.ndarray]) -> tuple[str, ...]:
    """Reward term names present in a step ``info`` (keys ``reward_<term>``)."""
    return tuple(k.removeprefix("reward_") for k in info if k.startswith("reward_"))


class EpisodeStatistics:
    """Running per-environment episode sums; :meth:`update` returns the metrics of the episodes that ended.

    The sums live where the environment's arrays do (``reference``: an array of the core, e.g. ``core.episode_step``:
    numpy on the host, torch tensors on the physics' device), so that a step adds to them without leaving the
    device; the metrics of finished episodes come back as numpy.
    """

    def __init__(self, num_envs: int, dt: float, warmup_steps: int = 0, reference: Any = None) -> None:
        """``dt``: policy step [s]; ``warmup_steps``: steps at the start of each episode left out of the
        acceleration statistics; ``reference``: an array of the kind and device the step outputs come in (None:
        numpy)."""
        self.num_envs, self.dt, self.warmup_steps = num_envs, float(dt), int(warmup_steps)
        self.terms: tuple[str, ...] = ()
        xp = self._xp = namespace(np.zeros(0) if reference is None else reference)
        self._device = "cpu" if reference is None else device_of(reference)
        n = num_envs
        self._return = self._zeros(n)
        self._length = self._zeros(n, dtype=xp.int64)
        self._terms = self._zeros(n, 0)
        self._margin_sum = self._zeros(n)
        self._margin_min = xp.full(n, xp.inf, dtype=xp.float64, device=self._device)
        self._margin_negative = self._zeros(n)
        self._acc_count = self._zeros(n)
        self._lin_sq = self._zeros(n, 3)
        self._lin_peak = self._zeros(n, 3)
        self._ang_sq = self._zeros(n, 3)
        self._ang_peak = self._zeros(n, 3)
        self._vel_err = self._zeros(n)
        self._fwd_vel = self._zeros(n)
        self._stance = self._zeros(n)
        self._base_height = self._zeros(n)
        self._touchdowns = self._zeros(n)
        self._edge_touchdowns = self._zeros(n)
        self._torque_sq = self._zeros(n)
        self._torque_at_limit = self._zeros(n)
        self._window_keys: tuple[str, ...] | None = None  # accumulate(): the metrics summed, in order
        self._window = self._zeros(2, 0)  # accumulate(): (sum, count) per metric over the episodes ended

    def _zeros(self, *shape: int, dtype: Any = None) -> Any:
        xp = self._xp
        return xp.zeros(shape, dtype=xp.float64 if dtype is None else dtype, device=self._device)

    def _float(self, value: Any) -> Any:
        xp = self._xp
        return xp.astype(xp.asarray(value), xp.float64, copy=False)

    def reset(self, ids: Any = None) -> None:
        """Start new episodes in environments ``ids`` (all if None)."""
        ids = slice(None) if ids is None else like(ids, self._return)
        for array in self._episode_sums():
            array[ids] = 0
        self._margin_min[ids] = math.inf

    def _reset_where(self, done: Any) -> None:
        """Start new episodes where ``done`` ((N,) bool) holds, in place and without a host read."""
        rows = ResetRows.where(done)
        for array in self._episode_sums():
            rows.write(array, 0)
        rows.write(self._margin_min, math.inf)

    def _episode_sums(self) -> tuple[Any, ...]:
        """The per-environment sums an episode starts from zero."""
        return (
            self._return,
            self._length,
            self._terms,
            self._margin_sum,
            self._margin_negative,
            self._acc_count,
            self._lin_sq,
            self._lin_peak,
            self._ang_sq,
            self._ang_peak,
            self._vel_err,
            self._fwd_vel,
            self._stance,
            self._base_height,
            self._touchdowns,
            self._edge_touchdowns,
            self._torque_sq,
            self._torque_at_limit,
        )

    def update(
        self,
        reward: np.ndarray,
        info: Mapping[str, np.ndarray],
        terminated: np.ndarray,
        truncated: np.ndarray,
    ) -> dict[str, np.ndarray]:
        """Add one step of every environment; returns the metrics (arrays over the finished episodes, in
        environment order, plus ``"env"``: their indices) and starts new episodes there. Empty when none ended."""
        xp = self._xp
        self._add_step(reward, info)
        truncated = xp.astype(xp.asarray(truncated), xp.bool, copy=False)
        done = xp.astype(xp.asarray(terminated), xp.bool, copy=False) | truncated
        if not bool(xp.any(done)):
            return {}
        ids = xp.nonzero(done)[0]
        metrics = self._finish(ids, info, truncated)
        self.reset(ids)
        return metrics

    def accumulate(self, reward: Any, info: Mapping[str, Any], terminated: Any, truncated: Any) -> None:
        """:meth:`update` without a host read: the metrics of the episodes that end are summed where the sums are
        (each metric over the episodes where it is finite), for :meth:`drain` to read once per window (a rollout);
        the same work every step, however many episodes end."""
        xp = self._xp
        self._add_step(reward, info)
        truncated = xp.astype(xp.asarray(truncated), xp.bool, copy=False)
        done = xp.astype(xp.asarray(terminated), xp.bool, copy=False) | truncated
        metrics = self._metrics(slice(None), info, truncated)
        metrics.pop("env")
        if self._window_keys is None:
            self._window_keys = tuple(metrics)
            self._window = self._zeros(2, len(self._window_keys))
        values = xp.stack([xp.astype(metrics[key], xp.float64) for key in self._window_keys])  # (K, N)
        counted = done[None, :] & xp.isfinite(values)
        self._window[0] += xp.sum(xp.where(counted, values, 0.0), axis=1)
        self._window[1] += xp.sum(xp.astype(counted, xp.float64), axis=1)
        self._reset_where(done)

    def drain(self) -> dict[str, tuple[float, int]]:
        """Each metric's (mean, episodes) over the episodes that ended since the last drain, where it was finite
        (metrics no such episode gave are left out), read from the sums in one host read; the sums start again."""
        if self._window_keys is None:
            return {}
        sums, counts = np.array(to_numpy(self._window))  # a copy: on the CPU to_numpy shares the tensor's memory
        self._window[...] = 0.0
        return {
            key: (float(sums[k] / counts[k]), int(counts[k])) for k, key in enumerate(self._window_keys) if counts[k]
        }

    def _add_step(self, reward: Any, info: Mapping[str, Any]) -> None:
        """Add one step of every environment to the running sums."""
        xp, f = self._xp, self._float
        if not self.terms:
            self.terms = reward_terms(info)
            self._terms = self._zeros(self.num_envs, len(self.terms))
        self._return += reward
        self._length += 1
        if self.terms:
            self._terms += xp.stack([info[f"reward_{t}"] for t in self.terms], axis=1)
        margin = f(info["margin"])
        self._margin_sum += margin
        self._margin_min[...] = xp.minimum(self._margin_min, margin)
        self._margin_negative += margin < 0
        counted = (self._length > self.warmup_steps)[:, None]
        lin, ang = xp.asarray(info["base_lin_acc"]), xp.asarray(info["base_ang_acc"])
        self._acc_count += counted[:, 0]
        self._lin_sq += counted * lin**2
        self._ang_sq += counted * ang**2
        self._lin_peak[...] = xp.where(counted, xp.maximum(self._lin_peak, xp.abs(lin)), self._lin_peak)
        self._ang_peak[...] = xp.where(counted, xp.maximum(self._ang_peak, xp.abs(ang)), self._ang_peak)
        self._vel_err += info["velocity_error"]
        self._fwd_vel += xp.asarray(info["base_lin_vel"])[:, 0]
        self._stance += info["stance_width"]
        self._base_height += info["base_height"]
        self._touchdowns += info["touchdowns"]
        self._edge_touchdowns += info["edge_touchdowns"]
        self._torque_sq += info["joint_torque_sq"]
        self._torque_at_limit += info["torque_at_limit"]

    def close(self, ids: Any, info: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """End the running episodes of ``ids`` without another step (counted as time-outs); their metrics."""
        ids = like(np.asarray(to_numpy(ids), dtype=np.int64), self._return)
        if ids.shape[0] == 0:
            return {}
        metrics = self._finish(ids, info, self._xp.ones(self.num_envs, dtype=self._xp.bool, device=self._device))
        self.reset(ids)
        return metrics

    def _finish(self, ids: Any, info: Mapping[str, Any], truncated: Any) -> dict[str, np.ndarray]:
        """The metrics of the episodes of ``ids``, computed where the sums are and returned as numpy."""
        return {key: to_numpy(value) for key, value in self._metrics(ids, info, truncated).items()}

    def _metrics(self, ids: Any, info: Mapping[str, Any], truncated: Any) -> dict[str, Any]:
        """The metrics of the episodes of ``ids`` (indices, or ``slice(None)``: every environment), where the sums
        are."""
        xp, f = self._xp, self._float
        copy = xp.asarray
        length = xp.astype(self._length[ids], xp.float64)
        count = self._acc_count[ids]
        with np.errstate(invalid="ignore", divide="ignore"):
            lin_ms = self._lin_sq[ids] / count[:, None]
            ang_ms = self._ang_sq[ids] / count[:, None]
        no_acc = count == 0
        metrics: dict[str, Any] = {
            "env": ids,
            "return": copy(self._return[ids], copy=True),
            "length": length,
            "duration_s": length * self.dt,
        }
        for j, term in enumerate(self.terms):
            metrics[f"reward/{term}"] = copy(self._terms[ids, j], copy=True)
        if "margin" in self.terms:
            magnitude = xp.sum(xp.abs(self._terms[ids]), axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                metrics["margin_reward_share"] = xp.abs(self._terms[ids, self.terms.index("margin")]) / magnitude
        metrics["margin_mean"] = self._margin_sum[ids] / length
        metrics["margin_min"] = copy(self._margin_min[ids], copy=True)
        metrics["margin_negative_fraction"] = self._margin_negative[ids] / length
        for name, ms, peak in (("lin_acc", lin_ms, self._lin_peak[ids]), ("ang_acc", ang_ms, self._ang_peak[ids])):
            for k, axis in enumerate(AXES):
                metrics[f"{name}_rms_{axis}"] = xp.sqrt(ms[:, k])
                metrics[f"{name}_peak_{axis}"] = xp.where(no_acc, xp.nan, peak[:, k])
            metrics[f"{name}_rms"] = xp.sqrt(xp.sum(ms, axis=1))
        metrics["velocity_error_mean"] = self._vel_err[ids] / length
        metrics["forward_velocity_mean"] = self._fwd_vel[ids] / length
        metrics["stance_width_mean"] = self._stance[ids] / length
        metrics["base_height_mean"] = self._base_height[ids] / length
        metrics["torque_rms"] = xp.sqrt(self._torque_sq[ids] / length)
        metrics["torque_limit_fraction"] = self._torque_at_limit[ids] / length
        with np.errstate(invalid="ignore", divide="ignore"):
            metrics["edge_landing_fraction"] = self._edge_touchdowns[ids] / self._touchdowns[ids]
        metrics["fell"] = f(info["fell"])[ids]
        metrics["diverged"] = f(info["diverged"])[ids]
        for cause in CAUSE_NAMES:
            if info_key(cause) in info:
                metrics[f"termination/{cause}"] = f(info[info_key(cause)])[ids]
        metrics["timed_out"] = xp.astype(truncated[ids], xp.float64)
        return metrics


def split_episodes(metrics: Mapping[str, np.ndarray]) -> list[dict[str, float]]:
    """The arrays of :meth:`EpisodeStatistics.update` as one dict of floats per episode."""
    if not metrics:
        return []
    keys = list(metrics)
    count = len(metrics[keys[0]])
    return [{k: float(metrics[k][i]) for k in keys} for i in range(count)]


def tensorboard_tags(metrics: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Episode metrics under their TensorBoard tags (the same for both backends):
    ``Episode_Reward/<term>``, ``Episode_Termination/<fell|diverged|timed_out>``,
    ``Episode_Termination/<cause>`` (each termination cause; ``diverged`` is both a cause and a key, with the same
    values), ``Episode_Metrics/<name>``."""
    tags: dict[str, np.ndarray] = {}
    for key, value in metrics.items():
        if key == "env":
            continue
        if key.startswith("reward/"):
            tags[f"Episode_Reward/{key.removeprefix('reward/')}"] = value
        elif key in TERMINATION_KEYS:
            tags[f"Episode_Termination/{key}"] = value
        elif key.startswith("termination/"):
            tags.setdefault(f"Episode_Termination/{key.removeprefix('termination/')}", value)
        else:
            tags[f"Episode_Metrics/{key}"] = value
    return tags


def step_tags(info: Mapping[str, Any]) -> dict[str, float]:
    """Per-step statistics over the batch (logged every step, also before any episode ends), reduced where the info
    arrays are (numpy or a device's tensors) and read back once."""
    names, values = step_statistics(info)
    return {name: float(value) for name, value in zip(names, to_numpy(values), strict=True)}


def step_statistics(info: Mapping[str, Any]) -> tuple[tuple[str, ...], Any]:
    """The tags of :func:`step_tags` and their values as one array where the info arrays are (no host read)."""
    xp = namespace(info["margin"])
    margin = xp.astype(xp.asarray(info["margin"]), xp.float64, copy=False)
    lin = xp.linalg.vector_norm(xp.asarray(info["base_lin_acc"]), axis=1)
    velocity_error = xp.mean(xp.asarray(info["velocity_error"]))
    statistics = [xp.mean(margin), xp.min(margin), xp.mean(lin), velocity_error]
    names = ["Step/margin_mean", "Step/margin_min", "Step/lin_acc_norm_mean", "Step/velocity_error_mean"]
    if "terrain_level" in info:  # the terrain curriculum's mean level
        statistics.append(xp.mean(xp.astype(xp.asarray(info["terrain_level"]), xp.float64)))
        names.append("Curriculum/terrain_level_mean")
    return tuple(names), xp.stack(statistics)


def summarize(episodes: Iterable[Mapping[str, float]]) -> dict[str, dict[str, float]]:
    """Mean and standard deviation (population, ddof 0) of each metric over episodes, ignoring NaN."""
    episodes = list(episodes)
    keys = [k for k in (episodes[0] if episodes else {}) if k != "env"]
    summary: dict[str, dict[str, float]] = {}
    for key in keys:
        values = np.array([e[key] for e in episodes if key in e], dtype=float)
        finite = values[np.isfinite(values)]
        summary[key] = {
            "mean": float(finite.mean()) if finite.size else math.nan,
            "std": float(finite.std()) if finite.size else math.nan,
            "count": int(finite.size),
        }
    return summary


def not_computed(summary: Mapping[str, Mapping[str, Any]], warmup_s: float | None = None) -> dict[str, str]:
    """Metric -> why it has no value, for every metric of a :func:`summarize` result that no episode could give.

    ``warmup_s``: the seconds left out of the acceleration statistics (ANYmal evaluation), named in the reason.
    """
    reasons = {}
    for key, stats in summary.items():
        if stats.get("count", 1):
            continue
        if key.startswith(ACCELERATION_PREFIXES) and warmup_s is not None:
            reasons[key] = (
                f"episode shorter than the RMS window: no episode lasted beyond the first {warmup_s:g} s, which "
                "are left out of the acceleration statistics (--warmup-s)"
            )
        else:
            reasons[key] = "no episode reported a finite value"
    return reasons


def mean_std(values: Sequence[float]) -> tuple[float, float]:
    """Mean and population standard deviation of finite values (NaN, NaN when there are none)."""
    array = np.asarray(values, dtype=float)
    array = array[np.isfinite(array)]
    if array.size == 0:
        return math.nan, math.nan
    return float(array.mean()), float(array.std())


def _mean_std_cell(mean: float | None, std: float | None) -> str:
    if mean is None or not math.isfinite(mean):
        return "n/a"
    return f"{mean:.4g} ± {std:.2g}" if std is not None and math.isfinite(std) else f"{mean:.4g}"


def summary_table(variants: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Markdown lines of the comparison table: a header, then per variant its margin weight and the
    mean ± std of every column of :func:`table_metrics` (``variants[name]`` has ``margin_weight``, ``mean``
    and ``std`` dicts; missing or non-finite values print as n/a)."""
    columns = table_metrics(variants)
    lines = [
        "| variant | margin weight | " + " | ".join(columns.values()) + " |",
        "|---|---|" + "---|" * len(columns),
    ]
    for name, v in variants.items():
        cells = [_mean_std_cell(v["mean"].get(k), v["std"].get(k)) for k in columns]
        lines.append(f"| {name} | {v['margin_weight']:g} | " + " | ".join(cells) + " |")
    return lines
