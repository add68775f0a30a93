"""Load a saved policy of any kind for deterministic evaluation, and check that it fits an environment.

Kinds (recognised from the file's contents, not its name):

* ``sb3``: a Stable-Baselines3 PPO ``.zip`` (``final_model.zip``, ``checkpoints/ckpt_*.zip``). SB3 unpickles
  parts of it: a warning says so; load only files from a source you trust.
* ``rsl``: an rsl-rl checkpoint (``final_model.pt``, ``checkpoints/ckpt_*.pt``), loaded with
  ``torch.load(weights_only=True)``. The actor is rebuilt from the training config stored in the checkpoint
  (or the run's ``config.json``).
* ``torchscript``: an exported actor (``policy_torchscript.pt``, also rsl-rl's ``export_policy_to_jit``).

Every kind becomes a :class:`LoadedPolicy`: ``policy(obs)`` maps (N, obs) float32 to deterministic actions
(N, 12). :meth:`LoadedPolicy.check` raises :class:`PolicyMismatchError` when the observation or action size
differs from the environment's.
"""

from __future__ import annotations

import copy
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rsl_rl.utils import resolve_class
from stable_baselines3 import PPO
from tensordict import TensorDict

from margin_rl.train.backends.sb3 import warn_unpickling
from margin_rl.train.runs import find_run_config, read_json, torchscript_export

POLICY_KINDS: tuple[str, ...] = ("sb3", "rsl", "torchscript")


class PolicyMismatchError(ValueError):
    """A policy whose observation or action size does not fit the environment."""


@dataclass
class LoadedPolicy:
    """A deterministic policy: ``policy(obs (N, obs_dim) float32) -> actions (N, action_dim)``."""

    kind: str
    path: Path
    obs_dim: int | None  # None when the file does not declare it (TorchScript without linear layers)
    action_dim: int | None
    act: Callable[[np.ndarray], np.ndarray]
    train_config: dict[str, Any] | None = None  # the run's config.json, when found

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.act(np.ascontiguousarray(obs, dtype=np.float32))

    def check(self, obs_dim: int, action_dim: int, env: str = "the environment") -> None:
        """Raise :class:`PolicyMismatchError` unless the policy maps ``obs_dim`` inputs to ``action_dim`` outputs."""
        where = f"{self.path} ({self.kind} policy)"
        if self.obs_dim is not None and self.obs_dim != obs_dim:
            raise PolicyMismatchError(
                f"{where} expects observations of size {self.obs_dim}, but {env} gives {obs_dim}: "
                "it was trained on another environment or observation layout"
            )
        if self.action_dim is not None and self.action_dim != action_dim:
            raise PolicyMismatchError(
                f"{where} outputs {self.action_dim} actions, but {env} takes {action_dim}: "
                "it was trained for another robot or action space"
            )
        try:
            out = self(np.zeros((2, obs_dim), dtype=np.float32))
        except RuntimeError as exc:
            raise PolicyMismatchError(f"{where} rejects observations of size {obs_dim} from {env}: {exc}") from exc
        if out.shape != (2, action_dim):
            raise PolicyMismatchError(
                f"{where} returned actions of shape {out.shape[1:]} for {env}, which takes ({action_dim},)"
            )


