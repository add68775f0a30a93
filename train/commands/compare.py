"""``compare``: PPO without and with the stability-margin reward, over seeds, on the same budget (seed 000 §V-C).

Example::

    python -m margin_rl.train compare --env margin_rl/AnymalB-v1 --backend rsl --seeds 3 \\
        --total-steps 5000000 --margin-weight 0.2 --env-option reward_params.alive_bonus=0.1 \\
        --out runs/compare_b

For the ANYmal ids, ``--margin-weight`` defaults to the recipe's (0.1 for ``robust``) and ``--env-option
reward_params.alive_bonus`` to 0.1 for both variants: the shipped experiment (see
:mod:`margin_rl.train.commands.options`).

Both variants train with a training recipe of :mod:`margin_rl.train.recipes` (its environment options,
environments, steps, PPO options and margin weight; options given here replace the recipe's): the shipped bundles'
``robust`` unless ``--recipe NAME`` names another (``--recipe none``: none).

For each variant (margin weight 0, and ``--margin-weight``) and each training seed, a run is trained into
``<out>/runs/mw<weight>__s<seed>`` (a finished run is reused, a stopped one resumed), then evaluated on the same
fixed command and the same evaluation seeds. Both variants use the same margin model, so the margin is
measured for the baseline too. Outputs in ``<out>``:

* ``compare.png``: Fig. 9-style base acceleration over an evaluation episode (blue without, red with margin),
  per base-frame axis, from the first training seed and the first evaluation episode;
* ``compare.md`` and ``compare.json``: mean ± std over training seeds (each seed's value is its mean over the
  evaluation episodes) of velocity tracking error, base linear and angular acceleration RMS, stance width,
  margin and falls (on rough ground also each fall cause and the feet landing on step edges:
  :data:`~margin_rl.train.metrics.TERRAIN_METRICS`), with every run's numbers in the JSON. A metric an evaluation
  could not compute (e.g. the acceleration RMS of episodes shorter than ``--warmup-s``) is ``null`` there with its
  reason in the run's ``"not_computed": {metric: reason}`` and listed under the Markdown table (both only when it
  happens); and, per metric, the difference with − without margin over the training seeds with a two-sided Welch
  test, the interval that inverts it and a bootstrap interval (``"statistics"`` in the JSON, a second table in the
  Markdown; :mod:`margin_rl.train.analysis.significance`).

``--eval-commands 0.5 1.0 --eval-conditions friction_0.4 mass_-20 mass_+20`` also evaluates every policy in each
(condition, command) cell of the grid (conditions of :mod:`margin_rl.train.analysis.conditions`; the main cell is
the nominal condition at ``--forward-velocity``), with the same episodes and seeds: ``"grid"`` in the JSON (each
cell's variants and statistics, as for the main cell) and a table with one row per cell in the Markdown. An
evaluation made before for the same request (policy checksum, options, episodes, seeds: ``request.json``) is
reused: every grid cell, and in the main cell every policy but each variant's first (the plot shows its episode).
A run's evaluations go into ``<run>/eval`` and ``<run>/eval_grid/<cell>``; evaluated in a changed environment
(``--terrain-difficulty``, evaluation ``--env-option``, a bundle's margin weights) into ``eval_<digest>`` and
``eval_grid_<digest>`` of those options, so comparisons of the same runs at several difficulties keep each other's
evaluations and may run side by side (each run's folder: ``"eval_dir"`` in the JSON).

``--runs RUN_DIR ...`` trains nothing and evaluates finished runs (margin weight 0 and one other weight, e.g. runs
trained one by one with ``train``) exactly like its own. A bundled policy folder counts as a finished run, so a
new bundle can reuse policies that need no retraining (baselines, whose training never read the margin network)::

    python -m margin_rl.train compare --runs train/bundled/anymal_c/without_margin__s0 ... runs/c_margin_s0 ... \
        --bundle train/bundled/anymal_c

Push recovery of the same policies: :mod:`margin_rl.train.commands.push_recovery` (``--bundled NAME`` or ``--variant``).

``--bundle DIR`` then copies the runs' TorchScript actors and configs (trained here or given by ``--runs``), and
the learned-margin weights they were trained with, into a policy bundle with a card
(:mod:`margin_rl.train.artifacts.bundle`); ``--bundled NAME`` trains nothing and evaluates a bundle the same way,
with the bundle's margin weights, e.g. the shipped ANYmal B policies (the README's main job)::

    python -m margin_rl.train compare --bundled anymal_b --out results/anymal_b

With ``--bundled``, ``--env-option``/``--margin-weights`` change the evaluation environment (other terrain, the
package's current margin weights, ...); the card's table then need not be reproduced.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass, is_dataclass
from pathlib import Path
from typing import Any

from margin_rl.provenance import git_commit, sha256_file
from margin_rl.train.analysis.conditions import CONDITIONS, DEFAULT_CONDITION, check_condition
from margin_rl.train.analysis.media import plot_accelerations
from margin_rl.train.analysis.significance import RESAMPLES, compare_variants, difference_table, grid_table
from margin_rl.train.artifacts.bundle import POLICY_FILE, bundled_policy_entry, load_bundle, write_bundle
from margin_rl.train.commands.evaluate import DEFAULT_FORWARD_VELOCITY, Evaluation, evaluate
from margin_rl.train.commands.options import (
    CLI_MARGIN_WEIGHT,
    DEFAULTS_HELP,
    add_env_arguments,
    add_recipe_argument,
    env_overrides,
    recipe_of,
    with_training_defaults,
)
from margin_rl.train.commands.train import DEFAULT_BACKEND, DEFAULT_NUM_ENVS, TrainSpec, load_spec, make_spec, train
from margin_rl.train.environments import DEFAULT_ENV
from margin_rl.train.metrics import METRIC_LABELS, comparison_metrics, mean_std, summary_table
from margin_rl.train.recipes import get_recipe, with_recipe
from margin_rl.train.runs import (
    CONFIG_FILE,
    PROGRESS_FILE,
    final_model_name,
    find_run_config,
    read_json,
    versions,
    write_json,
)


@dataclass(frozen=True)
class CompareSettings:
    """What ``compare`` trains and how it evaluates."""

    env_id: str = DEFAULT_ENV
    backend: str = DEFAULT_BACKEND
    margin_weight: float = 1.0  # weight of the "with margin" variant (the other is 0)
    seeds: tuple[int, ...] = (0, 1, 2)  # training seeds
    num_envs: int = DEFAULT_NUM_ENVS
    total_steps: int = 5_000_000  # per run
    checkpoint_every: int = 500_000
    eval_episodes: int = 4
    eval_seed: int = 1000  # the same evaluation seeds for every policy
    forward_velocity: float = DEFAULT_FORWARD_VELOCITY  # the same command for every policy [m/s]
    warmup_s: float = 1.0
    device: str = "cpu"
    recipe: str | None = None  # the training recipe (margin_rl.train.recipes) the runs are trained with, if any
    # More evaluation cells: every (condition, command) of ("nominal", *grid_conditions) x (forward_velocity,
    # *grid_commands) other than the main one (nominal, forward_velocity); empty: the main cell only.
    grid_commands: tuple[float, ...] = ()  # [m/s]
    grid_conditions: tuple[str, ...] = ()  # names of margin_rl.train.analysis.conditions

    def __post_init__(self) -> None:
        if self.margin_weight <= 0:
            raise ValueError(f"--margin-weight must be > 0 (the baseline uses 0), got {self.margin_weight}")
        if not self.seeds:
            raise ValueError("at least one seed is needed")
        for command in self.grid_commands:
            if not (isinstance(command, (int, float)) and math.isfinite(command)):
                raise ValueError(f"--eval-commands must be finite velocities [m/s], got {command!r}")
        for condition in self.grid_conditions:
            check_condition(condition)

    def grid_cells(self) -> list[tuple[str, float]]:
        """The (condition, command) cells evaluated besides the main one: conditions in the given order (nominal
        first), commands ascending."""
        conditions = list(dict.fromkeys((DEFAULT_CONDITION, *self.grid_conditions)))
        commands = sorted({float(self.forward_velocity), *map(float, self.grid_commands)})
        main = (DEFAULT_CONDITION, float(self.forward_velocity))
        return [(c, v) for c in conditions for v in commands if (c, v) != main]

    def variants(self) -> dict[str, float]:
        """Variant name -> margin weight."""
        return {"without margin": 0.0, "with margin": self.margin_weight}


def _run_spec(settings: CompareSettings, weight: float, seed: int, overrides: dict[str, Any]) -> TrainSpec:
    return make_spec(
        settings.env_id,
        settings.backend,
        {**overrides, "margin_weight": weight},
        get_recipe(settings.recipe).ppo_overrides(settings.backend) if settings.recipe is not None else None,
        seed=seed,
        num_envs=settings.num_envs,
        total_steps=settings.total_steps,
        checkpoint_every=settings.checkpoint_every,
        device=settings.device,
        recipe=settings.recipe,
    )


def _train_or_reuse(spec: TrainSpec, run_dir: Path, progress: bool) -> Path:
    """Train a run, resume a stopped one, or reuse a finished one; returns its final model."""
    final = run_dir / final_model_name(spec.backend)
    finished = (run_dir / PROGRESS_FILE).is_file() and read_json(run_dir / PROGRESS_FILE).get("finished")
    if finished and final.is_file():
        print(f"reusing finished run {run_dir}")
        return final
    resume = (run_dir / CONFIG_FILE).is_file()
    result = train(spec, run_dir, resume=resume, progress=progress)
    if result.stopped or result.final_model is None:
        raise KeyboardInterrupt(f"training of {run_dir} was stopped; run compare again to resume it")
    return result.final_model


def run_compare(
    settings: CompareSettings, out: str | Path, env_options: dict[str, Any] | None = None, progress: bool = True
) -> dict[str, Any]:
    """Train and evaluate every (variant, seed); write compare.png/.md/.json into ``out``; returns the JSON."""
    out = Path(out)
    overrides = dict(env_options or {})
    variants: dict[str, tuple[float, list[tuple[int, Path]]]] = {}
    for name, weight in settings.variants().items():
        for seed in settings.seeds:
            run_dir = out / "runs" / f"mw{weight:g}__s{seed}"
            final = _train_or_reuse(_run_spec(settings, weight, seed, overrides), run_dir, progress)
            variants.setdefault(name, (weight, []))[1].append((seed, final))
    return evaluate_variants(variants, settings, out, overrides)


def evaluate_variants(
    variants: dict[str, tuple[float, list[tuple[int, Path]]]],
    settings: CompareSettings,
    out: str | Path,
    env_options: dict[str, Any] | None = None,
    eval_env_overrides: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Evaluate every variant's policies on the same command and seeds; write compare.png/.md/.json into ``out``.

    ``variants``: name -> (margin weight, [(training seed, policy file), ...]). A policy inside a run directory
    is evaluated into ``<run>/eval``, any other (e.g. a bundled one) into ``<out>/eval/<variant>__s<seed>`` (with
    ``eval_env_overrides``, ``eval_<digest>`` instead of ``eval``: :func:`eval_folder`; each run's folder is its
    ``"eval_dir"`` in the report).
    ``env_options``: the options the runs were trained with (recorded); ``eval_env_overrides``: EnvConfig fields
    changed for the evaluation only (a bundle's own learned-margin weights). With both variants, the report's
    ``"statistics"`` holds, per table metric, "with margin" against "without margin" over the training seeds
    (:func:`margin_rl.train.analysis.significance.compare_seeds` as a dict). The settings' grid cells
    (:meth:`CompareSettings.grid_cells`) are evaluated the same way into ``<run>/eval_grid/<cell>`` (or
    ``<out>/eval_grid/<variant>__s<seed>/<cell>``), each with its variants and statistics in ``report["grid"]``.
    """
    out = Path(out)
    # recipes' and --terrain-difficulty's options are config dataclasses: recorded as JSON gives them back
    report: dict[str, Any] = {"settings": _settings_json(settings), "env_options": _json_ready(dict(env_options or {}))}
    if eval_env_overrides:
        report["eval_env_overrides"] = _json_ready(dict(eval_env_overrides))
    main_cell = (DEFAULT_CONDITION, settings.forward_velocity)
    report["variants"], examples = _evaluate_cell(variants, settings, out, eval_env_overrides, main_cell)
    report.update(_variant_statistics(report["variants"]))
    if settings.grid_cells():
        report["grid"] = []
        for condition, command in settings.grid_cells():
            cell, _ = _evaluate_cell(variants, settings, out, eval_env_overrides, (condition, command))
            report["grid"].append(
                {"condition": condition, "forward_velocity": command, "variants": cell, **_variant_statistics(cell)}
            )
    out.mkdir(parents=True, exist_ok=True)
    report["plot"] = plot_accelerations(examples, out / "compare.png", settings).name
    report["table"] = write_markdown(report, out / "compare.md").name
    write_json(out / "compare.json", report)
    return report


