"""MuJoCo Warp behind the physics seam: ``num_envs`` worlds of one model stepped by ``mujoco_warp`` kernels.

:class:`WarpPhysics` satisfies :class:`~margin_rl.envs.physics.PhysicsBackend`, the contract
:class:`~margin_rl.envs.physics.MujocoBatchPhysics` satisfies, with these differences (each a property of Warp,
stated where the core or a user meets it):

* **float32.** Warp computes in single precision; the live arrays are float32 (``mujoco.batch``: float64). One
  decimated step from the same state agrees with MuJoCo to ~1e-5 on flat ground; on the rough heightfield the
  contact sets can differ, and so can the trajectories (the tests state each tolerance and its reason).
* **Where the arrays live.** The live arrays are torch tensors over the Warp arrays (``wp.to_torch``: the same
  memory, no copy), on the backend's device: CPU tensors on Warp's CPU device, CUDA tensors on a GPU. The core
  computes in the namespace of these arrays (:mod:`margin_rl.arrays`), so on a GPU the whole step stays there.
* **Graphs.** Each of the three things the core asks of the physics per step is recorded once as a Warp graph and
  replayed: the decimated step (``nstep`` physics steps and the forward pass, one graph per ``nstep``), the reset of
  the worlds a mask selects (``reset_data`` with a mask this backend owns: ``reset_data_keyframe`` would allocate a
  mask per call) and the forward pass. On a GPU they are CUDA graphs (eager launching is an order of magnitude
  slower, and MuJoCo Warp's solver loop, ``capture_while``, reads the host on every iteration outside a capture);
  on Warp's CPU device Warp records and replays them the same way, so the tests replay what a GPU replays. A graph
  keeps the arrays it was captured with: this backend never replaces one (per-world fields, resets and the
  keyframe's state write in place), and captures again after :meth:`set_const`. ``graphs=False`` launches every
  call eagerly (debugging). The kernels run on Warp's own stream of the device, a blocking stream: it synchronises
  with CUDA's default stream, where torch runs the core's operations unless told otherwise, so the two are ordered
  without an explicit wait (and a graph cannot be captured on torch's default stream).
* **Buffers of a stated size.** Warp allocates its contact and constraint buffers once (MuJoCo grows its arena).
  :func:`contact_budget` sizes them from the model; a step that needs more sets ``Data.overflow``, which this
  backend ORs into a flag of its own on the device after every step (kept across resets, which clear
  ``Data.overflow``; no host round-trip) and :meth:`WarpPhysics.check_overflow` turns into
  :class:`PhysicsOverflowError`, naming the setting to raise (``nconmax`` / ``njmax``). The core checks it every
  step on the CPU device and once per :data:`~margin_rl.envs.core.DEVICE_CHECK_STEPS` steps on a GPU.
* **Divergence.** Warp neither raises nor resets a simulation whose accelerations blow up: its state turns
  non-finite and stays so, which the core's divergence check (non-finite or too fast) catches; :meth:`step`
  never reports failed ids of its own.
* **Resets** go through ``mujoco_warp.reset_data`` with a per-world mask (given as ids, or as a bool tensor on the
  device: no host read), then the keyframe's clock, positions, velocities and controls are written where the mask
  holds, so the solver's warm start, the applied forces and the clock of a reset world are cleared as MuJoCo
  clears them (``reset_data_keyframe``'s result, for models without actuator activations or mocap bodies).

Kernels compile on first use (tens of seconds for ANYmal on one CPU core, cached in ``~/.cache/warp`` after).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import mujoco
import numpy as np
import torch

try:
    import mujoco_warp as mjw
    import warp as wp
except ImportError as exc:  # the optional dependency of the GPU path
    raise ImportError(
        f"physics='warp' needs MuJoCo Warp ({exc}); install it with: pip install \"margin_rl[gpu]\" (mujoco-warp "
        "and warp-lang, pinned together with mujoco), or use physics='mujoco'"
    ) from exc

from margin_rl.arrays import to_numpy, write_where
from margin_rl.envs.physics import ModelConstants, render_data, restore_per_env_fields

# No start-up banner and no line per kernel module loaded or compiled (hundreds for ANYmal); warnings stay.
wp.config.log_level = wp.LOG_WARNING

INTEGRATION_STATE = int(mujoco.mjtState.mjSTATE_INTEGRATION)
"""The state components :meth:`WarpPhysics.get_state` carries: MuJoCo's integration state (time, qpos, qvel, act,
the solver's warm start, controls, applied forces, ...), as ``mujoco.batch`` does."""

