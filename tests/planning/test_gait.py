"""Gaits and the event-based schedule: invariants and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.planning import TROT, WALK, Gait, contact_flags, get_gait
from margin_rl.planning.schedule import horizon_schedule


@settings(max_examples=50, deadline=None)
@given(t=st.floats(0.0, 100.0))
def test_walk_keeps_three_feet_down_and_trot_a_diagonal(t):
    walk = contact_flags(WALK, np.array(t))
    assert walk.sum() >= 3
    trot = contact_flags(TROT, np.array(t))
    assert trot.sum() in (2, 4)
    if trot.sum() == 2:  # the stance pair is a diagonal: LF+RH or RF+LH
        assert trot[0] == trot[3] and trot[1] == trot[2]


@settings(max_examples=30, deadline=None)
@given(t0=st.floats(0.0, 20.0))
def test_one_foothold_per_touchdown_and_feet_follow_their_footholds(t0):
    sched = horizon_schedule(WALK, t0, 3.0, 0.2)
    for leg in range(4):
        touchdowns = [s.touchdown for s in sched.swings[leg]]
        assert touchdowns == sorted(touchdowns) and all(td > t0 for td in touchdowns)
        assert len(sched.slot_indices(leg)) == len(touchdowns)
        centres = [np.array([float(j), 0.0, 0.0]) for j in range(len(touchdowns) + 1)]
        up = np.array([0.0, 0.0, 1.0])
        for k, t in enumerate(sched.node_times):
            p = sched.foot_centre(leg, float(t), centres, up)
            if sched.contacts[k, leg] > 0:  # in stance: exactly on a foothold
                assert p[0] == round(p[0]) and p[2] == 0.0


def test_walk_horizon_has_the_papers_size():
    sched = horizon_schedule(WALK, 0.0, 3.0, 0.2)
    assert sched.n_nodes == 16  # T / dT + 1
    assert 4 <= len(sched.slots) <= 8


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"period": -1.0}, "period"),
        ({"swing_duration": 0.0}, "swing_duration"),
        ({"swing_duration": 3.0}, "swing_duration"),
        ({"liftoff_phase": (0.0, 0.5, 1.2, 0.0)}, "liftoff_phase"),
        ({"speed": -0.1}, "speed"),
    ],
)
def test_bad_gaits_name_the_field(kwargs, message):
    values = {**WALK.__dict__, **kwargs}
    with pytest.raises(ValueError, match=message):
        Gait(**values)


@settings(max_examples=20, deadline=None)
@given(horizon=st.floats(-5.0, 0.3), node_dt=st.floats(-1.0, 0.0))
def test_bad_horizons_are_refused(horizon, node_dt):
    with pytest.raises(ValueError, match=r"horizon|node_dt"):
        horizon_schedule(WALK, 0.0, horizon, node_dt)


def test_unknown_gait_lists_the_known_ones():
    with pytest.raises(ValueError, match="walk"):
        get_gait("gallop")
