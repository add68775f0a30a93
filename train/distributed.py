"""Training on several GPUs: one process per GPU under ``torchrun``, through rsl-rl's own distributed PPO.

``torchrun --nproc_per_node N -m margin_rl.train train ... --physics warp`` starts N processes; torchrun tells each
its place in the environment variables ``WORLD_SIZE``, ``RANK`` and ``LOCAL_RANK``, which rsl-rl's
``OnPolicyRunner`` reads too (it then joins the NCCL process group, broadcasts rank 0's networks at the start and
averages the gradients at every update). This module is the project's side: each process's environments and learner
on ``cuda:LOCAL_RANK`` (Warp's physics there, so nothing crosses between GPUs but the gradients), its own seed
(``seed + RANK``: the ranks draw different episodes), and one run folder written by rank 0 alone (config, progress,
checkpoints, TensorBoard, the final model); every rank reads the checkpoint on ``--resume``. ``--num-envs`` and
``--total-steps`` are per process, as rsl-rl counts them: N GPUs collect N times the steps of one.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class Ranks:
    """This process's place among the training processes: ``world_size`` processes, ``rank`` among them,
    ``local_rank`` among those of its machine (its GPU's index)."""

    world_size: int = 1
    rank: int = 0
    local_rank: int = 0

    def __post_init__(self) -> None:
        if self.world_size < 1:
            raise ValueError(f"WORLD_SIZE must be >= 1 (the number of training processes), got {self.world_size}")
        for name in ("rank", "local_rank"):
            value = getattr(self, name)
            if not 0 <= value < self.world_size:
                raise ValueError(
                    f"{name.upper()} must lie in 0..{self.world_size - 1} (WORLD_SIZE {self.world_size}), got {value}; "
                    "start the processes with torchrun --nproc_per_node N"
                )

    @classmethod
    def from_environment(cls, environ: Mapping[str, str] | None = None) -> Ranks:
        """The ranks torchrun gives this process (``WORLD_SIZE``, ``RANK``, ``LOCAL_RANK``; absent: one process).

        Raises:
            ValueError: a variable that is not a whole number, or ranks outside the world.
        """
        environ = os.environ if environ is None else environ
        values = {}
        for field_name, variable, default in (
            ("world_size", "WORLD_SIZE", "1"),
            ("rank", "RANK", "0"),
            ("local_rank", "LOCAL_RANK", "0"),
        ):
            text = environ.get(variable, default)
            try:
                values[field_name] = int(text)
            except ValueError:
                raise ValueError(f"{variable} must be a whole number (torchrun sets it), got {text!r}") from None
        return cls(**values)

    @property
    def distributed(self) -> bool:
        """Whether this is one of several training processes."""
        return self.world_size > 1

    @property
    def writes(self) -> bool:
        """Whether this process writes the run folder (rank 0 does, the others only read it)."""
        return self.rank == 0

    @property
    def device(self) -> str:
        """The GPU of this process: ``cuda:LOCAL_RANK`` (rsl-rl asks its learner to be there)."""
        return f"cuda:{self.local_rank}"

    def seed(self, seed: int) -> int:
        """This process's seed from the run's: ``seed + rank`` (rank 0 keeps the run's)."""
        return seed + self.rank