BUFFER_OVERFLOWS = int(
    mjw.OverflowType.NEFC
    | mjw.OverflowType.NJMAX_NNZ
    | mjw.OverflowType.BROADPHASE
    | mjw.OverflowType.NARROWPHASE
    | mjw.OverflowType.CCD
    | mjw.OverflowType.HFIELD
    | mjw.OverflowType.NVMAX
    | mjw.OverflowType.EPA_HORIZON
)
"""The bits of ``Data.overflow`` that mean a buffer was too small and something was dropped (the solver's
iteration limits are not among them: MuJoCo stops there too, and nothing is lost)."""

CONTACTS_PER_GEOM = {"plane": 1, "hfield": 4}
"""Contacts budgeted per robot geom that can touch the ground, by the ground's kind. On a plane one per geom is far
above what a world uses (measured with random actions, falls included, 32 worlds x 150 steps: at most 5-7 contacts
per world against a budget of 40-48); on a heightfield a foot sphere gets up to 3 contacts where it straddles prism
edges, so 4 per geom (measured: at most 8-14 per world against 144-176)."""

ROWS_PER_CONTACT = 4
"""Constraint rows of one contact with a pyramidal friction cone and condim 3 (2 (condim - 1))."""


class PhysicsOverflowError(RuntimeError):
    """A Warp contact or constraint buffer was too small: contacts or constraint rows were dropped."""


def contact_budget(model: mujoco.MjModel) -> tuple[int, int]:
    """(nconmax, njmax): contacts and constraint rows per world, by a rule stated here and in the tests.

    nconmax = n_g c, with n_g the geoms that can collide with the ground (contype/conaffinity) and c
    :data:`CONTACTS_PER_GEOM` of the ground's kind; njmax = :data:`ROWS_PER_CONTACT` nconmax plus one row per
    limited joint (each limit can be active) and per equality (none in ANYmal). Rounded up to a multiple of 8.
    """
    floor = int(model.geom("floor").id) if _has_geom(model, "floor") else -1
    ground_kind = "hfield" if floor >= 0 and model.geom_type[floor] == mujoco.mjtGeom.mjGEOM_HFIELD else "plane"
    if floor >= 0:
        touches = (model.geom_contype & model.geom_conaffinity[floor]) | (
            model.geom_conaffinity & model.geom_contype[floor]
        )
        colliding = int(np.count_nonzero(touches)) - 1  # the floor itself
    else:
        colliding = int(model.ngeom)
    nconmax = max(8, colliding * CONTACTS_PER_GEOM[ground_kind])
    njmax = ROWS_PER_CONTACT * nconmax + int(np.count_nonzero(model.jnt_limited)) + int(model.neq)
    return _round_up(nconmax, 8), _round_up(njmax, 8)


def _has_geom(model: mujoco.MjModel, name: str) -> bool:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name) >= 0


def _round_up(value: int, multiple: int) -> int:
    return int(math.ceil(value / multiple) * multiple)


def check_warp_device(device: str | None) -> str:
    """The Warp device this backend runs on: ``device`` checked (a name of ``warp.get_devices()``: ``"cpu"``,
    ``"cuda:0"``, ...), or the first GPU where None; ValueError otherwise."""
    available = [str(d) for d in wp.get_devices()]
    if device is None:
        gpus = [d for d in available if d.startswith("cuda")]
        if not gpus:
            raise ValueError(
                "physics='warp' defaults to the first GPU, and Warp finds none here (devices: "
                f"{', '.join(available)}); pass physics_device='cpu' for Warp's CPU device (tests and debugging), "
                "or physics='mujoco' to train on the CPU"
            )
        device = gpus[0]
    if not isinstance(device, str) or device not in available:
        raise ValueError(
            f"physics_device must be one of Warp's devices here {available}, got {device!r}"
            + ("" if any(d.startswith("cuda") for d in available) else " (Warp finds no GPU on this machine)")
        )
    return device


