"""Command-line options and defaults shared by ``train``, ``evaluate`` and ``compare``.

:func:`add_env_arguments` adds the options that shape the environment, :func:`env_overrides` turns them into
EnvConfig field overrides.

Training defaults of the command line (``train`` and ``compare``): the shipped bundles' experiment, the recipe
:data:`~margin_rl.train.recipes.SHIPPED_RECIPE` (:func:`add_recipe_argument`, ``--recipe none`` for none) with its
margin weight (:data:`CLI_MARGIN_WEIGHT`, also the weight without a recipe) and ``reward_params.alive_bonus``
:data:`CLI_ALIVE_BONUS` (:func:`with_training_defaults`). ``EnvConfig``'s own defaults (the paper's reward: weight 1,
no bonus) stay what the Python API and the environments use: with them, a trot's negative learned margin makes every
step's reward negative and PPO learns to fall.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from typing import Any

from margin_rl.envs.config import REWARD_PRESETS
from margin_rl.envs.margin_kinds import MARGIN_KINDS
from margin_rl.envs.terrain import TerrainConfig, at_difficulty
from margin_rl.train.config import parse_assignments
from margin_rl.train.environments import DEFAULT_ENV, anymal_id
from margin_rl.train.recipes import NO_RECIPE, RECIPES, SHIPPED_RECIPE, TrainingRecipe, get_recipe

CLI_MARGIN_WEIGHT = RECIPES[SHIPPED_RECIPE].margin_weight
"""Margin-reward weight of ``train`` (and of ``compare``'s margin variant) unless ``--margin-weight`` is given: the
shipped recipe's, with or without a recipe (another recipe brings its own)."""
CLI_ALIVE_BONUS = 0.1
"""``reward_params.alive_bonus`` of ``train`` and ``compare`` unless ``--env-option reward_params.alive_bonus=...``
(or a ``reward_params`` mapping naming ``alive_bonus``) is given."""
DEFAULTS_HELP = (
    f"the shipped bundles' experiment: --recipe {SHIPPED_RECIPE} (--recipe {NO_RECIPE} for none), its --margin-weight "
    f"{CLI_MARGIN_WEIGHT:g} and --env-option reward_params.alive_bonus={CLI_ALIVE_BONUS:g} (EnvConfig's own defaults, "
    "weight 1 and no bonus, make PPO learn to fall)"
)


def add_recipe_argument(parser: argparse.ArgumentParser, help_text: str) -> None:
    """``--recipe NAME`` (default :data:`~margin_rl.train.recipes.SHIPPED_RECIPE`; ``none``: no recipe)."""
    parser.add_argument(  # no argparse default: --resume tells a given --recipe from none given
        "--recipe",
        choices=(*RECIPES, NO_RECIPE),
        help=f"{help_text} (default {SHIPPED_RECIPE}, the shipped bundles'; {NO_RECIPE}: no recipe)",
    )


def recipe_of(name: str | None) -> TrainingRecipe | None:
    """The recipe of ``--recipe NAME``: :data:`~margin_rl.train.recipes.SHIPPED_RECIPE` when not given, None for
    ``none``."""
    if name == NO_RECIPE:
        return None
    return get_recipe(SHIPPED_RECIPE if name is None else name)


def add_env_arguments(parser: argparse.ArgumentParser) -> None:
    """Options that shape the environment (``train``, ``evaluate``, ``compare``)."""
    parser.add_argument("--env", default=None, help=f"margin_rl ANYmal id (default {DEFAULT_ENV})")
    parser.add_argument("--margin", choices=tuple(MARGIN_KINDS), help="margin used by the env")
    parser.add_argument("--margin-weights", help="learned-margin weights .npz with its card (default: bundled)")
    parser.add_argument("--reward-preset", choices=tuple(REWARD_PRESETS), help="reward preset (default paper)")
    parser.add_argument(
        "--terrain-difficulty",
        type=float,
        metavar="D",
        help="rough ground at D in [0, 1] of seed 000's Fig. 8 scale (steps 6-18 cm and inclines to 15 degrees times "
        "D): the default 24 m square of tiles of every type, seeded by the environment's seed; the fixed-difficulty "
        "terrains of rough-ground comparisons (sets terrain and terrain_config)",
    )
    parser.add_argument(
        "--env-option",
        action="append",
        metavar="KEY=VALUE",
        help="any EnvConfig field, e.g. command='{\"forward_velocity\": [0.5, 1.0]}', or one entry of a mapping "
        "field, e.g. reward_params.alive_bonus=0.1. VALUE in JSON (repeatable)",
    )


def env_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """Environment option overrides from the shared environment options (and ``--margin-weight``, if any)."""
    overrides = parse_assignments(args.env_option, "--env-option")
    for key in ("margin", "margin_weights", "reward_preset"):
        if getattr(args, key, None) is not None:
            overrides[key] = getattr(args, key)
    if getattr(args, "margin_weight", None) is not None:
        overrides["margin_weight"] = args.margin_weight
    if getattr(args, "terrain_difficulty", None) is not None:
        if "terrain_config" in overrides:
            raise ValueError("--terrain-difficulty sets terrain_config: give one of it and --env-option terrain_config")
        overrides["terrain"] = "rough"
        overrides["terrain_config"] = at_difficulty(TerrainConfig(), args.terrain_difficulty)
    return overrides


def with_training_defaults(env_id: str, overrides: Mapping[str, Any], margin_weight: bool = True) -> dict[str, Any]:
    """``overrides`` with the command line's training defaults filled in: ``reward_params.alive_bonus``
    :data:`CLI_ALIVE_BONUS` and, with ``margin_weight``, ``margin_weight`` :data:`CLI_MARGIN_WEIGHT`, unless given
    (the other ``reward_params`` entries given are kept).

    Raises:
        ValueError: ``env_id`` is not a batched ANYmal id (:func:`~margin_rl.train.environments.anymal_id`).
    """
    anymal_id(env_id)
    defaults = {"margin_weight": CLI_MARGIN_WEIGHT} if margin_weight else {}
    params = overrides.get("reward_params", {})
    if isinstance(params, Mapping):  # anything else is passed on, for the config check to name
        params = {"alive_bonus": CLI_ALIVE_BONUS, **params}
    return {**defaults, **overrides, "reward_params": params}