def eval_folder(kind: str, eval_env_overrides: dict[str, Any] | None) -> str:
    """A run's evaluation folder: ``kind`` ("eval", "eval_grid") in the run's own environment, ``<kind>_<digest>``
    (the first 8 hex digits of the overrides' JSON's SHA-256) in a changed one, e.g. a fixed terrain difficulty, so
    that comparisons of the same runs in several environments keep (and reuse) each other's evaluations."""
    if not eval_env_overrides:
        return kind
    text = json.dumps(_json_ready(dict(eval_env_overrides)), sort_keys=True)
    return f"{kind}_{hashlib.sha256(text.encode()).hexdigest()[:8]}"


def cell_name(condition: str, forward_velocity: float) -> str:
    """Folder of one grid cell's evaluation: ``<condition>__v<command>``."""
    return f"{condition}__v{forward_velocity:g}"


def _evaluate_cell(
    variants: dict[str, tuple[float, list[tuple[int, Path]]]],
    settings: CompareSettings,
    out: Path,
    eval_env_overrides: dict[str, Any] | None,
    cell: tuple[str, float],
) -> tuple[dict[str, Any], dict[str, Evaluation]]:
    """Every variant's policies in one (condition, command) cell: the variants' report and a first episode each."""
    condition, command = cell
    main = cell == (DEFAULT_CONDITION, settings.forward_velocity)
    report: dict[str, Any] = {}
    examples: dict[str, Evaluation] = {}
    folder = eval_folder("eval" if main else "eval_grid", eval_env_overrides)
    for name, (weight, policies) in variants.items():
        runs, terrain = [], "flat"
        for seed, policy in policies:
            config = find_run_config(policy, levels=1)
            in_run = config is not None and (config.parent / PROGRESS_FILE).is_file()
            eval_dir = config.parent / folder if in_run else out / folder / f"{name.replace(' ', '_')}__s{seed}"
            request = {
                "policy_sha256": sha256_file(policy),
                "env_overrides": _json_ready(dict(eval_env_overrides or {})),
                "episodes": settings.eval_episodes,
                "seed": settings.eval_seed,
                "forward_velocity": command,
                "warmup_s": settings.warmup_s,
                "condition": condition,
            }
            if not main:
                eval_dir = eval_dir / cell_name(condition, command)
            # the main cell's plot needs one fresh episode per variant: its first policy is always evaluated
            needs_example = main and name not in examples
            metrics = None if needs_example else _reusable_evaluation(eval_dir, request)
            if metrics is None:
                metrics, evaluation = evaluate(
                    policy,
                    env_overrides=eval_env_overrides,
                    episodes=settings.eval_episodes,
                    seed=settings.eval_seed,
                    forward_velocity=command,
                    warmup_s=settings.warmup_s,
                    out_dir=eval_dir,
                    condition=condition,
                )
                write_json(eval_dir / REQUEST_FILE, request)
                examples.setdefault(name, evaluation)
            summary = {k: v["mean"] for k, v in metrics["summary"].items()}
            terrain = metrics.get("env_config", {}).get("terrain", "flat")  # the same for every run of a comparison
            run_dir = str(config.parent) if in_run else None
            runs.append(
                {"seed": seed, "run_dir": run_dir, "policy": str(policy), "eval_dir": str(eval_dir), "metrics": summary}
            )
            if metrics.get("not_computed"):  # null in "metrics": say why (present only then)
                runs[-1]["not_computed"] = metrics["not_computed"]
        table = {key: mean_std([r["metrics"][key] for r in runs]) for key in comparison_metrics(terrain)}
        report[name] = {
            "margin_weight": weight,
            "runs": runs,
            "mean": {k: v[0] for k, v in table.items()},
            "std": {k: v[1] for k, v in table.items()},
        }
    return report, examples


