"""The checks a step makes on what comes in and goes out, kept as flags where the step computes and read together.

On the host (``mujoco.batch``) a check costs nothing and raises at once. On a device, reading a flag waits for the
device to finish every operation queued before it: a step that read its checks every time would run at the speed of
that round trip, and could not be replayed as a graph. There each check ORs its result into per-environment flags
on the device, and :meth:`StepChecks.raise_pending` reads them all at once (one host read), at a cadence the caller
sets (:attr:`~margin_rl.envs.core.AnymalCore.check_every`: the learner's rollout length), the same on Warp's CPU
device as on a GPU. The error then names the check, the first step it failed at (counted on the device, one per
recorded step: a step replayed as a graph bakes in no step number of the host's) and the environments.

=====================  ===============================  ==========================================================
flag                   raised as                        holds where
=====================  ===============================  ==========================================================
``action``             ValueError                       an action entry is NaN or inf (the step used 0 there)
``observation``        FloatingPointError               an observation entry is not finite
``reward``             FloatingPointError               the reward is not finite
=====================  ===============================  ==========================================================
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from margin_rl.arrays import finite_mask, namespace, to_numpy, write_where

CHECKS: dict[str, type[Exception]] = {
    "action": ValueError,
    "observation": FloatingPointError,
    "reward": FloatingPointError,
}
"""The checks, in the order of the flags' columns and of the errors raised, and the exception each raises."""

NO_STEP = np.iinfo(np.int64).max
"""The first-step record of an environment whose flag never held."""


class StepChecks:
    """Per-environment flags of :data:`CHECKS` ((N, checks) bool), the first step each environment raised one, and
    the count of steps recorded (the step number a record gets: 0 for the first), kept in arrays of ``reference``'s
    kind and device."""

    def __init__(self, reference: Any) -> None:
        xp = self._xp = namespace(reference)
        self._failed = xp.zeros((reference.shape[0], len(CHECKS)), dtype=xp.bool, device=reference.device)
        self._first_step = xp.full_like(reference, NO_STEP, dtype=xp.int64)
        self._steps = xp.zeros((), dtype=xp.int64, device=reference.device)

    def record(self, failed: Mapping[str, Any]) -> None:
        """OR one step's failures (``failed[check]``: (N,) bool, where check ``check`` failed, for every check of
        :data:`CHECKS`) into the flags, remembering the step's number where it is an environment's first, and count
        the step; a few operations for all the checks, the same every step, and no host read."""
        xp = self._xp
        if set(failed) != set(CHECKS):
            raise ValueError(f"record takes every check of {list(CHECKS)}, got {sorted(failed)}")
        now = xp.stack([failed[check] for check in CHECKS], axis=1)
        self._failed |= now
        first = xp.any(now, axis=1) & (self._first_step == NO_STEP)
        write_where(self._first_step, first, self._steps)
        self._steps += 1

    def record_step(self, action_failed: Any, reward: Any, observations: Any) -> None:
        """Record a step's checks: ``action_failed`` (N,) where an action was NaN or inf, and where ``reward`` (N,) or
        any of ``observations`` (each (N, k)) is not finite."""
        xp = self._xp
        outputs = xp.concat(list(observations), axis=1)
        failed = {
            "action": action_failed,
            "observation": ~xp.all(finite_mask(outputs), axis=1),
            "reward": ~finite_mask(reward),
        }
        self.record(failed)

    def raise_pending(self, hints: Mapping[str, str]) -> None:
        """Read the flags once; raise the first check that failed (in :data:`CHECKS` order) for the environments
        it failed in, naming the first step and adding ``hints[check]`` (what to change); clear nothing (a failed
        environment stays failed)."""
        xp = self._xp
        both = to_numpy(xp.concat([xp.astype(self._failed, xp.int64), self._first_step[:, None]], axis=1))  # one read
        failed, first_step = both[:, :-1], both[:, -1]
        for k, (check, error) in enumerate(CHECKS.items()):
            envs = np.flatnonzero(failed[:, k])
            if envs.size:
                step = int(first_step[envs].min())
                listed = ", ".join(str(e) for e in envs[:8]) + (", ..." if envs.size > 8 else "")
                raise error(
                    f"the {check} is not finite in {envs.size} environment(s) [{listed}], first at step {step}"
                    f"{'; ' + hints[check] if check in hints else ''}"
                )
