"""Tests of the CasADi/IPOPT footstep planner."""

from __future__ import annotations

import numpy as np
import pytest

from margin_rl.slip.dynamics import Status, simulate_batch
from margin_rl.slip.margin import BOX_HIGH, BOX_LOW
from margin_rl.slip.models import load_bundle
from margin_rl.slip.planner import (
    FootstepPlanner,
    PlannerConfig,
    PlanResult,
    random_tasks,
    run_table,
    table_markdown,
    validate_plan,
)

pytest.importorskip("casadi")


@pytest.fixture(scope="module")
def bundle():  # type: ignore[no-untyped-def]
    return load_bundle()


def _solved_plans(planner: FootstepPlanner, n_tasks: int, seed: int) -> list[tuple[PlanResult, np.ndarray]]:
    s0s, goals = random_tasks(n_tasks, seed)
    out = []
    for s0, goal in zip(s0s, goals, strict=True):
        plan = planner.solve(s0, goal)
        np.testing.assert_array_equal(plan.states[0], s0)
        if plan.solved:
            out.append((plan, goal))
    return out


@pytest.mark.parametrize("horizon,objective", [(3, "state"), (4, "none")])
def test_margin_plan_satisfies_all_constraints(bundle, horizon: int, objective: str) -> None:  # type: ignore[no-untyped-def]
    cfg = PlannerConfig(horizon=horizon, objective=objective, use_margin=True)  # type: ignore[arg-type]
    planner = FootstepPlanner(bundle.return_map, bundle.margin, cfg)
    plans = _solved_plans(planner, 12, seed=0)
    assert plans, "no task solved; the planner is broken"
    for plan, goal in plans:
        res = planner.constraint_residuals(plan, goal)  # recomputed with the numpy networks
        assert res["dynamics"] < 1e-5
        assert res["goal"] < 1e-6
        assert res["margin_slack"] > -1e-6
        assert res["box_violation"] < 1e-8
        z = np.column_stack([plan.states[:-1], plan.actions])
        np.testing.assert_allclose(plan.dx, bundle.return_map(z)[:, 0], atol=1e-9)
        if objective == "state":
            d = np.diff(plan.states, axis=0)
            assert plan.objective == pytest.approx(float(np.sum(d * d * [6.25, 0.25])), rel=1e-9, abs=1e-12)
        else:
            assert plan.objective == 0.0


def test_plans_start_at_s0_and_end_at_goal(bundle) -> None:  # type: ignore[no-untyped-def]
    planner = FootstepPlanner(bundle.return_map, bundle.margin, PlannerConfig(3, "none", use_margin=False))
    s0, goal = np.array([1.05, 0.2]), np.array([1.08, 0.45])
    plan = planner.solve(s0, goal)
    assert plan.solved
    np.testing.assert_array_equal(plan.states[0], s0)
    np.testing.assert_allclose(plan.states[-1], goal, atol=1e-6)
    assert plan.states.shape == (4, 2) and plan.actions.shape == (3, 2)
    assert np.all(plan.actions >= BOX_LOW[2:] - 1e-9) and np.all(plan.actions <= BOX_HIGH[2:] + 1e-9)
    assert np.isnan(planner.constraint_residuals(plan, goal)["margin_slack"])


def test_validation_resimulates_every_step(bundle) -> None:  # type: ignore[no-untyped-def]
    planner = FootstepPlanner(bundle.return_map, bundle.margin, PlannerConfig(3, "none", use_margin=True))
    plan, _ = _solved_plans(planner, 12, seed=0)[0]
    checked = validate_plan(plan)
    truth = simulate_batch(plan.states[:-1], plan.actions)
    assert checked.step_status == tuple(int(s) for s in truth.status)
    assert checked.valid == bool(truth.valid.all())
    # Breaking one step (apex too low to place the foot) must invalidate the whole plan.
    states = plan.states.copy()
    states[1] = [0.81, 0.0]
    actions = plan.actions.copy()
    actions[1] = [0.0, 0.05]
    broken = validate_plan(PlanResult(**{**plan.__dict__, "states": states, "actions": actions}))
    assert broken.step_status is not None and broken.step_status[1] == Status.NO_TOUCHDOWN
    assert broken.valid is False


def test_run_table_percentages(bundle) -> None:  # type: ignore[no-untyped-def]
    rows = run_table(3, seed=1, horizons=(3,), bundle=bundle)
    assert len(rows) == 4
    for r in rows:
        assert r["pct_infeasible"] + r["pct_invalid"] + r["pct_valid"] == pytest.approx(100.0)
        assert r["paper"] is not None
    md = table_markdown(rows)
    assert "Declared infeasible" in md and "(25.4 %)" in md


def test_config_validation(bundle) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match="horizon"):
        PlannerConfig(horizon=0)
    with pytest.raises(ValueError, match="objective"):
        PlannerConfig(objective="fast")  # type: ignore[arg-type]
    planner = FootstepPlanner(bundle.return_map, bundle.margin, PlannerConfig(2))
    with pytest.raises(ValueError, match="s0"):
        planner.solve([1.0, 0.0, 0.0], [1.0, 0.0])
