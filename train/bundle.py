"""Bundled policies: the trained policies of a ``compare`` run, shipped inside the package with a card.

A bundle is a folder ``margin_rl/train/bundled/<name>/`` (or any folder given by path)::

    card.json                        compare settings, command, commit, training time, metrics, sha256 per file
    CARD.md                          the same for people, with the comparison table
    <variant>__s<seed>/policy.pt     TorchScript deterministic actor (observations -> actions; no pickle)
    <variant>__s<seed>/config.json   the training run's config.json: the environment to evaluate it in

``compare --bundle <dir>`` writes one from a finished comparison; ``compare --bundled <name>`` evaluates one
(the README's main job). Loading verifies every file against the card's checksums, so a truncated or edited
policy is refused instead of silently evaluated.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from margin_rl.provenance import sha256_file
from margin_rl.train.runs import CONFIG_FILE, PROGRESS_FILE, TORCHSCRIPT_FILE, read_json, write_json

BUNDLE_ROOT = Path(__file__).resolve().parent / "bundled"
CARD_FILE = "card.json"
CARD_MARKDOWN = "CARD.md"
POLICY_FILE = "policy.pt"
CARD_FORMAT = 1


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
    if card.get("format") != CARD_FORMAT:
        raise ValueError(f"{folder / CARD_FILE}: card format {card.get('format')!r}, this package reads {CARD_FORMAT}")
    runs = []
    for entry in card["policies"]:
        for key in ("policy", "config"):
            path = folder / entry[key]
            if not path.is_file():
                raise ValueError(f"{folder}: {entry[key]} listed in {CARD_FILE} is missing; reinstall margin_rl")
            digest = sha256_file(path)
            if digest != entry[f"{key}_sha256"]:
                raise ValueError(
                    f"{path}: checksum mismatch (card {entry[f'{key}_sha256']}, file {digest}); the file was changed "
                    "or truncated: reinstall margin_rl or rewrite the bundle with `compare --bundle`"
                )
        weight, seed = float(entry["margin_weight"]), int(entry["seed"])
        runs.append(BundledRun(entry["variant"], weight, seed, folder / entry["policy"]))
    return Bundle(folder.name, folder, card, tuple(runs))


def margin_model_identity(run_config: dict[str, Any]) -> dict[str, Any] | None:
    """Which learned margin a run's environment used: {"source": robot name or weights path, "sha256": of the
    weights}, or None when the run used no learned margin. Stored per policy in the card, so that evaluating
    a bundled policy with other margin weights than it was trained with can be detected."""
    from margin_rl.stability import LearnedMargin

    env = run_config.get("env_config") or {}
    if env.get("margin") != "learned":
        return None
    source = env.get("margin_weights") or env["robot"]
    return {"source": source, "sha256": LearnedMargin.load(source).card.get("sha256")}


def _run_record(run: dict[str, Any], variant: str, weight: float) -> tuple[Path, Path, dict[str, Any]]:
    """(TorchScript file, config.json, training facts) of one compare run; clear error when unfinished."""
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
        "learned_margin": margin_model_identity(run_config),
        "metrics": run["metrics"],
    }
    return policy, config, facts


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
            "provenance": provenance,
            "table": {
                name: {"margin_weight": v["margin_weight"], "mean": v["mean"], "std": v["std"]}
                for name, v in report["variants"].items()
            },
            "policies": entries,
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
    from margin_rl.train.metrics import summary_table

    s, p = card["settings"], card["provenance"]
    lines = [
        f"# Policy bundle `{card['name']}`",
        "",
        f"PPO ({s['backend']}) on `{s['env_id']}`, {len(s['seeds'])} training seeds {s['seeds']} per variant, "
        f"{s['total_steps']:,} environment steps per run on {s['num_envs']} environments; environment options "
        f"`{card['env_options']}`.",
        "",
        f"- command: `{p.get('command', '?')}`",
        f"- package commit: `{p.get('commit', '?')}`",
        f"- machine: {p.get('machine', '?')}",
        f"- wall time of the comparison (training and evaluation): {p.get('wall_time_s', float('nan')) / 60:.1f} min",
        *([f"- note: {p['note']}"] if p.get("note") else []),
        "",
        f"Evaluation: {s['eval_episodes']} deterministic episodes from seed {s['eval_seed']}, command "
        f"{s['forward_velocity']:g} m/s, accelerations after {s['warmup_s']:g} s; mean ± std over training seeds.",
        "",
    ]
    lines += summary_table(card["table"])
    lines += ["", "| policy | margin weight | seed | env steps | sha256 (first 12) |", "|---|---|---|---|---|"]
    for e in card["policies"]:
        steps = f"{e['env_steps']:,}" if e.get("env_steps") is not None else "?"
        digest = e["policy_sha256"][:12]
        lines.append(f"| `{e['policy']}` | {e['margin_weight']:g} | {e['seed']} | {steps} | {digest} |")
    return "\n".join(lines) + "\n"
