"""The physics seam of :class:`~margin_rl.envs.core.AnymalCore`: every call it makes into the simulator.

:class:`PhysicsBackend` is the written contract; :class:`MujocoBatchPhysics` (this module, the default) and
:class:`~margin_rl.envs.physics_warp.WarpPhysics` (MuJoCo Warp) satisfy it, and
:func:`~margin_rl.envs.backends.make_physics` builds one by name. :class:`MujocoBatchPhysics` holds ``num_envs``
simulations of one MuJoCo model in ``mujoco.batch.Batch`` (a native thread pool, results bit-identical to one
``MjData`` per simulation at any thread count). The core reads the state through the live arrays below, writes
controls and external forces into them, and calls ``reset``, ``forward`` and ``step``; model constants come from
the lookups by name (:class:`ModelConstants`, shared by the backends).

Live arrays, ``(num_envs, ...)``: ``qpos``, ``qvel``, ``ctrl``, ``xfrc_applied`` and ``time`` are the state
(writes take effect at the next call); ``sensordata``, ``site_xpos``, ``xpos`` and ``actuator_force`` are
outputs, refreshed by every call.

``get_state`` and ``set_state`` carry the whole integration state (including the solver's warm start) and the
per-environment model fields, so that a restored copy steps to the same numbers (what pickling an environment
needs).
"""

from __future__ import annotations

import os
from typing import Any, Protocol

import mujoco
import numpy as np
from mujoco import batch as mj_batch

from margin_rl.arrays import like, to_numpy

SET_CONST_INPUTS = frozenset({"body_mass"})
"""Per-environment model fields written here that MuJoCo derives constants from (``mj_setConst``)."""


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the platform reports one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows: no affinity API
        return max(1, os.cpu_count() or 1)


class PhysicsBackend(Protocol):
    """The written contract of a physics backend: every member :class:`~margin_rl.envs.core.AnymalCore` uses.

    Live arrays, ``(num_envs, ...)`` (numpy arrays on the host, or torch tensors on the backend's device; writes
    take effect at the next call, outputs refreshed by every call): ``qpos``, ``qvel``, ``ctrl``, ``xfrc_applied``
    (``(num_envs, nbody, 6)``), ``time``; ``sensordata``, ``site_xpos``, ``xpos``, ``actuator_force``. Model
    constants are read by name from ``model`` (the MjModel the backend was built from). ``reset(ids, keyframe)``
    gives the worlds ``ids`` the keyframe's state, controls and clock and clears their applied forces (the core then
    writes only qpos and qvel). Both backends are checked against this protocol by the tests, member by member.
    """

    model: mujoco.MjModel
    num_envs: int
    qpos: np.ndarray
    qvel: np.ndarray
    time: np.ndarray
    ctrl: np.ndarray
    xfrc_applied: np.ndarray
    sensordata: np.ndarray
    site_xpos: np.ndarray
    xpos: np.ndarray
    actuator_force: np.ndarray

    @property
    def timestep(self) -> float: ...
    @property
    def nv(self) -> int: ...
    def body_id(self, name: str) -> int: ...
    def site_id(self, name: str) -> int: ...
    def geom_id(self, name: str) -> int: ...
    def keyframe(self, name: str) -> tuple[int, np.ndarray, np.ndarray]: ...
    def sensor_slice(self, name: str) -> slice: ...
    def sensor_adr(self, name: str) -> int: ...
    def body_mass(self, body: int) -> float: ...
    def geom_friction(self, geom: int) -> float: ...
    def per_env_field(self, name: str) -> np.ndarray: ...
    def set_const(self) -> None: ...
    def reset(self, ids: np.ndarray, keyframe: int) -> None: ...
    def forward(self, ids: np.ndarray | None = None) -> None: ...
    def step(self, nstep: int) -> np.ndarray: ...
    def check_overflow(self) -> None: ...
    def render_data(self, env: int) -> mujoco.MjData: ...
    def get_state(self) -> dict[str, Any]: ...
    def set_state(self, state: dict[str, Any]) -> None: ...