def detect_kind(path: str | Path) -> str:
    """``"sb3"``, ``"rsl"`` or ``"torchscript"`` from the file's archive layout.

    Raises:
        FileNotFoundError: no such file.
        ValueError: not one of the three kinds.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"policy file not found: {path}")
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path} is not a policy file (expected an SB3 .zip, an rsl-rl checkpoint or TorchScript)")
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
    if "data" in names and "policy.pth" in names:
        return "sb3"
    if any("/code/" in n for n in names) or any(n.endswith("/constants.pkl") for n in names):
        return "torchscript"
    if any(n.endswith("/data.pkl") for n in names):
        return "rsl"
    raise ValueError(f"{path}: unrecognised archive (not an SB3 .zip, an rsl-rl checkpoint or TorchScript)")


def load_policy(path: str | Path, kind: str | None = None) -> LoadedPolicy:
    """Load a policy file of any kind (detected when ``kind`` is None) on the CPU."""
    path = Path(path)
    kind = kind or detect_kind(path)
    run_config = _run_config(path)
    loaders = {"sb3": _load_sb3, "rsl": _load_rsl, "torchscript": _load_torchscript}
    if kind not in loaders:
        raise ValueError(f"policy kind must be one of {POLICY_KINDS}, got {kind!r}")
    policy = loaders[kind](path, run_config)
    policy.train_config = run_config
    return policy


def _run_config(path: Path) -> dict[str, Any] | None:
    """The ``config.json`` of the margin_rl run holding ``path``, or None (also for unrelated config files)."""
    config_path = find_run_config(path, levels=2)
    if config_path is None:
        return None
    try:
        data = read_json(config_path)
    except ValueError:
        return None
    keys = {"env_id", "backend", "backend_config"}
    return data if isinstance(data, dict) and keys <= set(data) else None


def _load_sb3(path: Path, run_config: dict[str, Any] | None) -> LoadedPolicy:
    warn_unpickling(path)
    try:
        model = PPO.load(path, device="cpu")
    except Exception as exc:  # SB3 raises many kinds for a zip that is not a PPO model
        raise ValueError(f"{path}: could not load an SB3 PPO model ({type(exc).__name__}: {exc})") from exc

    def act(obs: np.ndarray) -> np.ndarray:
        actions, _ = model.predict(obs, deterministic=True)
        return np.asarray(actions, dtype=np.float64)

    obs_shape, act_shape = model.observation_space.shape, model.action_space.shape
    obs_dim = int(np.prod(obs_shape)) if obs_shape else None
    action_dim = int(np.prod(act_shape)) if act_shape else None
    return LoadedPolicy("sb3", path, obs_dim, action_dim, act)


def _linear_dims(state: dict[str, Any], prefix: str) -> tuple[int | None, int | None]:
    """(input size of the first, output size of the last) 2-D weight under ``prefix`` in a state dict."""
    weights = [v for k, v in state.items() if k.startswith(prefix) and k.endswith("weight") and v.ndim == 2]
    if not weights:
        return None, None
    return int(weights[0].shape[1]), int(weights[-1].shape[0])


def _load_rsl(path: Path, run_config: dict[str, Any] | None) -> LoadedPolicy:
    try:
        loaded = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # pickle.UnpicklingError for files that need full unpickling, among others
        raise ValueError(f"{path}: not loadable with torch.load(weights_only=True): {exc}") from exc
    if not isinstance(loaded, dict) or "actor_state_dict" not in loaded:
        raise ValueError(f"{path}: not an rsl-rl checkpoint (no 'actor_state_dict')")
    infos = loaded.get("infos") or {}
    train_cfg = infos.get("train_cfg") or (run_config or {}).get("backend_config")
    if not train_cfg or "actor" not in train_cfg:
        raise ValueError(
            f"{path}: the checkpoint carries no rsl-rl training config and no run config.json was found next to it"
        )
    state = loaded["actor_state_dict"]
    obs_dim, action_dim = _linear_dims(state, "mlp.")
    if obs_dim is None or action_dim is None:
        raise ValueError(f"{path}: the actor is not an MLP (no mlp.* weights); only MLP actors are supported")
    actor_class, actor_cfg = resolve_class(copy.deepcopy(train_cfg["actor"]))
    dummy = TensorDict({"policy": torch.zeros(1, obs_dim)}, batch_size=[1])
    actor = actor_class(dummy, {"actor": ["policy"]}, "actor", action_dim, **actor_cfg)
    actor.load_state_dict(state, strict=True)
    actor.eval()

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            td = TensorDict({"policy": torch.from_numpy(obs)}, batch_size=[obs.shape[0]])
            return actor(td).numpy().astype(np.float64)

    return LoadedPolicy("rsl", path, obs_dim, action_dim, act)


def _load_torchscript(path: Path, run_config: dict[str, Any] | None) -> LoadedPolicy:
    with torchscript_export():
        module = torch.jit.load(str(path), map_location="cpu")
    module.eval()
    weights = [p for _, p in module.named_parameters() if p.ndim == 2]
    obs_dim = int(weights[0].shape[1]) if weights else None
    action_dim = int(weights[-1].shape[0]) if weights else None

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            return module(torch.from_numpy(obs)).numpy().astype(np.float64)

    return LoadedPolicy("torchscript", path, obs_dim, action_dim, act)