REQUEST_FILE = "request.json"
"""Beside a compare evaluation's ``metrics.json``: what was asked (policy checksum, options, episodes, seeds, cell);
an evaluation asked again with the same request reuses its metrics, so a long comparison continues where it
stopped (in the main cell, every policy but each variant's first, whose episode the plot shows)."""


def _json_ready(value: Any) -> Any:
    """``value`` as JSON would give it back (config dataclasses as dicts, tuples as lists, paths as strings)."""
    return json.loads(json.dumps(value, default=lambda o: asdict(o) if is_dataclass(o) else str(o)))


def _reusable_evaluation(eval_dir: Path, request: dict[str, Any]) -> dict[str, Any] | None:
    """The metrics of an evaluation in ``eval_dir`` made for exactly ``request``, else None."""
    metrics, asked = eval_dir / "metrics.json", eval_dir / REQUEST_FILE
    if not (metrics.is_file() and asked.is_file()) or read_json(asked) != request:
        return None
    return read_json(metrics)


def _variant_statistics(variants: dict[str, Any]) -> dict[str, Any]:
    """``{"statistics": ...}`` (with margin against without, per metric) when both variants are there, else {}."""
    if not {"without margin", "with margin"} <= set(variants):
        return {}
    differences = compare_variants(variants, "without margin", "with margin")
    return {"statistics": {metric: asdict(difference) for metric, difference in differences.items()}}