class WarpPhysics(ModelConstants):
    """``num_envs`` worlds of ``model`` in MuJoCo Warp (see the module docstring)."""

    def __init__(
        self,
        model: mujoco.MjModel,
        num_envs: int,
        device: str | None = None,
        nconmax: int | None = None,
        njmax: int | None = None,
        graphs: bool = True,
    ) -> None:
        """``device``: a Warp device name (see :func:`check_warp_device`); ``nconmax``, ``njmax``: contacts and
        constraint rows per world (None: :func:`contact_budget`); ``graphs``: record and replay (module docstring),
        or launch eagerly."""
        if model.na or model.nmocap:
            raise ValueError(
                f"the Warp backend resets worlds to a keyframe's positions, velocities and controls only; this model "
                f"has {model.na} actuator activations and {model.nmocap} mocap bodies, which it would not restore"
            )
        if not isinstance(graphs, bool):
            raise TypeError(f"graphs must be True or False, got {graphs!r}")
        self.model = model
        self.graphs = graphs
        self._inside_torch_capture = False  # launching into a step graph torch records (recorded_by_torch)
        self.recordings_invalidated = 0
        """How many times this backend's arrays may have moved since it was built (:meth:`set_const`): a graph
        recorded before holds stale addresses."""
        self.num_envs = num_envs
        self.device = check_warp_device(device)
        default_nconmax, default_njmax = contact_budget(model)
        self.nconmax = default_nconmax if nconmax is None else int(nconmax)
        self.njmax = default_njmax if njmax is None else int(njmax)
        with wp.ScopedDevice(self.device):
            batched = (*PER_ENV_FIELDS, *DERIVED_PER_WORLD)
            self._model = mjw.put_model(model, batch_sizes={name: num_envs for name in batched})
            self._model.opt.warn_overflow = 0  # reported by check_overflow, not printed from inside a kernel
            # At qpos0 the robot may sit inside the terrain (the core resets every world before its first step).
            self._data = mjw.make_data(
                model, nworld=num_envs, nconmax=self.nconmax, njmax=self.njmax, naconmax=self.nconmax * num_envs
            )
            self._reset_worlds = wp.zeros(num_envs, dtype=bool)  # the mask reset_data reads: this backend's own
            self._state_rows = wp.zeros((num_envs, mujoco.mj_stateSize(model, INTEGRATION_STATE)), dtype=float)
        self._graphs: dict[Any, Any] = {}  # ("step", nstep), "reset", "forward" -> its recorded graph
        self._no_failures = torch.zeros(0, dtype=torch.int64, device=wp.device_to_torch(self.device))
        data, view = self._data, wp.to_torch
        self.qpos, self.qvel, self.time = view(data.qpos), view(data.qvel), view(data.time)
        self.ctrl, self.xfrc_applied = view(data.ctrl), view(data.xfrc_applied)
        self.sensordata, self.site_xpos, self.xpos = view(data.sensordata), view(data.site_xpos), view(data.xpos)
        self.actuator_force = view(data.actuator_force)
        self._overflow = view(data.overflow)
        self._overflow_seen = torch.zeros_like(self._overflow)  # on the device, kept across resets (which clear it)
        self._reset_mask = view(self._reset_worlds)
        self._reset_rows = self._reset_mask[:, None]  # the mask over a row of qpos, qvel, ctrl (a view, made once)
        self._keyframes: dict[int, tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = {}
        self._per_env_fields = {name: view(getattr(self._model, name)) for name in PER_ENV_FIELDS}

    def _on_device(self) -> Any:
        """The scope of every launch: Warp's device, on its own (blocking) stream there (module docstring)."""
        return wp.ScopedDevice(self.device)

    @property
    def on_cuda(self) -> bool:
        """Whether the worlds are on a CUDA device (where a core's whole step can be recorded as one graph)."""
        return bool(self.device.is_cuda)

    def on_torch_stream(self, stream: Any) -> Any:
        """A scope in which Warp launches on torch's CUDA ``stream`` (a core's step graph,
        :mod:`~margin_rl.envs.step_graph`); enter it before torch begins its capture there."""
        return wp.ScopedStream(wp.stream_from_torch(stream))

    @contextmanager
    def recorded_by_torch(self) -> Iterator[None]:
        """Inside a capture torch began on the current stream (of :meth:`on_torch_stream`): the capture is
        registered with Warp (external), so that MuJoCo Warp's solver loop records a conditional node instead of
        reading the host, and this backend launches its kernels into it instead of replaying its own graphs."""
        wp.capture_begin(force_module_load=False, external=True)
        self._inside_torch_capture = True
        try:
            yield
        finally:
            self._inside_torch_capture = False
            wp.capture_end()

    # ------------------------------------------------------------------ per-environment model fields
    def per_env_field(self, name: str) -> torch.Tensor:
        """The live ``(num_envs, ...)`` per-world values of model field ``name`` (one of :data:`PER_ENV_FIELDS`);
        after writing a field of :data:`~margin_rl.envs.physics.SET_CONST_INPUTS`, call :meth:`set_const`."""
        if name not in self._per_env_fields:
            raise ValueError(
                f"{name!r} is not a per-environment field of the Warp backend; it has {sorted(PER_ENV_FIELDS)} "
                "(put_model's batch_sizes, fixed when the backend is built)"
            )
        return self._per_env_fields[name]

    def set_const(self) -> None:
        """Recompute the constants derived from the per-world model fields (``mujoco_warp.set_const``); the graphs
        are captured again at their next use, in case a model array was re-allocated (a graph keeps the arrays it was
        captured with)."""
        with self._on_device():
            mjw.set_const(self._model, self._data)
        self._graphs.clear()
        self.recordings_invalidated += 1  # a core's step graph records again too

    # ------------------------------------------------------------------ operations
    def reset(self, ids: Any, keyframe: int) -> None:
        """Reset worlds ``ids`` to ``keyframe`` (state, controls, applied forces, warm start, clock), computing
        nothing (the caller writes the state, then calls :meth:`forward`). ``ids``: world indices, or a (num_envs,)
        bool tensor on the device (the worlds where it holds: no host read, the same launches whichever they are)."""
        self._collect_overflow()
        mask = self._reset_mask
        if isinstance(ids, torch.Tensor) and ids.dtype == torch.bool:
            mask.copy_(ids)
        else:
            mask.fill_(False)
            mask[torch.as_tensor(ids, dtype=torch.int64, device=mask.device)] = True
        self._replay("reset", lambda: mjw.reset_data(self._model, self._data, self._reset_worlds))
        for live, value in zip((self.qpos, self.qvel, self.ctrl), self._keyframe_state(keyframe), strict=True):
            write_where(live, self._reset_rows, value)
        write_where(self.time, mask, float(self.model.key(keyframe).time[0]))

    def _keyframe_state(self, keyframe: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The keyframe's qpos, qvel and ctrl as tensors on the device, made once (not copied from the host at every
        reset)."""
        if keyframe not in self._keyframes:
            key = self.model.key(keyframe)
            self._keyframes[keyframe] = tuple(
                torch.as_tensor(value, dtype=live.dtype, device=live.device)
                for live, value in ((self.qpos, key.qpos), (self.qvel, key.qvel), (self.ctrl, key.ctrl))
            )
        return self._keyframes[keyframe]

    def forward(self, ids: np.ndarray | None = None) -> None:
        """Compute every derived quantity of the worlds. Warp's forward pass has no world mask: it runs on all
        of them, which leaves the others' outputs as they were (a forward pass is a function of the state)."""
        self._replay("forward", lambda: mjw.forward(self._model, self._data))

    def step(self, nstep: int) -> Any:
        """Advance every world by ``nstep`` physics steps, then compute the derived quantities of the new state
        (as ``mujoco.batch`` with ``stage=mjSTAGE_ACC``), replayed as a graph (module docstring). Returns no ids (an
        empty tensor): Warp reports no failed simulation (see the module docstring)."""
        self._replay(("step", nstep), lambda: self._launch_step(nstep))
        self._collect_overflow()
        return self._no_failures

    def _replay(self, key: Any, launch: Any) -> None:
        """Run ``launch`` (Warp launches only): the first time recorded as graph ``key``, then its replay; eagerly
        where ``graphs`` is off."""
        with self._on_device():
            if not self.graphs or self._inside_torch_capture:  # eager, or recorded into the step's own graph
                launch()
                return
            if key not in self._graphs:
                with wp.ScopedCapture() as capture:
                    launch()
                self._graphs[key] = capture.graph
            wp.capture_launch(self._graphs[key])

    def _launch_step(self, nstep: int) -> None:
        for _ in range(nstep):
            mjw.step(self._model, self._data)
        mjw.forward(self._model, self._data)

    def check_overflow(self) -> None:
        """:class:`PhysicsOverflowError` if any world's contact or constraint buffer overflowed since the backend
        was built (dropped contacts make every later step of that world wrong), naming the setting to raise."""
        seen = self._overflow_seen.cpu().numpy()  # the one host read: where the core chooses to check
        worlds = np.flatnonzero(seen & BUFFER_OVERFLOWS)
        if worlds.size == 0:
            return
        kinds = mjw.OverflowType(int(np.bitwise_or.reduce(seen[worlds])) & BUFFER_OVERFLOWS)
        raise PhysicsOverflowError(
            f"MuJoCo Warp dropped contacts or constraint rows ({kinds!r}) in {worlds.size} of {self.num_envs} worlds "
            f"(first: {worlds[:5].tolist()}); the buffers hold nconmax={self.nconmax} contacts and njmax={self.njmax} "
            "constraint rows per world: raise them (physics_options={'nconmax': ..., 'njmax': ...}; on the command "
            "line --physics-option nconmax=... --physics-option njmax=...), e.g. double both"
        )

    def _collect_overflow(self) -> None:
        self._overflow_seen.bitwise_or_(self._overflow)

    def render_data(self, env: int) -> mujoco.MjData:
        """An MjData with world ``env``'s positions and velocities, forwarded by MuJoCo (for rendering)."""
        return render_data(self.model, to_numpy(self.qpos[env]), to_numpy(self.qvel[env]))

    # ------------------------------------------------------------------ state
    def get_state(self) -> dict[str, Any]:
        """A copy of the integration state rows (:data:`INTEGRATION_STATE`, float32) and the per-world model
        fields: what a restored backend needs to step on identically."""
        with self._on_device():
            mjw.get_state(self._model, self._data, self._state_rows, INTEGRATION_STATE)
        return {
            "state": wp.to_torch(self._state_rows).cpu().numpy().copy(),
            "per_env_fields": {name: values.cpu().numpy().copy() for name, values in self._per_env_fields.items()},
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`get_state` of a backend of the same model and size, and recompute the derived
        quantities."""
        rows = np.asarray(state["state"])
        if rows.shape != tuple(self._state_rows.shape):
            raise ValueError(
                f"physics state of shape {rows.shape} does not fit these worlds {tuple(self._state_rows.shape)}: "
                "restore it into a backend of the same model and number of environments"
            )
        restore_per_env_fields(self, state["per_env_fields"])
        rows_live = wp.to_torch(self._state_rows)
        rows_live.copy_(torch.as_tensor(rows, dtype=rows_live.dtype))
        with self._on_device():
            mjw.set_state(self._model, self._data, self._state_rows, INTEGRATION_STATE)
        self.forward()


PER_ENV_FIELDS: tuple[str, ...] = ("geom_friction", "body_mass")
"""Model fields with a value per world (``put_model``'s ``batch_sizes``): the terrain friction and the base mass
the core randomises."""

DERIVED_PER_WORLD: tuple[str, ...] = ("body_subtreemass", "body_invweight0", "dof_invweight0", "actuator_acc0")
"""Model fields ``mujoco_warp.set_const`` derives from the body masses: batched too, or every world would share one
world's subtree mass (the CoM sensors read it: measured 1.6-7.6 cm CoM error with ±5 kg of base mass unbatched)."""
