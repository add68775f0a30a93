"""Bundled policies: the trained policies of a ``compare`` run, shipped inside the package with a card.

A bundle is a folder ``margin_rl/train/bundled/<name>/`` (or any folder given by path)::

    card.json                        compare settings, command, commit, training time, metrics (the main cell, the
                                     grid of commands and conditions when evaluated, the differences with their
                                     tests), sha256 per file, and the earlier versions' tables (``history``)
    CARD.md                          the same for people, with the comparison table
    <variant>__s<seed>/policy.pt     TorchScript deterministic actor (observations -> actions; no pickle)
    <variant>__s<seed>/config.json   the training run's config.json: the environment to evaluate it in
    learned_margin/<robot>.npz/.json the learned-margin weights and card the policies were trained with

``compare --bundle <dir>`` writes one from a finished comparison; ``compare --bundled <name>`` evaluates one
(the README's main job). Writing a bundle over an existing one keeps the replaced card's numbers in the new
card's ``history`` (and CARD.md), newest first, so a retrained bundle still shows what its predecessors measured.
Loading verifies every file against the card's checksums, so a truncated or edited
policy is refused instead of silently evaluated. Carrying its own learned-margin weights keeps a bundle
reproducible when the package's bundled margin weights are retrained: the policies' actions never depend on
the margin (it is not a policy observation), but their reward did, and the card's margin column is measured
with these weights. (``evaluate`` on one bundled ``policy.pt`` uses the package's weights unless given
``--margin-weights <bundle>/learned_margin/<robot>.npz``.)
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from margin_rl.provenance import sha256_file
from margin_rl.stability.learned.model import LearnedMargin, weights_path
from margin_rl.train.analysis.significance import grid_table
from margin_rl.train.environments import weights_identity
from margin_rl.train.metrics import summary_table
from margin_rl.train.runs import CONFIG_FILE, PROGRESS_FILE, TORCHSCRIPT_FILE, final_model_name, read_json, write_json

BUNDLE_ROOT = Path(__file__).resolve().parents[1] / "bundled"
CARD_FILE = "card.json"
CARD_MARKDOWN = "CARD.md"
POLICY_FILE = "policy.pt"
MARGIN_FOLDER = "learned_margin"
CARD_FORMAT = 2
READABLE_CARD_FORMATS = (1, 2)  # format 1: no copy of the learned-margin weights


@dataclass(frozen=True)
class BundledRun:
    """One bundled policy: its comparison variant, margin weight, training seed and TorchScript file."""

    variant: str
    margin_weight: float
    seed: int
    policy: Path


@dataclass(frozen=True)
class Bundle:
    """A verified bundle: its card and its policies in card order."""

    name: str
    path: Path
    card: dict[str, Any]
    runs: tuple[BundledRun, ...]
    margin_weights: Path | None = None  # the learned-margin .npz the policies were trained with (format >= 2)

    def env_overrides(self) -> dict[str, Any]:
        """EnvConfig overrides that evaluate the policies as the card's figures were measured: in the card's
        evaluation environment (``eval_env_overrides``, e.g. a rough terrain at a fixed difficulty; none for flat
        bundles) and with the margin they were trained with (the bundle's own weights, whatever the card names)."""
        overrides = {k: v for k, v in self.card.get("eval_env_overrides", {}).items() if k != "margin_weights"}
        if self.margin_weights is not None:
            overrides["margin_weights"] = str(self.margin_weights)
        return overrides

    def variants(self) -> dict[str, tuple[float, list[tuple[int, Path]]]]:
        """Variant name -> (margin weight, [(training seed, policy file), ...])."""
        grouped: dict[str, tuple[float, list[tuple[int, Path]]]] = {}
        for run in self.runs:
            grouped.setdefault(run.variant, (run.margin_weight, []))[1].append((run.seed, run.policy))
        return grouped


def bundled_names() -> tuple[str, ...]:
    """Names of the bundles shipped with the package."""
    if not BUNDLE_ROOT.is_dir():
        return ()
    return tuple(sorted(p.name for p in BUNDLE_ROOT.iterdir() if (p / CARD_FILE).is_file()))


def _slug(variant: str) -> str:
    return variant.replace(" ", "_")


def load_bundle(name_or_path: str | Path) -> Bundle:
    """A bundle by shipped name (see :func:`bundled_names`) or folder, with every file's checksum verified.

    Raises:
        ValueError: unknown name, missing card or file, checksum mismatch, or an unsupported card format.
    """
    folder = Path(name_or_path)
    if not (folder / CARD_FILE).is_file():
        folder = BUNDLE_ROOT / str(name_or_path)
    if not (folder / CARD_FILE).is_file():
        raise ValueError(
            f"no policy bundle {str(name_or_path)!r}: shipped bundles are {list(bundled_names())}, or give a folder "
            f"holding {CARD_FILE} (written by `compare --bundle`)"
        )
    card = read_json(folder / CARD_FILE)
    if card.get("format") not in READABLE_CARD_FORMATS:
        raise ValueError(
            f"{folder / CARD_FILE}: card format {card.get('format')!r}, this package reads {READABLE_CARD_FORMATS}"
        )
    runs = []
    for entry in card["policies"]:
        for key in ("policy", "config"):
            _verify(folder, entry[key], entry[f"{key}_sha256"])
        weight, seed = float(entry["margin_weight"]), int(entry["seed"])
        runs.append(BundledRun(entry["variant"], weight, seed, folder / entry["policy"]))
    margin = card.get("learned_margin_weights")
    margin_weights = None
    if margin is not None:
        for key in ("npz", "card"):
            _verify(folder, margin[key], margin[f"{key}_sha256"])
        margin_weights = folder / margin["npz"]
        trained_with = {e["learned_margin"]["sha256"] for e in card["policies"] if _margin_in_reward(e)}
        if trained_with - {margin["npz_sha256"]}:
            raise ValueError(
                f"{folder / CARD_FILE}: policies were trained with learned-margin weights {sorted(trained_with)}, "
                f"but the bundle carries {margin['npz_sha256']}; rewrite the bundle with `compare --bundle`"
            )
    return Bundle(folder.name, folder, card, tuple(runs), margin_weights)


def _verify(folder: Path, relative: str, sha256: str) -> None:
    """Refuse a bundle file that is missing or differs from the card's checksum."""
    path = folder / relative
    if not path.is_file():
        raise ValueError(f"{folder}: {relative} listed in {CARD_FILE} is missing; reinstall margin_rl")
    digest = sha256_file(path)
    if digest != sha256:
        raise ValueError(
            f"{path}: checksum mismatch (card {sha256}, file {digest}); the file was changed "
            "or truncated: reinstall margin_rl or rewrite the bundle with `compare --bundle`"
        )


def _margin_in_reward(entry: dict[str, Any]) -> bool:
    """Whether a card entry's policy was rewarded with a learned margin: at margin weight 0 the network its
    environment loaded only logged the margin, so a baseline may be bundled beside margin policies trained with
    another network (its own identity stays recorded in its entry)."""
    return bool(entry.get("learned_margin")) and float(entry["margin_weight"]) != 0.0


def copy_margin_weights(entries: list[dict[str, Any]], folder: Path) -> dict[str, Any] | None:
    """Copy the learned-margin weights (npz + card) that the runs in ``entries`` were rewarded with into
    ``folder/learned_margin/``; returns the card record, or None when no run's reward used a learned margin
    (the runs at margin weight 0 do not count: :func:`_margin_in_reward`).

    Raises:
        ValueError: the runs used different weights (one bundle carries one margin model), or the weights
            changed since training (their checksum no longer matches the one recorded for the runs).
    """
    identities = {
        (e["learned_margin"]["source"], e["learned_margin"]["sha256"]) for e in entries if _margin_in_reward(e)
    }
    if not identities:
        return None
    if len(identities) > 1:
        raise ValueError(f"the runs were trained with different learned-margin weights {sorted(identities)}")
    ((source, sha256),) = identities
    npz = weights_path(source)
    if LearnedMargin.load(npz).card.get("sha256") != sha256:
        raise ValueError(
            f"{npz} changed since the runs were trained with it (sha256 {sha256}); the bundle must carry the "
            "weights the policies were trained with: restore them or retrain the policies"
        )
    (folder / MARGIN_FOLDER).mkdir(exist_ok=True)
    record: dict[str, Any] = {"source": source}
    for key, path in (("npz", npz), ("card", npz.with_suffix(".json"))):
        relative = f"{MARGIN_FOLDER}/{path.name}"
        shutil.copyfile(path, folder / relative)
        record[key], record[f"{key}_sha256"] = relative, sha256_file(folder / relative)
    return record


def margin_model_identity(run_config: dict[str, Any]) -> dict[str, Any] | None:
    """Which learned margin a run's environment used: {"source": robot name or weights path, "sha256": of the
    weights}, or None when the run used no learned margin. Stored per policy in the card, so that evaluating
    a bundled policy with other margin weights than it was trained with can be detected. The identity the run
    recorded when it started is used; runs recorded before that field existed fall back to the weights the
    source loads now (:func:`copy_margin_weights` then checks them against every run of the bundle)."""
    if "learned_margin" in run_config:
        return run_config["learned_margin"]
    env = run_config.get("env_config") or {}
    if env.get("margin") != "learned":
        return None
    return weights_identity(env.get("margin_weights") or env["robot"])


def final_action_std(run_dir: Path) -> float | None:
    """The mean action-noise std an rsl-rl run ended with (``infos["action_std"]`` of its final model), or None
    for an SB3 run or a model saved before checkpoints recorded it (see :mod:`margin_rl.train.exploration`)."""
    final = run_dir / final_model_name("rsl")
    if not final.is_file():
        return None
    infos = torch.load(final, map_location="cpu", weights_only=True).get("infos", {})
    value = infos.get("action_std")
    return None if value is None else float(value)


REUSED_FACTS = (
    "env_steps",
    "training_sessions",
    "steps_per_s_last_session",
    "final_action_std",
    "learned_margin",
    "training_command",
    "init_from",
)
"""The training facts a bundled policy brings from its card into a new bundle that reuses it."""


def bundled_policy_entry(folder: str | Path) -> tuple[dict[str, Any], dict[str, Any]] | None:
    """(card, the card's entry) when ``folder`` is one policy folder of a bundle (``<bundle>/<variant>__s<seed>``
    holding the ``policy.pt`` and ``config.json`` its card lists), else None. Lets a new bundle reuse policies
    that need no retraining (e.g. baselines, whose training never read the margin) with their training facts.

    Raises:
        ValueError: the folder is listed in its bundle's card but a file's checksum does not match.
    """
    folder = Path(folder)
    card_file = folder.parent / CARD_FILE
    if not ((folder / POLICY_FILE).is_file() and card_file.is_file()):
        return None
    card = read_json(card_file)
    for entry in card.get("policies", []):
        if Path(entry["policy"]).parent.name == folder.name:
            for key in ("policy", "config"):
                _verify(folder.parent, entry[key], entry[f"{key}_sha256"])
            return card, entry
    return None


def _bundled_record(policy: Path, variant: str, weight: float) -> tuple[Path, Path, dict[str, Any]]:
    """(TorchScript file, config.json, training facts) of a policy reused from another bundle (its card's facts,
    and where it came from)."""
    found = bundled_policy_entry(policy.parent)
    if found is None:
        raise ValueError(f"{policy} is neither in a training run nor listed in a bundle's {CARD_FILE}")
    card, entry = found
    if float(entry["margin_weight"]) != weight:
        raise ValueError(
            f"{policy} was trained at margin weight {entry['margin_weight']:g}, not the {weight:g} of {variant!r}"
        )
    facts = {
        "variant": variant,
        "margin_weight": weight,
        "seed": int(entry["seed"]),
        **{key: entry.get(key) for key in REUSED_FACTS},
        "reused_from": {
            "bundle": card["name"],
            "commit": card.get("provenance", {}).get("commit"),
            "policy": entry["policy"],
        },
    }
    return policy, policy.parent / CONFIG_FILE, facts


def _command_text(command: list[str]) -> str | None:
    """A run's recorded command line as a user types it: the program by its name, not the path it was started by
    (runs recorded before ``train`` wrote its name have e.g. ``.venv/bin/margin-rl-train``)."""
    if not command:
        return None
    program, *argv = (str(part) for part in command)
    return " ".join([Path(program).name, *argv])


def _run_record(run: dict[str, Any], variant: str, weight: float) -> tuple[Path, Path, dict[str, Any]]:
    """(TorchScript file, config.json, training facts) of one compare run, or of a policy reused from a bundle
    (:func:`bundled_policy_entry`); clear error when unfinished."""
    if run.get("run_dir") is None:
        policy, config, facts = _bundled_record(Path(run["policy"]), variant, weight)
        return policy, config, {**facts, "metrics": run["metrics"]}
    run_dir = Path(run["run_dir"])
    policy, config = run_dir / TORCHSCRIPT_FILE, run_dir / CONFIG_FILE
    for path in (policy, config):
        if not path.is_file():
            raise ValueError(f"{path} is missing: the run of {variant!r}, seed {run['seed']} has not finished")
    progress = read_json(run_dir / PROGRESS_FILE) if (run_dir / PROGRESS_FILE).is_file() else {}
    run_config = read_json(config)
    sessions = run_config.get("sessions", [])
    facts = {
        "variant": variant,
        "margin_weight": weight,
        "seed": int(run["seed"]),
        "env_steps": progress.get("env_steps"),
        "training_sessions": len(sessions),
        "steps_per_s_last_session": progress.get("session_steps_per_s"),
        "final_action_std": final_action_std(run_dir),
        "learned_margin": margin_model_identity(run_config),
        # how the run was trained (the command line of its first `train` call; a warm start names its source model)
        "training_command": _command_text(run_config.get("command", [])),
        "init_from": run_config.get("init_from"),
        "metrics": run["metrics"],
    }
    return policy, config, facts


def _variant_table(variants: dict[str, Any]) -> dict[str, Any]:
    """Per variant its margin weight and the mean and std over training seeds (a report's runs left out)."""
    return {
        name: {"margin_weight": v["margin_weight"], "mean": v["mean"], "std": v["std"]} for name, v in variants.items()
    }


def _measured_differences(report: dict[str, Any]) -> dict[str, Any]:
    """The report's with − without statistics of the main cell and its grid of commands and conditions (each
    cell's variant table and statistics), the keys a report has."""
    found: dict[str, Any] = {}
    if report.get("statistics"):
        found["statistics"] = report["statistics"]
    if report.get("grid"):
        found["grid"] = [
            {
                "condition": cell["condition"],
                "forward_velocity": cell["forward_velocity"],
                "variants": _variant_table(cell["variants"]),
                **({"statistics": cell["statistics"]} if cell.get("statistics") else {}),
            }
            for cell in report["grid"]
        ]
    return found


HISTORY_KEYS = ("name", "settings", "env_options", "provenance", "table", "statistics", "grid")
"""What the card of a replaced bundle passes on to its successor's ``history`` (its policies are gone)."""


def card_history(dest: Path) -> list[dict[str, Any]]:
    """The ``history`` of a bundle about to be written into ``dest``: the card found there (its settings,
    provenance and measured tables, with the seeds and learned margin of its policies), then that card's own
    history; empty when ``dest`` holds no bundle card.

    Raises:
        ValueError: ``dest`` has a card that cannot be read, so its numbers would be lost.
    """
    card_file = dest / CARD_FILE
    if not card_file.is_file():
        return []
    try:
        previous = read_json(card_file)
        entry = {key: previous[key] for key in HISTORY_KEYS if key in previous}
        entry["seeds"] = policy_seeds(previous["policies"])
        if previous.get("learned_margin_weights"):
            entry["learned_margin_sha256"] = previous["learned_margin_weights"]["npz_sha256"]
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(
            f"{card_file} cannot be read ({exc!r}): writing a bundle over it would lose its numbers; move the "
            "folder away or mend its card first"
        ) from exc
    return [entry, *previous.get("history", [])]


def write_bundle(report: dict[str, Any], dest: str | Path, provenance: dict[str, Any]) -> Path:
    """Copy the TorchScript actors and run configs of a finished ``compare`` report into ``dest``, with a card.

    ``provenance``: what produced the report (command, commit, wall time, machine), written into the card.
    The bundle is assembled in a temporary sibling folder and moved into place, so an interrupted write
    leaves the previous bundle (if any) intact.
    """
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", dir=dest.parent))
    try:
        entries = []
        for variant, data in report["variants"].items():
            for run in data["runs"]:
                policy, config, facts = _run_record(run, variant, float(data["margin_weight"]))
                folder = f"{_slug(variant)}__s{facts['seed']}"
                (staging / folder).mkdir()
                shutil.copyfile(policy, staging / folder / POLICY_FILE)
                shutil.copyfile(config, staging / folder / CONFIG_FILE)
                entries.append(
                    {
                        **facts,
                        "policy": f"{folder}/{POLICY_FILE}",
                        "config": f"{folder}/{CONFIG_FILE}",
                        "policy_sha256": sha256_file(staging / folder / POLICY_FILE),
                        "config_sha256": sha256_file(staging / folder / CONFIG_FILE),
                    }
                )
        card = {
            "format": CARD_FORMAT,
            "name": dest.name,
            "settings": report["settings"],
            "env_options": report.get("env_options", {}),
            # the evaluation's own environment options (compare --runs ... --terrain-difficulty D): --bundled reuses
            # them
            "eval_env_overrides": report.get("eval_env_overrides", {}),
            "provenance": provenance,
            "table": _variant_table(report["variants"]),
            **_measured_differences(report),
            "policies": entries,
            "learned_margin_weights": copy_margin_weights(entries, staging),
            "history": card_history(dest),
        }
        write_json(staging / CARD_FILE, card)
        (staging / CARD_MARKDOWN).write_text(card_markdown(card))
        os.chmod(staging, 0o755)
        _replace_folder(staging, dest)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return dest


def _replace_folder(new: Path, dest: Path) -> None:
    """Move ``new`` to ``dest``; an existing ``dest`` is moved aside first and deleted only afterwards."""
    old = None
    if dest.exists():
        old = dest.with_name(f".{dest.name}.old")
        shutil.rmtree(old, ignore_errors=True)
        os.replace(dest, old)
    try:
        os.replace(new, dest)
    except BaseException:
        if old is not None:
            os.replace(old, dest)
        raise
    if old is not None:
        with contextlib.suppress(OSError):
            shutil.rmtree(old)


def card_markdown(card: dict[str, Any]) -> str:
    """The card for people: what was trained, how, from which commit, and the measured table."""
    s, p = card["settings"], card["provenance"]
    # compare --runs evaluates runs trained before it (provenance "trained_here": False)
    timed = "training and evaluation"
    if not p.get("trained_here", True):
        timed = "evaluation only: the runs were trained before"
    # the seeds of each variant, from the policies (a --runs comparison may hold more seeds of one variant)
    seed_text = _seeds_text(policy_seeds(card["policies"]))
    if p.get("trained_here", True):
        options = f"environment options `{card['env_options']}`"
    else:  # compare --runs: each run's own options, in its training command below and its config.json
        options = "each run's environment options are in its training command below"
    lines = [
        f"# Policy bundle `{card['name']}`",
        "",
        f"PPO ({s['backend']}) on `{s['env_id']}`, {seed_text}; "
        f"{s['total_steps']:,} environment steps per run on {s['num_envs']} environments"
        + (f", training recipe `{s['recipe']}`" if s.get("recipe") else "")
        + f"; {options}.",
        "",
        f"- command: `{p.get('command', '?')}`",
        f"- package commit: `{p.get('commit', '?')}`",
        f"- machine: {p.get('machine', '?')}",
        f"- wall time of the comparison ({timed}): {p.get('wall_time_s', float('nan')) / 60:.1f} min",
        *([f"- note: {p['note']}"] if p.get("note") else []),
        *(
            [
                f"- learned margin: `{m['npz']}` (sha256 {m['npz_sha256'][:12]}, copied from `{m['source']}`), the "
                "weights these policies were trained with; `compare --bundled` measures the margin with them"
            ]
            if (m := card.get("learned_margin_weights"))
            else []
        ),
        "",
        f"Evaluation: {s['eval_episodes']} deterministic episodes from seed {s['eval_seed']}, command "
        f"{s['forward_velocity']:g} m/s, accelerations after {s['warmup_s']:g} s; mean ± std over training seeds.",
        *(
            [
                "Evaluation environment options (as `--env-option`s; `compare --bundled` applies them): "
                f"`{json.dumps(o)}`"
            ]
            if (o := card.get("eval_env_overrides"))
            else []
        ),
        "",
    ]
    lines += summary_table(card["table"])
    if card.get("grid"):
        lines += ["", *grid_table(card_report(card))]
    lines += [
        "",
        "| policy | margin weight | seed | env steps | final action std | sha256 (first 12) |",
        "|---|---|---|---|---|---|",
    ]
    for e in card["policies"]:
        steps = f"{e['env_steps']:,}" if e.get("env_steps") is not None else "?"
        std = f"{e['final_action_std']:.3f}" if e.get("final_action_std") is not None else "not recorded"
        digest = e["policy_sha256"][:12]
        lines.append(f"| `{e['policy']}` | {e['margin_weight']:g} | {e['seed']} | {steps} | {std} | {digest} |")
    commands = [e for e in card["policies"] if e.get("training_command") or e.get("reused_from")]
    if commands and not p.get("trained_here", True):
        lines += ["", "Training commands (each run's `config.json`):", ""]
        lines += [
            f"- `{e['policy']}`: "
            + (f"`{e['training_command']}`" if e.get("training_command") else "not recorded")
            + _reused_text(e)
            for e in commands
        ]
    if card.get("history"):
        lines += [
            "",
            "## Earlier versions of this bundle",
            "",
            "Newest first; their policies were replaced by the ones above.",
        ]
        for earlier in card["history"]:
            lines += ["", *_history_markdown(earlier)]
    return "\n".join(lines) + "\n"


def _reused_text(entry: dict[str, Any]) -> str:
    """Where a reused policy was trained: its package commit and the learned margin its environment loaded."""
    source = entry.get("reused_from")
    if not source:
        return ""
    margin = entry.get("learned_margin")
    weights = f", learned margin sha256 {margin['sha256'][:12]}" if margin else ""
    commit = str(source.get("commit") or "?")[:12]
    return f" (trained at package commit `{commit}`{weights}; reused from bundle `{source['bundle']}`)"


def policy_seeds(policies: list[dict[str, Any]]) -> dict[str, list[int]]:
    """Variant -> its training seeds, ascending, from a card's policy entries (variants in card order)."""
    seeds: dict[str, list[int]] = {}
    for policy in policies:
        seeds.setdefault(policy["variant"], []).append(int(policy["seed"]))
    return {variant: sorted(found) for variant, found in seeds.items()}


def _seeds_text(seeds: dict[str, list[int]]) -> str:
    return "; ".join(f"{variant}: seeds {found}" for variant, found in seeds.items())


def card_report(card: dict[str, Any]) -> dict[str, Any]:
    """A card's measured tables with the keys of a ``compare`` report (for the shared table writers)."""
    return {
        "settings": card["settings"],
        "variants": card["table"],
        "statistics": card.get("statistics", {}),
        "grid": card.get("grid", []),
    }


def _history_markdown(earlier: dict[str, Any]) -> list[str]:
    """One replaced version of a bundle for people: how it was made and what it measured."""
    s, p = earlier["settings"], earlier.get("provenance", {})
    seeds = _seeds_text(earlier.get("seeds", {}))
    lines = [
        f"### Package commit `{str(p.get('commit', '?'))[:12]}`: `{s['env_id']}`, {s['total_steps']:,} steps per run"
        + (f", recipe `{s['recipe']}`" if s.get("recipe") else "")
        + (f", environment options `{earlier['env_options']}`" if earlier.get("env_options") else ""),
        "",
        f"- command: `{p.get('command', '?')}`",
        *([f"- {seeds}"] if seeds else []),
        *(
            [f"- learned margin sha256 {earlier['learned_margin_sha256'][:12]}"]
            if earlier.get("learned_margin_sha256")
            else []
        ),
        f"- evaluation: {s['eval_episodes']} deterministic episodes from seed {s['eval_seed']}, command "
        f"{s['forward_velocity']:g} m/s",
        "",
        *summary_table(earlier["table"]),
    ]
    if earlier.get("grid"):
        lines += ["", *grid_table(card_report(earlier))]
    return lines