def _settings_json(settings: CompareSettings) -> dict[str, Any]:
    data = asdict(settings)
    data["seeds"] = list(settings.seeds)
    for key in ("grid_commands", "grid_conditions"):
        data[key] = list(data[key])
    return data


def write_markdown(report: dict[str, Any], path: Path) -> Path:
    """The comparison table (mean ± std over training seeds) as Markdown, then, when the report has
    ``"statistics"``, the differences with − without margin with their interval and test."""
    s = report["settings"]
    lines = [
        f"# Margin reward comparison: {s['env_id']} ({s['backend']})",
        "",
        f"{len(s['seeds'])} training seed(s) {s['seeds']}, {s['total_steps']:,} environment steps each, "
        f"{s['num_envs']} environments; evaluation: {s['eval_episodes']} deterministic episode(s) from seed "
        f"{s['eval_seed']}, command {s['forward_velocity']:g} m/s, accelerations after the first "
        f"{s['warmup_s']:g} s. Values: mean ± std over training seeds of each seed's mean over its episodes.",
        "",
    ]
    lines += summary_table(report["variants"])
    missing = [
        f"- {key} ({name}, seed {run['seed']}): {reason}"
        for name, variant in report["variants"].items()
        for run in variant["runs"]
        for key, reason in run.get("not_computed", {}).items()
        if key in METRIC_LABELS
    ]
    if missing:
        lines += ["", "Not computed (n/a, or left out of a mean):", *missing]
    if report.get("statistics"):
        rows = [((METRIC_LABELS.get(k, k),), difference) for k, difference in report["statistics"].items()]
        lines += [
            "",
            "Differences with − without margin over training seeds (the unit: one seed's mean over its episodes): "
            "two-sided Welch t-test and the interval that inverts it, and a percentile bootstrap interval "
            f"({RESAMPLES:,} resamples of each variant's seeds; narrower than its nominal level with a few seeds). "
            "With a few seeds a test has little power: not significant is not no difference.",
            "",
            *difference_table(rows, difference_header="difference (with − without)"),
        ]
    if report.get("grid"):
        lines += ["", *grid_table(report)]
    lines += ["", f"![base acceleration]({report['plot']})", ""]
    path.write_text("\n".join(lines))
    return path


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="margin-rl-compare", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_env_arguments(parser)
    d = CompareSettings()
    parser.add_argument("--backend", choices=("rsl", "sb3"), default=d.backend)
    parser.add_argument(
        "--margin-weight",
        type=float,
        default=None,
        help=f"weight of the margin variant (default the recipe's, {CLI_MARGIN_WEIGHT:g} without); {DEFAULTS_HELP}",
    )
    add_recipe_argument(
        parser, "train both variants with a training recipe (margin_rl.train.recipes); options given here replace its"
    )
    parser.add_argument("--seeds", type=int, default=len(d.seeds), help="number of training seeds (0, 1, ...)")
    parser.add_argument("--num-envs", type=int, help=f"environments (default {d.num_envs}, or the recipe's)")
    parser.add_argument(
        "--total-steps", type=int, help=f"environment steps per run (default {d.total_steps}, or the recipe's)"
    )
    parser.add_argument("--checkpoint-every", type=int, default=d.checkpoint_every)
    parser.add_argument("--eval-episodes", type=int, help=f"evaluation episodes per policy (default {d.eval_episodes})")
    parser.add_argument("--eval-seed", type=int, help=f"seed of the evaluation episodes (default {d.eval_seed})")
    parser.add_argument("--forward-velocity", type=float, help=f"command [m/s] (default {d.forward_velocity:g})")
    parser.add_argument("--warmup-s", type=float, help=f"seconds left out of accelerations (default {d.warmup_s:g})")
    parser.add_argument(
        "--eval-commands",
        type=float,
        nargs="+",
        help="also evaluate at these commands [m/s] (a grid with --eval-conditions; see CompareSettings)",
    )
    parser.add_argument(
        "--eval-conditions",
        nargs="+",
        choices=tuple(CONDITIONS),
        help="also evaluate in these conditions (margin_rl.train.analysis.conditions), at every command; "
        f"'{DEFAULT_CONDITION}' alone: the commands only (e.g. to evaluate a bundle on fewer cells than its card's)",
    )
    parser.add_argument("--device", default=d.device)
    parser.add_argument("--out", type=Path, help="output folder (default runs/compare__<env>__<backend>)")
    parser.add_argument(
        "--bundle", type=Path, metavar="DIR", help="after the comparison, write its policies and a card into DIR"
    )
    parser.add_argument(
        "--bundled",
        metavar="NAME",
        help="train nothing: evaluate a policy bundle (shipped name, e.g. anymal_b, or a folder) with the "
        "evaluation settings of its card unless given here",
    )
    parser.add_argument(
        "--runs",
        nargs="+",
        type=Path,
        metavar="RUN_DIR",
        help="train nothing: evaluate these finished runs (margin weight 0 and one other weight) like compare's own",
    )
    parser.add_argument("--no-progress", action="store_true")
    return parser


