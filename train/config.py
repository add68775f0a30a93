"""PPO settings per backend (frozen dataclasses), kept apart from the environment config.

Defaults follow legged_gym's flat ANYmal task (``LeggedRobotCfgPPO`` + ``AnymalCFlatCfgPPO``): actor and critic
MLPs [128, 64, 32] with ELU, initial action noise std 1.0, learning rate 1e-3 with the KL-adaptive schedule
(desired KL 0.01), γ 0.99, λ 0.95, clip 0.2, entropy 0.01, value-loss coefficient 1.0 (clipped), 5 epochs,
4 minibatches, 24 steps per environment and iteration, gradient-norm clip 1.0.

SB3's PPO has no KL-adaptive learning rate; its closest equivalent here is the same learning rate with
``target_kl`` early stopping of the epochs (documented difference, see :class:`Sb3PPOConfig`).

Both configs, and the environment's :class:`~margin_rl.envs.config.EnvConfig`, are written as JSON into every
run directory; :func:`from_dict` rebuilds them (nested dataclasses, tuples, optionals) for ``--resume``. A config
class may translate dicts stored by its earlier versions (a classmethod ``upgrade_stored(data) -> dict``, as
``EnvConfig`` has for its v0 fields) and name what replaced an unknown field (a classmethod
``unknown_field_hint(names) -> str``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from dataclasses import dataclass
from typing import Any, Union

import torch

BACKENDS: tuple[str, ...] = ("rsl", "sb3")
"""``rsl``: rsl-rl's OnPolicyRunner (PPO); ``sb3``: Stable-Baselines3's PPO."""


@dataclass(frozen=True)
class RslPPOConfig:
    """rsl-rl 5.x OnPolicyRunner + PPO settings (legged_gym flat ANYmal defaults)."""

    actor_hidden_dims: tuple[int, ...] = (128, 64, 32)
    critic_hidden_dims: tuple[int, ...] = (128, 64, 32)
    activation: str = "elu"
    init_noise_std: float = 1.0  # initial std of the Gaussian action noise [action units]
    obs_normalization: bool = False  # legged_gym used fixed observation scales (already in the env)
    learning_rate: float = 1e-3
    schedule: str = "adaptive"  # "adaptive" (KL-driven learning rate) or "fixed"
    desired_kl: float = 0.01
    gamma: float = 0.99  # discount per policy step (20 ms)
    lam: float = 0.95  # GAE λ
    clip_param: float = 0.2
    entropy_coef: float = 0.01
    value_loss_coef: float = 1.0
    use_clipped_value_loss: bool = True
    max_grad_norm: float = 1.0
    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    num_steps_per_env: int = 24  # rollout length per iteration [policy steps]

    def __post_init__(self) -> None:
        if self.schedule not in ("adaptive", "fixed"):
            raise ValueError(f"schedule must be 'adaptive' or 'fixed', got {self.schedule!r}")
        _check_positive(self, ("learning_rate", "num_learning_epochs", "num_mini_batches", "num_steps_per_env"))

    @property
    def steps_per_env(self) -> int:
        """Policy steps each environment takes per PPO update."""
        return self.num_steps_per_env

    def runner_cfg(self, privileged: bool, save_interval: int, run_name: str = "") -> dict[str, Any]:
        """The ``train_cfg`` dict of ``rsl_rl.runners.OnPolicyRunner`` (rsl-rl-lib 5.x layout).

        ``privileged``: the critic also reads the observation group ``"critic"`` (privileged terms).
        ``save_interval``: checkpoint every this many iterations.
        """
        critic_groups = ["policy", "critic"] if privileged else ["policy"]
        return {
            "num_steps_per_env": self.num_steps_per_env,
            "save_interval": int(save_interval),
            "run_name": run_name,
            # the environment core checks its observations and rewards itself (at once on the host; on a device
            # once per rollout, without the host read per step rsl-rl's check costs: docs/environments.md)
            "check_for_nan": False,
            "logger": "tensorboard",
            "obs_groups": {"actor": ["policy"], "critic": critic_groups},
            "algorithm": {
                "class_name": "PPO",
                "learning_rate": self.learning_rate,
                "schedule": self.schedule,
                "desired_kl": self.desired_kl,
                "gamma": self.gamma,
                "lam": self.lam,
                "clip_param": self.clip_param,
                "entropy_coef": self.entropy_coef,
                "value_loss_coef": self.value_loss_coef,
                "use_clipped_value_loss": self.use_clipped_value_loss,
                "max_grad_norm": self.max_grad_norm,
                "num_learning_epochs": self.num_learning_epochs,
                "num_mini_batches": self.num_mini_batches,
                "rnd_cfg": None,
                "symmetry_cfg": None,
            },
            "actor": {
                "class_name": "MLPModel",
                "hidden_dims": list(self.actor_hidden_dims),
                "activation": self.activation,
                "obs_normalization": self.obs_normalization,
                "distribution_cfg": {
                    "class_name": "GaussianDistribution",
                    "init_std": self.init_noise_std,
                    "std_type": "scalar",
                },
            },
            "critic": {
                "class_name": "MLPModel",
                "hidden_dims": list(self.critic_hidden_dims),
                "activation": self.activation,
                "obs_normalization": self.obs_normalization,
            },
        }


@dataclass(frozen=True)
class Sb3PPOConfig:
    """Stable-Baselines3 PPO settings equivalent to :class:`RslPPOConfig`.

    Differences from rsl-rl that SB3 does not offer: no KL-adaptive learning rate (``target_kl`` stops the
    epochs of an update early instead, at 1.5 × target_kl), a state-independent log-std initialised at
    ``log(init_noise_std)``, orthogonal initialisation, advantages normalised per minibatch.
    """

    net_arch: tuple[int, ...] = (128, 64, 32)  # same for the policy and the value network (not shared)
    activation: str = "elu"  # "elu", "tanh" or "relu"
    init_noise_std: float = 1.0
    learning_rate: float = 1e-3
    target_kl: float | None = 0.01
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 1.0
    max_grad_norm: float = 1.0
    n_epochs: int = 5
    num_mini_batches: int = 4  # batch_size = n_steps * num_envs / num_mini_batches
    n_steps: int = 24  # rollout length per environment and update [policy steps]
    normalize_advantage: bool = True
    ortho_init: bool = True

    def __post_init__(self) -> None:
        if self.activation not in _ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(_ACTIVATIONS)}, got {self.activation!r}")
        _check_positive(self, ("learning_rate", "n_epochs", "num_mini_batches", "n_steps", "init_noise_std"))

    @property
    def steps_per_env(self) -> int:
        """Policy steps each environment takes per PPO update."""
        return self.n_steps

    def ppo_kwargs(self, num_envs: int) -> dict[str, Any]:
        """Keyword arguments of ``stable_baselines3.PPO`` (besides policy, env, seed, device)."""
        rollout = self.n_steps * num_envs
        return {
            "learning_rate": self.learning_rate,
            "n_steps": self.n_steps,
            "batch_size": max(2, rollout // self.num_mini_batches),
            "n_epochs": self.n_epochs,
            "gamma": self.gamma,
            "gae_lambda": self.gae_lambda,
            "clip_range": self.clip_range,
            "ent_coef": self.ent_coef,
            "vf_coef": self.vf_coef,
            "max_grad_norm": self.max_grad_norm,
            "target_kl": self.target_kl,
            "normalize_advantage": self.normalize_advantage,
            "policy_kwargs": {
                "net_arch": {"pi": list(self.net_arch), "vf": list(self.net_arch)},
                "activation_fn": getattr(torch.nn, _ACTIVATIONS[self.activation]),
                "log_std_init": math.log(self.init_noise_std),
                "ortho_init": self.ortho_init,
            },
        }


_ACTIVATIONS: dict[str, str] = {"elu": "ELU", "tanh": "Tanh", "relu": "ReLU"}

PPOConfig = RslPPOConfig | Sb3PPOConfig
"""PPO settings of either backend."""


def default_ppo_config(backend: str) -> PPOConfig:
    """The default PPO settings of a backend (``"rsl"`` or ``"sb3"``)."""
    if backend == "rsl":
        return RslPPOConfig()
    if backend == "sb3":
        return Sb3PPOConfig()
    raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")


def _check_positive(config: object, names: tuple[str, ...]) -> None:
    for name in names:
        if getattr(config, name) <= 0:
            raise ValueError(f"{type(config).__name__}.{name} must be positive, got {getattr(config, name)!r}")


# ---------------------------------------------------------------------------------------------------------------------
# (de)serialisation of frozen config dataclasses
# ---------------------------------------------------------------------------------------------------------------------
def to_dict(config: object) -> dict[str, Any]:
    """A JSON-ready dict of a (nested) config dataclass; tuples become lists."""
    return json.loads(json.dumps(dataclasses.asdict(config)))  # type: ignore[arg-type]


def _coerce(hint: Any, value: Any, where: str) -> Any:
    """``value`` (from JSON or the command line) converted to the annotated type ``hint``."""
    origin = typing.get_origin(hint)
    if origin in (Union, types.UnionType):
        options = typing.get_args(hint)
        if value is None and type(None) in options:
            return None
        errors = []
        for option in (o for o in options if o is not type(None)):
            try:
                return _coerce(option, value, where)
            except (TypeError, ValueError) as exc:
                errors.append(str(exc))
        raise TypeError(f"{where}: {value!r} does not fit {hint} ({'; '.join(errors)})")
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        if isinstance(value, hint):
            return value
        if not isinstance(value, dict):
            raise TypeError(f"{where}: expected a mapping for {hint.__name__}, got {value!r}")
        return from_dict(hint, value, where)
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, (list, tuple)):
            raise TypeError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(args[0], v, where) for v in value)
        if len(args) != len(value):
            raise TypeError(f"{where}: expected {len(args)} values, got {value!r}")
        return tuple(_coerce(a, v, where) for a, v in zip(args, value, strict=True))
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TypeError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not (isinstance(value, int) or (isinstance(value, float) and value.is_integer())):
            raise TypeError(f"{where}: expected an integer, got {value!r}")
        return int(value)
    if hint is bool:
        if not isinstance(value, bool):
            raise TypeError(f"{where}: expected true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise TypeError(f"{where}: expected a string, got {value!r}")
        return value
    return value


def _unknown_hint(cls: type, unknown: list[str]) -> str:
    hint = getattr(cls, "unknown_field_hint", None)
    return hint(unknown) if hint is not None else ""


def from_dict(cls: type, data: dict[str, Any], where: str = "") -> Any:
    """Rebuild a (nested) frozen config dataclass from :func:`to_dict` output (or a dict stored by an earlier
    version of ``cls``, through its ``upgrade_stored``); unknown keys raise."""
    upgrade = getattr(cls, "upgrade_stored", None)
    if upgrade is not None and isinstance(data, dict):
        data = upgrade(data)
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise TypeError(
            f"{where or cls.__name__}: unknown option(s) {unknown}; known: {sorted(names)}{_unknown_hint(cls, unknown)}"
        )
    kwargs = {k: _coerce(hints[k], v, f"{where or cls.__name__}.{k}") for k, v in data.items()}
    return cls(**kwargs)


def apply_overrides(config: Any, overrides: dict[str, Any]) -> Any:
    """A copy of a config dataclass with some fields replaced; a nested config accepts a partial mapping."""
    if not overrides:
        return config
    current = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
    merged: dict[str, Any] = {}
    for key, value in overrides.items():
        if key not in current:
            raise TypeError(
                f"{type(config).__name__}: unknown option {key!r}; known: {sorted(current)}"
                f"{_unknown_hint(type(config), [key])}"
            )
        old = current[key]
        if dataclasses.is_dataclass(old) and isinstance(value, dict):
            value = {**to_dict(old), **value}
        merged[key] = value
    base = {k: v for k, v in to_dict(config).items() if k not in merged}
    return from_dict(type(config), {**base, **merged})


def parse_assignments(items: list[str] | None, what: str) -> dict[str, Any]:
    """``["key=value", ...]`` from the command line; values are JSON where they parse, else strings.

    A dotted key sets one entry of a mapping field: ``reward_params.alive_bonus=0.1`` gives
    ``{"reward_params": {"alive_bonus": 0.1}}``, merged with other entries given for the same field (its other
    entries keep their values, see :func:`apply_overrides`).
    """
    result: dict[str, Any] = {}
    for item in items or []:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"{what} must look like KEY=VALUE, got {item!r}")
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            value = text
        field_name, dot, entry = key.partition(".")
        if not dot:
            both_mappings = isinstance(result.get(key), dict) and isinstance(value, dict)
            result[key] = {**result[key], **value} if both_mappings else value
            continue
        if not field_name or not entry or "." in entry:
            raise ValueError(f"{what}: a dotted KEY must be FIELD.ENTRY (e.g. reward_params.alive_bonus), got {key!r}")
        holder = result.setdefault(field_name, {})
        if not isinstance(holder, dict):
            raise ValueError(f"{what}: {field_name} is given as {holder!r} and as {key}=...; give one of them")
        holder[entry] = value
    return result
