"""How many torch operations a device step dispatches (each a kernel launched from Python on a GPU), counted on Warp's
CPU device: the same every step, and no more than measured when the step was last made leaner
(``benchmarks/speed/profile_core_ops.py --by-source K`` prints them module by module and line by line). The GPU
issue's budget (300 on flat ground, 400 on rough) is not reached: these ceilings keep what was reached from growing
back."""

from __future__ import annotations

import pytest

from benchmarks.speed.bench_gpu import make_core, random_actions
from benchmarks.tools.host_reads import DispatchCounter
from tests.conftest import require_mujoco_warp

require_mujoco_warp()

CEILINGS = {
    ("margin_rl/AnymalC-v1", "robust"): 347,  # measured 342
    ("margin_rl/AnymalC-Rough-v1", "rough"): 513,  # measured 508
}
"""Operations per step of the benchmark's core (16 environments, learned margin), measured + a few."""


@pytest.mark.parametrize(("env", "recipe"), list(CEILINGS))
def test_a_device_step_dispatches_a_fixed_and_bounded_number_of_operations(env: str, recipe: str) -> None:
    core = make_core(16, "cpu", "learned", env, recipe)
    actions = random_actions(12, 16, "cpu")
    for k in range(2):
        core.step(actions[k])
    per_step = []
    for k in range(2, 12):
        counter = DispatchCounter()
        with counter:
            core.step(actions[k])
        per_step.append(counter.total)
        assert dict(counter.host_reads) == {}
    assert len(set(per_step)) == 1, per_step
    assert per_step[0] <= CEILINGS[env, recipe], f"{per_step[0]} operations per step, ceiling {CEILINGS[env, recipe]}"


def test_every_operation_of_a_step_is_traced_to_a_line_of_the_package() -> None:
    """What ``profile_core_ops.py --by-source`` prints: each operation attributed to the package's line that made it
    (an array helper's caller), their sum the step's count."""
    core = make_core(4, "cpu", "learned", "margin_rl/AnymalC-v1", "robust")
    first, second = random_actions(2, 4, "cpu").unbind(0)
    core.step(first)
    counter = DispatchCounter(by_source=True)
    with counter:
        core.step(second)
    assert sum(sum(ops.values()) for ops in counter.sources.values()) == counter.total
    assert "elsewhere" not in counter.sources, counter.sources.get("elsewhere")
    files = {line.rsplit(":", 1)[0] for line in counter.sources}
    assert {"envs/core.py", "envs/state_read.py", "margin_rl/robot/kinematics.py"} <= files
    assert not any(name.endswith("arrays.py") for name in files)  # a helper's operations go to its caller