_EVAL_OPTIONS = ("eval_episodes", "eval_seed", "forward_velocity", "warmup_s")


def _eval_overrides(args: argparse.Namespace) -> dict[str, Any]:
    options = {k: getattr(args, k) for k in _EVAL_OPTIONS if getattr(args, k) is not None}
    if args.eval_commands is not None:
        options["grid_commands"] = tuple(args.eval_commands)
    if args.eval_conditions is not None:
        options["grid_conditions"] = tuple(args.eval_conditions)
    return options


def _settings_from_args(args: argparse.Namespace) -> CompareSettings:
    d = CompareSettings()
    recipe = recipe_of(args.recipe)
    return CompareSettings(
        env_id=args.env or DEFAULT_ENV,
        backend=args.backend,
        margin_weight=(
            args.margin_weight
            if args.margin_weight is not None
            else recipe.margin_weight
            if recipe
            else CLI_MARGIN_WEIGHT
        ),
        seeds=tuple(range(args.seeds)),
        num_envs=args.num_envs or (recipe.num_envs if recipe else d.num_envs),
        total_steps=args.total_steps or (recipe.total_steps if recipe else d.total_steps),
        recipe=recipe.name if recipe else None,
        checkpoint_every=args.checkpoint_every,
        device=args.device,
        **_eval_overrides(args),
    )


