"""Which simulator an environment runs on: the backends by name and the factory that builds one.

A backend is a construction argument of the environments (``physics=``, ``physics_device=``,
``physics_options=``), not an EnvConfig field, so that a run made with one evaluates and resumes with another.
Every backend satisfies :class:`~margin_rl.envs.physics.PhysicsBackend`.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import mujoco

from margin_rl.envs.physics import MujocoBatchPhysics, PhysicsBackend

PHYSICS_BACKENDS: tuple[str, ...] = ("mujoco", "warp")
"""The simulators behind the seam, by the name a user passes (``physics=``): ``"mujoco"``
(:class:`MujocoBatchPhysics`, the default) and ``"warp"`` (:class:`~margin_rl.envs.physics_warp.WarpPhysics`,
MuJoCo Warp, the optional ``gpu`` extra)."""


@dataclass(frozen=True)
class PhysicsChoice:
    """The simulator behind a core's seam: backend name, device and the backend's own settings (kept with a
    pickled core, not in its EnvConfig)."""

    name: str
    device: str | None
    options: dict[str, Any]

    @property
    def arguments(self) -> tuple[str, str | None, dict[str, Any]]:
        """(physics, physics_device, physics_options), the construction arguments of a core or a training env."""
        return self.name, self.device, self.options


def make_physics(
    name: str, model: mujoco.MjModel, num_envs: int, device: str | None = None, options: Mapping[str, Any] | None = None
) -> PhysicsBackend:
    """The backend ``name`` (one of :data:`PHYSICS_BACKENDS`) of ``num_envs`` simulations of ``model``.

    ``device``: where the backend computes (``"mujoco"``: None or ``"cpu"``; ``"warp"``: a Warp device, None for
    the first GPU); ``options``: the backend's own settings (``"mujoco"``: ``nthread``; ``"warp"``: ``nconmax``,
    ``njmax``).

    Raises:
        ValueError: an unknown backend or device. TypeError: an option the backend does not take.
        ImportError: ``"warp"`` without MuJoCo Warp installed (the message says how to install it).
    """
    backend = check_physics_choice(name, device, options)
    arguments = {} if name == "mujoco" else {"device": device}
    return backend(model, num_envs, **arguments, **dict(options or {}))


def check_physics_choice(name: str, device: str | None, options: Mapping[str, Any] | None) -> type:
    """The backend class of ``name``, once ``device`` and the names of ``options`` are known to suit it (what
    :func:`make_physics` takes; checked before a run writes anything).

    Raises:
        ValueError: an unknown backend or device. TypeError: an option the backend does not take.
        ImportError: ``"warp"`` without MuJoCo Warp installed (the message says how to install it).
    """
    if name not in PHYSICS_BACKENDS:
        raise ValueError(f"physics must be one of {list(PHYSICS_BACKENDS)}, got {name!r}")
    if name == "mujoco":
        if device not in (None, "cpu"):
            raise ValueError(
                f"physics='mujoco' runs on the CPU, got physics_device={device!r}; use physics='warp' for a GPU"
            )
        backend: type = MujocoBatchPhysics
    else:
        from margin_rl.envs.physics_warp import WarpPhysics, check_warp_device  # the optional gpu extra

        check_warp_device(device)
        backend = WarpPhysics
    accepted = [
        p for p in inspect.signature(backend.__init__).parameters if p not in ("self", "model", "num_envs", "device")
    ]
    unknown = sorted(set(options or {}) - set(accepted))
    if unknown:
        raise TypeError(f"physics_options {unknown} are not settings of physics={name!r}; it takes {accepted}")
    return backend
