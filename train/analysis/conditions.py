"""Evaluation conditions: the worlds a policy is evaluated in, declared once, independent of how it was trained.

A policy trained with randomisation (friction, base mass, pushes, observation noise; the ``robust`` recipe of
:mod:`margin_rl.train.recipes`) must not meet that randomisation when it is measured: falls and accelerations
would then depend on the training recipe's random draws. Every evaluation (``evaluate``, ``compare``,
``push-recovery``) therefore runs in one of these conditions, each a rule that rewrites the training
environment's :class:`~margin_rl.envs.config.RandomizationConfig`:

* ``nominal`` (the default): the MJCF's floor friction and masses, no pushes, no observation noise; the training
  environment's reset noise (part of the initial-state distribution, the same for every policy of a recipe).
* ``friction_0.4`` / ``friction_1.0``: nominal on a floor of friction coefficient 0.4 (slippery) or 1.0.
* ``mass_-20`` / ``mass_+20``: nominal with the base body's mass 20 % lower or higher (the base's mass is read from
  the robot's MJCF by name): the model mismatch of a payload or a lighter shell.
* ``training``: the training environment unchanged (its randomisation on), e.g. to see what the policy met.

Every condition but ``training`` also measures the margin on the terrain's contact normals
(:attr:`~margin_rl.envs.config.EnvConfig.margin_normals` ``"terrain"``), the seed's margin, whatever normals the
policy was trained with, so that the margins of every variant of a comparison are the same quantity. The command,
terrain and everything else stay the training environment's (``evaluate`` fixes the command).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from margin_rl.envs.config import EnvConfig, RandomizationConfig
from margin_rl.robot import load_robot
from margin_rl.robot.mjcf_names import BASE_BODY

MASS_CHANGE = 0.2
"""Relative change of the base body's mass in the ``mass_-20`` / ``mass_+20`` conditions."""


def base_mass(robot: str) -> float:
    """Mass of the robot's base body in its MJCF [kg] (ANYmal B 16.8 kg, ANYmal C 19.2 kg)."""
    return float(load_robot(robot).mj_model.body(BASE_BODY).mass[0])


def nominal_randomization(training: RandomizationConfig) -> RandomizationConfig:
    """``training`` with friction, base-mass, push and observation-noise randomisation off (reset noise kept)."""
    return dataclasses.replace(
        training, friction=None, added_base_mass=None, push_interval_s=None, observation_noise=0.0
    )


def measured(config: EnvConfig, randomization: RandomizationConfig) -> EnvConfig:
    """``config`` with ``randomization`` and the seed's margin (terrain normals): an evaluation world."""
    return config.replace(randomization=randomization, margin_normals="terrain")


def _friction(mu: float) -> Callable[[EnvConfig], EnvConfig]:
    def apply(config: EnvConfig) -> EnvConfig:
        return measured(config, dataclasses.replace(nominal_randomization(config.randomization), friction=(mu, mu)))

    return apply


def _base_mass(relative: float) -> Callable[[EnvConfig], EnvConfig]:
    def apply(config: EnvConfig) -> EnvConfig:
        added = relative * base_mass(config.robot)
        randomization = dataclasses.replace(nominal_randomization(config.randomization), added_base_mass=(added, added))
        return measured(config, randomization)

    return apply


def _nominal(config: EnvConfig) -> EnvConfig:
    return measured(config, nominal_randomization(config.randomization))


CONDITIONS: dict[str, Callable[[EnvConfig], EnvConfig]] = {
    "nominal": _nominal,
    "friction_0.4": _friction(0.4),
    "friction_1.0": _friction(1.0),
    f"mass_-{MASS_CHANGE * 100:.0f}": _base_mass(-MASS_CHANGE),
    f"mass_+{MASS_CHANGE * 100:.0f}": _base_mass(MASS_CHANGE),
    "training": lambda config: config,
}
"""Condition name -> the rule that turns a training environment into the evaluation environment (module docstring)."""

DEFAULT_CONDITION = "nominal"


def check_condition(name: object) -> str:
    """``name`` if it is a condition.

    Raises:
        ValueError: naming the conditions.
    """
    if not isinstance(name, str) or name not in CONDITIONS:
        raise ValueError(f"unknown evaluation condition {name!r}; the conditions are {', '.join(CONDITIONS)}")
    return name


def condition_config(config: EnvConfig, name: str) -> EnvConfig:
    """The environment of condition ``name`` for a policy trained in ``config`` (see the module docstring)."""
    return CONDITIONS[check_condition(name)](config)