def variants_of_runs(runs: list[Path]) -> tuple[str, dict[str, tuple[float, list[tuple[int, Path]]]]]:
    """(environment id, variants) of finished training runs: margin weight 0 is "without margin", the one other
    weight "with margin", each run's seed from its ``config.json``. A bundle's policy folder
    (``<bundle>/<variant>__s<seed>``) counts as a finished run: its TorchScript actor is evaluated, and a bundle
    written from the comparison carries the facts of its training from the source card
    (:func:`~margin_rl.train.artifacts.bundle.bundled_policy_entry`).

    Raises:
        ValueError: a run that is not finished, runs of several environments, or not exactly one nonzero weight.
    """
    found: dict[float, list[tuple[int, Path]]] = {}
    env_ids = set()
    for run in runs:
        config, progress = run / CONFIG_FILE, run / PROGRESS_FILE
        bundled = bundled_policy_entry(run) is not None
        if not (bundled or (config.is_file() and progress.is_file() and read_json(progress).get("finished"))):
            raise ValueError(
                f"--runs {run}: not a finished training run (no config.json, or progress not finished), nor a "
                "bundled policy folder (<bundle>/<variant>__s<seed>)"
            )
        data = read_json(config)
        policy = run / (POLICY_FILE if bundled else final_model_name(data["backend"]))
        env_ids.add(data["env_id"])
        weight = float(data["env_config"]["margin_weight"])
        found.setdefault(weight, []).append((int(data["seed"]), policy))
    weights = sorted(found)
    if len(env_ids) != 1 or len(weights) != 2 or weights[0] != 0.0:
        raise ValueError(
            f"--runs: give finished runs of one environment with margin weight 0 and one other weight; got "
            f"environments {sorted(env_ids)} and weights {weights}"
        )
    variants = {"without margin": (0.0, sorted(found[0.0])), "with margin": (weights[1], sorted(found[weights[1]]))}
    return env_ids.pop(), variants