def restore_per_env_fields(backend: PhysicsBackend, fields: dict[str, np.ndarray]) -> None:
    """Write the per-environment model fields of a ``get_state`` into ``backend``; recompute the constants derived
    from them (``set_const``) only where a field of :data:`SET_CONST_INPUTS` changed: recomputing them from unchanged
    masses is wasted work in MuJoCo, and in Warp (float32) it would change their last bits, so that a restored copy
    would not step identically."""
    changed = {
        name for name, values in fields.items() if not np.array_equal(to_numpy(backend.per_env_field(name)), values)
    }
    for name in changed:
        live = backend.per_env_field(name)
        live[:] = like(fields[name], live, live.dtype)
    if SET_CONST_INPUTS & changed:
        backend.set_const()


def render_data(model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray) -> mujoco.MjData:
    """An MjData of ``model`` at (qpos, qvel), forwarded by MuJoCo (for rendering one environment)."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    data.qvel[:] = qvel
    mujoco.mj_forward(model, data)
    return data


class ModelConstants:
    """The model constants a backend reads from its MjModel ``model``, by name (shared by every backend)."""

    model: mujoco.MjModel

    @property
    def timestep(self) -> float:
        """Physics time step [s] (the MJCF's)."""
        return float(self.model.opt.timestep)

    @property
    def nv(self) -> int:
        """Degrees of freedom (the size of a ``qvel`` row)."""
        return int(self.model.nv)

    def body_id(self, name: str) -> int:
        return int(self.model.body(name).id)

    def site_id(self, name: str) -> int:
        return int(self.model.site(name).id)

    def geom_id(self, name: str) -> int:
        return int(self.model.geom(name).id)

    def keyframe(self, name: str) -> tuple[int, np.ndarray, np.ndarray]:
        """(id, qpos, ctrl) of the keyframe ``name`` (copies)."""
        key = int(self.model.key(name).id)
        return key, self.model.key_qpos[key].copy(), self.model.key_ctrl[key].copy()

    def sensor_slice(self, name: str) -> slice:
        """The entries of sensor ``name`` in a ``sensordata`` row."""
        sensor = self.model.sensor(name)
        return slice(int(sensor.adr[0]), int(sensor.adr[0] + sensor.dim[0]))

    def sensor_adr(self, name: str) -> int:
        """The first entry of sensor ``name`` in a ``sensordata`` row (a contact sensor's "found")."""
        return int(self.model.sensor(name).adr[0])

    def body_mass(self, body: int) -> float:
        """The model's mass of ``body`` [kg] (before any per-environment change)."""
        return float(self.model.body_mass[body])

    def geom_friction(self, geom: int) -> float:
        """The model's sliding friction coefficient of ``geom``."""
        return float(self.model.geom_friction[geom, 0])


class MujocoBatchPhysics(ModelConstants):
    """``num_envs`` simulations of ``model`` in one ``mujoco.batch.Batch`` (see the module docstring)."""

    def __init__(self, model: mujoco.MjModel, num_envs: int, nthread: int | None = None) -> None:
        """``nthread``: threads of the batch; None: one per core this process may run on (:func:`usable_cores`).
        (MuJoCo's nthread=0 would start one per core of the machine, so several trainings pinned to a few cores
        each, with taskset or cgroups, would oversubscribe.)"""
        self.model = model
        self.num_envs = num_envs
        self.batch = mj_batch.Batch(model, nsim=num_envs, nthread=usable_cores() if nthread is None else nthread)
        bind = self.batch.bind
        self.qpos, self.qvel, self.time = bind("qpos"), bind("qvel"), bind("time")
        self.ctrl, self.xfrc_applied = bind("ctrl"), bind("xfrc_applied")
        self.sensordata, self.site_xpos, self.xpos = bind("sensordata"), bind("site_xpos"), bind("xpos")
        self.actuator_force = bind("actuator_force")
        self._per_env_fields: dict[str, np.ndarray] = {}

    # ------------------------------------------------------------------ per-environment model fields
    def per_env_field(self, name: str) -> np.ndarray:
        """The live ``(num_envs, ...)`` per-environment values of model field ``name`` (``geom_friction``,
        ``body_mass``); after writing a field of :data:`SET_CONST_INPUTS`, call :meth:`set_const`."""
        if name not in self._per_env_fields:
            self._per_env_fields[name] = self.batch.expand(name)
        return self._per_env_fields[name]

    def set_const(self) -> None:
        """Recompute the constants MuJoCo derives from the per-environment model fields."""
        self.batch.set_const()

    # ------------------------------------------------------------------ operations
    def reset(self, ids: np.ndarray, keyframe: int) -> None:
        """Reset simulations ``ids`` (indices, or a (num_envs,) bool mask) to ``keyframe``, computing nothing (the
        caller writes the state, then calls :meth:`forward`)."""
        ids = np.asarray(ids)
        if ids.dtype == np.bool_:
            ids = np.flatnonzero(ids)
        self.batch.reset(ids=ids, keyframe=keyframe, stage=mujoco.mjtStage.mjSTAGE_NONE)

    def forward(self, ids: np.ndarray | None = None) -> None:
        """Compute every derived quantity (``mj_forward``) of simulations ``ids`` (all if None)."""
        self.batch.forward(ids=ids)

    def step(self, nstep: int) -> np.ndarray:
        """Advance every simulation by ``nstep`` physics steps, then compute the derived quantities of the new
        state (``mj_forward``); returns the ids of the simulations that failed: MuJoCo raised an error in them (they
        keep the state they had before the call, the others ran), or it reset them in a step where their positions,
        velocities or accelerations blew up (a "bad QPOS / QVEL / QACC" warning, no error) and stepped on from the
        model's default state. ``mujoco.batch`` has no warning counters to read, so a reset shows by what
        ``mj_resetData`` clears: the controls (zeroed; a step never writes them otherwise), or the clock (it did not
        advance by the ``nstep`` steps). Each sees a case the other misses: a blow-up in the first step from clock 0
        (the reset puts the clock back where it was), controls that were all 0 already."""
        expected = self.time + nstep * self.timestep  # a new array: the clocks the steps should reach
        controls = self.ctrl.copy()
        raised = np.zeros(0, dtype=np.int64)
        try:
            self.batch.step(nstep=nstep, stage=mujoco.mjtStage.mjSTAGE_ACC)
        except mj_batch.SimulationError as exc:
            raised = np.asarray(exc.ids, dtype=np.int64)
        stalled = np.abs(self.time - expected) > 0.5 * self.timestep
        cleared = np.any(self.ctrl != controls, axis=1)
        return np.union1d(raised, np.flatnonzero(stalled | cleared))

    def check_overflow(self) -> None:
        """Nothing to check: MuJoCo grows its contact and constraint arena as needed (a full arena raises in
        :meth:`step`, reported as failed simulations)."""

    def render_data(self, env: int) -> mujoco.MjData:
        """An MjData with simulation ``env``'s positions and velocities, forwarded (for rendering)."""
        return render_data(self.model, self.qpos[env], self.qvel[env])

    # ------------------------------------------------------------------ state
    def get_state(self) -> dict[str, Any]:
        """A copy of everything a restored batch needs to step on identically: the integration state rows
        (time, qpos, qvel, controls, applied forces, the solver's warm start, ...) and the per-environment
        model fields."""
        return {
            "state": self.batch.state.copy(),
            "per_env_fields": {name: values.copy() for name, values in self._per_env_fields.items()},
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`get_state` of a batch of the same model and size, and recompute the derived
        quantities (the outputs a step would have left)."""
        rows = np.asarray(state["state"])
        if rows.shape != self.batch.state.shape:
            raise ValueError(
                f"physics state of shape {rows.shape} does not fit this batch {self.batch.state.shape}: restore it "
                "into a batch of the same model and number of environments"
            )
        restore_per_env_fields(self, state["per_env_fields"])
        self.batch.state[:] = rows
        # MuJoCo's forward pass resets a simulation holding NaN, inf or a value beyond mjMAXVAL (with a warning);
        # such a state (a diverged one, left for the next step to flag) is restored as it was, not forwarded.
        sane = (np.abs(self.qpos) < mujoco.mjMAXVAL).all(axis=1) & (np.abs(self.qvel) < mujoco.mjMAXVAL).all(axis=1)
        if sane.any():
            self.forward(np.flatnonzero(sane))