def run_bundled(
    name: str,
    out: str | Path,
    eval_overrides: dict[str, Any] | None = None,
    env_overrides: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Evaluate a policy bundle (see :mod:`margin_rl.train.artifacts.bundle`) like ``compare`` evaluates its runs.

    ``eval_overrides``: CompareSettings evaluation fields replacing the card's; ``env_overrides``: EnvConfig
    fields for the evaluation (e.g. rough terrain, or other learned-margin weights than the bundle's own).
    """
    bundle = load_bundle(name)
    stored = dict(bundle.card["settings"])
    stored["seeds"] = tuple(stored["seeds"])
    for key in ("grid_commands", "grid_conditions"):  # JSON lists; absent in cards written before grids existed
        if key in stored:
            stored[key] = tuple(stored[key])
    settings = CompareSettings(**{**stored, **dict(eval_overrides or {})})
    overrides = {**bundle.env_overrides(), **dict(env_overrides or {})}
    report = evaluate_variants(bundle.variants(), settings, out, bundle.card.get("env_options"), overrides)
    report["bundle"] = {"name": bundle.name, "path": str(bundle.path), "card_table": bundle.card["table"]}
    write_json(Path(out) / "compare.json", report)
    return report


def _provenance(command: list[str], wall_time_s: float) -> dict[str, Any]:
    cpuinfo = Path("/proc/cpuinfo")
    lines = cpuinfo.read_text().splitlines() if cpuinfo.is_file() else []
    names = [line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")]
    cpu = names[0] if names else platform.processor() or platform.machine()
    machine = f"{cpu}, {os.cpu_count()} logical cores, {platform.system()}"
    return {
        "command": " ".join(command),
        "commit": git_commit(),
        "machine": machine,
        "wall_time_s": wall_time_s,
        "versions": versions(),
    }


def main(argv: list[str] | None = None) -> int:
    """Console entry point."""
    parser = build_parser()
    args = parser.parse_args(argv)
    command = ["margin-rl-compare", *(sys.argv[1:] if argv is None else argv)]
    env_id = args.env or DEFAULT_ENV
    t0 = time.perf_counter()
    if args.bundle is not None and args.bundled is not None:
        parser.error("--bundle writes the policies of trained or --runs runs; --bundled evaluates a bundle: give one")
    try:
        if args.runs is not None:
            run_env, variants = variants_of_runs(args.runs)
            first = load_spec(variants["with margin"][1][0][1].parent)
            settings = dataclasses.replace(
                _settings_from_args(args),
                env_id=run_env,
                backend=first.backend,
                margin_weight=variants["with margin"][0],
                seeds=tuple(seed for seed, _ in variants["with margin"][1]),
                num_envs=first.num_envs,
                total_steps=first.total_steps,
                recipe=first.recipe,
            )
            out = args.out or Path("results") / f"compare__{run_env.split('/')[-1]}__runs"
            options = env_overrides(args)
            options.pop("margin_weight", None)  # the runs' variants fix their weights
            report = evaluate_variants(variants, settings, out, None, options or None)
        elif args.bundled is not None:
            out = args.out or Path("results") / f"bundled__{Path(args.bundled).name}"
            options = env_overrides(args)
            options.pop("margin_weight", None)  # the bundle's variants fix their weights
            report = run_bundled(args.bundled, out, _eval_overrides(args), options)
        else:
            settings = _settings_from_args(args)
            options = env_overrides(args)
            options.pop("margin_weight", None)  # each variant sets its own
            if settings.recipe is not None:
                options = with_recipe(get_recipe(settings.recipe), options)
            options = with_training_defaults(env_id, options, margin_weight=False)
            out = args.out or Path("runs") / f"compare__{env_id.split('/')[-1]}__{args.backend}"
            report = run_compare(settings, out, options, progress=not args.no_progress)
        if args.bundle is not None:  # the policies of trained or given runs (--bundled is one already: refused)
            provenance = _provenance(command, time.perf_counter() - t0)
            provenance["trained_here"] = args.runs is None  # --runs: the wall time is the evaluation's only
            write_bundle(report, args.bundle, provenance)
            print(f"wrote the policy bundle {args.bundle}")
    except (ValueError, TypeError) as exc:
        parser.error(str(exc))
    except KeyboardInterrupt as exc:
        print(f"\n{exc or 'interrupted'}", file=sys.stderr)
        return 130
    print(Path(out / report["table"]).read_text())
    print(f"wrote {out / 'compare.png'}, {out / 'compare.md'}, {out / 'compare.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
