r"""Multi-step footstep planner with learned failure-margin constraints (paper §IV, §V-B).

Given the current apex state :math:`s_0` and a goal apex state :math:`s_{goal}`, solve the
nonlinear program of eq. (6)

.. math::
    \min_x f(x) \quad \text{s.t.}\quad
    P(s_n, a_n) - s_{n+1} = 0,\;\; M(s_n, a_n) - \varepsilon \ge 0 \;\;(n = 0..N-1),\;\;
    s_N - s_{goal} = 0,

over :math:`x = [s_1, \dots, s_N, a_0, \dots, a_{N-1}]` with :math:`s = [y, \dot x]`,
:math:`a = [\alpha, \Delta L]`.  :math:`P` here is the ``[y1, xdot1]`` part of the learned
return map (the predicted :math:`\Delta x` is only reported).  Objectives: ``"state"``,
eq. (7), :math:`f = \sum_{i=0}^{N-1} (s_i - s_{i+1})^\top H (s_i - s_{i+1})` with
:math:`H = \mathrm{diag}(6.25, 0.25)` (the paper leaves :math:`H` unspecified; we reuse the
range-normalising state weights of §V-A), and ``"none"``, :math:`f = 0`.  States and actions
are bounded to the eq. (13) box where the networks were trained.  The margin inequality
(9) is written :math:`\ge 0` (IPOPT's interior point keeps it strictly feasible anyway).

The networks are expressed exactly in CasADi, so IPOPT gets exact gradients and constraint
Jacobians (algorithmic differentiation of the same expression); the Lagrangian Hessian is
L-BFGS by default (see :class:`PlannerConfig`).  A plan is *validated* by simulating
every planned pair :math:`(s_n, a_n)` with the true aSLIP; it is valid only if all steps
return to the apex section.

Table I CLI::

    python -m margin_rl.slip.planner --n-tasks 1000 --out results/slip_table1
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from margin_rl.network import DenseNetwork
from margin_rl.slip.dynamics import SlipParams, Status, simulate_batch, simulate_hop
from margin_rl.slip.margin import BOX_HIGH, BOX_LOW
from margin_rl.slip.models import Bundle, load_bundle

__all__ = [
    "PAPER_TABLE_I",
    "STATE_WEIGHTS",
    "FootstepPlanner",
    "PlanResult",
    "PlannerConfig",
    "main",
    "random_tasks",
    "run_table",
    "validate_plan",
]

FloatArray = NDArray[np.float64]
Objective = Literal["state", "none"]

#: Default :math:`H` of eq. (7) on ``[y, xdot]``.
STATE_WEIGHTS: FloatArray = np.array([6.25, 0.25])

#: Paper Table I: (horizon, objective, margin) -> (% infeasible, % invalid, % valid, mean s).
PAPER_TABLE_I: dict[tuple[int, str, bool], tuple[float, float, float, float]] = {
    (3, "state", True): (25.4, 27.6, 47.0, 0.29),
    (3, "state", False): (1.1, 56.5, 42.4, 0.18),
    (3, "none", True): (29.0, 13.0, 57.6, 0.14),
    (3, "none", False): (0.5, 60.0, 39.5, 0.072),
    (4, "state", True): (29.4, 27.8, 42.8, 1.29),
    (4, "state", False): (10.5, 51.9, 37.6, 0.98),
    (4, "none", True): (22.6, 11.9, 65.5, 0.16),
    (4, "none", False): (0.4, 56.1, 43.5, 0.079),
}

_SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


@dataclass(frozen=True)
class PlannerConfig:
    """Shape of the NLP.

    Parameters
    ----------
    horizon : int
        Number of steps :math:`N`.
    objective : {"state", "none"}
        Eq. (7) or a constant objective.
    use_margin : bool
        Include the margin constraints (9).
    epsilon : float
        Margin threshold :math:`\\varepsilon` (paper: 0.05).
    state_weights : tuple of float
        Diagonal of :math:`H`.
    max_iter : int
        IPOPT iteration limit; runs that hit it count as "declared infeasible" in Table I
        (IPOPT cannot certify infeasibility of a nonconvex NLP, and multi-start checks on such
        tasks almost never found a solution).
    tol : float
        IPOPT convergence tolerance.
    hessian : {"limited-memory", "exact"}
        Lagrangian Hessian given to IPOPT.  Gradients and constraint Jacobians are always
        exact.  The exact Hessian of a ReLU network is zero almost everywhere, which leaves
        IPOPT without curvature at the kinks; L-BFGS recovers curvature from gradient
        changes across kinks and roughly doubled the number of margin-constrained tasks solved
        in our trials, so it is the default.
    """

    horizon: int = 3
    objective: Objective = "state"
    use_margin: bool = True
    epsilon: float = 0.05
    state_weights: tuple[float, float] = (6.25, 0.25)
    max_iter: int = 300
    tol: float = 1e-6
    hessian: Literal["limited-memory", "exact"] = "limited-memory"

    def __post_init__(self) -> None:
        if self.horizon < 1:
            raise ValueError(f"horizon must be >= 1; got {self.horizon}")
        if self.objective not in ("state", "none"):
            raise ValueError(f"objective must be 'state' or 'none'; got {self.objective!r}")
        if len(self.state_weights) != 2 or min(self.state_weights) < 0:
            raise ValueError(f"state_weights must be two non-negative numbers; got {self.state_weights}")
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1; got {self.max_iter}")
        if self.hessian not in ("limited-memory", "exact"):
            raise ValueError(f"hessian must be 'limited-memory' or 'exact'; got {self.hessian!r}")


@dataclass(frozen=True)
class PlanResult:
    """Solution of one planning problem.

    ``states`` has shape ``(N + 1, 2)`` and includes :math:`s_0`; ``actions`` is ``(N, 2)``;
    ``dx`` the predicted step lengths.  ``solved`` is IPOPT's verdict; ``valid`` (``None``
    until validated) whether every planned pair succeeds in the true aSLIP.
    """

    solved: bool
    ipopt_status: str
    states: FloatArray
    actions: FloatArray
    dx: FloatArray
    objective: float
    solve_time: float
    iterations: int
    step_status: tuple[int, ...] | None = None
    valid: bool | None = None
    extras: dict[str, Any] = field(default_factory=dict)


class FootstepPlanner:
    """Builds the CasADi/IPOPT NLP once for a configuration; :meth:`solve` per task."""

    def __init__(self, return_map: DenseNetwork, margin: DenseNetwork, config: PlannerConfig) -> None:
        import casadi as ca

        if return_map.in_dim != 4 or return_map.out_dim != 3:
            raise ValueError("return_map must map 4 inputs to [dx, y1, xdot1]")
        if margin.in_dim != 4 or margin.out_dim != 1:
            raise ValueError("margin must map 4 inputs to one value")
        self.config = config
        self.return_map = return_map
        self.margin = margin
        n = config.horizon
        x = ca.SX.sym("x", 4 * n)
        par = ca.SX.sym("p", 4)  # [s0, s_goal]
        states = [par[0:2]] + [x[2 * i : 2 * i + 2] for i in range(n)]
        actions = [x[2 * n + 2 * i : 2 * n + 2 * i + 2] for i in range(n)]
        h_w = ca.DM(list(config.state_weights))
        f = 0
        g_dyn, g_margin, dx_pred = [], [], []
        for i in range(n):
            zi = ca.vertcat(states[i], actions[i])
            pi = return_map.casadi(zi)
            g_dyn.append(pi[1:3] - states[i + 1])  # eq. (8)
            dx_pred.append(pi[0])
            if config.use_margin:
                g_margin.append(margin.casadi(zi) - config.epsilon)  # eq. (9)
            if config.objective == "state":
                d = states[i] - states[i + 1]
                f += ca.dot(h_w * d, d)  # eq. (7)
        g_goal = states[n] - par[2:4]  # eq. (10)
        g = ca.vertcat(*g_dyn, g_goal, *g_margin)
        self._n_eq = 2 * n + 2
        self._n_ineq = len(g_margin)
        opts = {
            "ipopt.print_level": 0,
            "print_time": False,
            "ipopt.sb": "yes",
            "ipopt.max_iter": config.max_iter,
            "ipopt.tol": config.tol,
            "ipopt.hessian_approximation": config.hessian,
        }
        self._solver = ca.nlpsol("plan", "ipopt", {"x": x, "p": par, "f": f, "g": g}, opts)
        self._dx_fun = ca.Function("dx", [x, par], [ca.vertcat(*dx_pred)])
        self._lbg = np.concatenate([np.zeros(self._n_eq), np.zeros(self._n_ineq)])
        self._ubg = np.concatenate([np.zeros(self._n_eq), np.full(self._n_ineq, np.inf)])
        self._lbx = np.concatenate([np.tile(BOX_LOW[:2], n), np.tile(BOX_LOW[2:], n)])
        self._ubx = np.concatenate([np.tile(BOX_HIGH[:2], n), np.tile(BOX_HIGH[2:], n)])

    @classmethod
    def from_bundle(cls, config: PlannerConfig, bundle: Bundle | None = None) -> FootstepPlanner:
        b = bundle if bundle is not None else load_bundle()
        return cls(b.return_map, b.margin, config)

    def initial_guess(self, s0: FloatArray, goal: FloatArray) -> FloatArray:
        """States on the straight line from ``s0`` to ``goal``; actions at the box centre."""
        n = self.config.horizon
        frac = np.arange(1, n + 1)[:, None] / n
        states = s0[None, :] + frac * (goal - s0)[None, :]
        actions = np.tile(0.5 * (BOX_LOW[2:] + BOX_HIGH[2:]), (n, 1))
        return np.concatenate([states.ravel(), actions.ravel()])

    def solve(self, s0: ArrayLike, goal: ArrayLike, x0: ArrayLike | None = None) -> PlanResult:
        """Solve the NLP for one task (``s0``, ``goal`` are ``[y, xdot]``)."""
        s0_arr = np.asarray(s0, dtype=float).reshape(-1)
        goal_arr = np.asarray(goal, dtype=float).reshape(-1)
        if s0_arr.shape != (2,) or goal_arr.shape != (2,):
            raise ValueError(f"s0 and goal must be [y, xdot]; got shapes {s0_arr.shape}, {goal_arr.shape}")
        n = self.config.horizon
        guess = self.initial_guess(s0_arr, goal_arr) if x0 is None else np.asarray(x0, dtype=float)
        if guess.shape != (4 * n,):
            raise ValueError(f"x0 must have shape ({4 * n},); got {guess.shape}")
        par = np.concatenate([s0_arr, goal_arr])
        t0 = time.perf_counter()
        sol = self._solver(x0=guess, p=par, lbx=self._lbx, ubx=self._ubx, lbg=self._lbg, ubg=self._ubg)
        elapsed = time.perf_counter() - t0
        stats = self._solver.stats()
        xs = np.array(sol["x"]).ravel()
        states = np.vstack([s0_arr, xs[: 2 * n].reshape(n, 2)])
        actions = xs[2 * n :].reshape(n, 2)
        status = str(stats.get("return_status", "unknown"))
        return PlanResult(
            solved=status in _SUCCESS,
            ipopt_status=status,
            states=states,
            actions=actions,
            dx=np.array(self._dx_fun(xs, par)).ravel(),
            objective=float(sol["f"]),
            solve_time=elapsed,
            iterations=int(stats.get("iter_count", -1)),
        )

    def constraint_residuals(self, plan: PlanResult, goal: ArrayLike) -> dict[str, float]:
        """Constraint violations of a plan, recomputed with the numpy networks.

        Returns the max absolute dynamics and goal residuals and the min margin slack
        :math:`\\min_n M(s_n, a_n) - \\varepsilon` (NaN without margin constraints).
        """
        z = np.column_stack([plan.states[:-1], plan.actions])
        dyn = self.return_map(z)[:, 1:] - plan.states[1:]
        goal_err = plan.states[-1] - np.asarray(goal, dtype=float)
        slack = self.margin(z)[:, 0] - self.config.epsilon
        box_viol = max(float(np.max(BOX_LOW - z, initial=0.0)), float(np.max(z - BOX_HIGH, initial=0.0)))
        return {
            "dynamics": float(np.max(np.abs(dyn))),
            "goal": float(np.max(np.abs(goal_err))),
            "margin_slack": float(slack.min()) if self.config.use_margin else float("nan"),
            "box_violation": box_viol,
        }


def validate_plan(plan: PlanResult, params: SlipParams | None = None) -> PlanResult:
    """Simulate every planned pair ``(s_n, a_n)`` with the true aSLIP (batched).

    Returns a copy with ``step_status`` and ``valid`` set, and in ``extras`` the open-loop
    rollout (actions applied in sequence from the true :math:`s_0`): whether all its hops
    succeed and its final-state error.
    """
    res = simulate_batch(plan.states[:-1], plan.actions, params)
    steps = tuple(int(s) for s in res.status)
    s = plan.states[0].copy()
    rollout_ok = True
    for a in plan.actions:
        r = simulate_batch(s[None, :], a[None, :], params)
        if not r.valid[0]:
            rollout_ok = False
            break
        s = r.next_apex[0, 1:]
    extras = dict(plan.extras)
    extras["rollout_valid"] = rollout_ok
    extras["rollout_goal_error"] = float(np.max(np.abs(s - plan.states[-1]))) if rollout_ok else float("nan")
    return PlanResult(
        **{**plan.__dict__, "step_status": steps, "valid": all(c == Status.OK for c in steps), "extras": extras}
    )


def random_tasks(n: int, seed: int) -> tuple[FloatArray, FloatArray]:
    """``n`` random (s0, goal) pairs, uniform in the state part of the eq. (13) box."""
    if n < 1:
        raise ValueError(f"n must be >= 1; got {n}")
    rng = np.random.default_rng(seed)
    lo, hi = BOX_LOW[:2], BOX_HIGH[:2]
    return lo + (hi - lo) * rng.random((n, 2)), lo + (hi - lo) * rng.random((n, 2))


# ---------------------------------------------------------------------------- Table I


def run_table(
    n_tasks: int,
    seed: int,
    horizons: Sequence[int] = (3, 4),
    bundle: Bundle | None = None,
    epsilon: float = 0.05,
    log: bool = False,
) -> list[dict[str, Any]]:
    """Solve every task under each (horizon, objective, margin) setting and tally outcomes."""
    b = bundle if bundle is not None else load_bundle()
    s0s, goals = random_tasks(n_tasks, seed)
    rows: list[dict[str, Any]] = []
    for horizon in horizons:
        for objective in ("state", "none"):
            for use_margin in (True, False):
                cfg = PlannerConfig(horizon=horizon, objective=objective, use_margin=use_margin, epsilon=epsilon)
                planner = FootstepPlanner(b.return_map, b.margin, cfg)
                counts = {"infeasible": 0, "invalid": 0, "valid": 0}
                statuses: dict[str, int] = {}
                times, rollout_valid = [], 0
                for s0, goal in zip(s0s, goals, strict=True):
                    plan = planner.solve(s0, goal)
                    times.append(plan.solve_time)
                    statuses[plan.ipopt_status] = statuses.get(plan.ipopt_status, 0) + 1
                    if not plan.solved:
                        counts["infeasible"] += 1
                        continue
                    plan = validate_plan(plan)
                    counts["valid" if plan.valid else "invalid"] += 1
                    rollout_valid += int(plan.extras["rollout_valid"])
                row = {
                    "horizon": horizon,
                    "objective": objective,
                    "margin": use_margin,
                    "n_tasks": n_tasks,
                    "epsilon": epsilon,
                    "pct_infeasible": 100.0 * counts["infeasible"] / n_tasks,
                    "pct_invalid": 100.0 * counts["invalid"] / n_tasks,
                    "pct_valid": 100.0 * counts["valid"] / n_tasks,
                    "mean_time_s": float(np.mean(times)),
                    "pct_rollout_valid": 100.0 * rollout_valid / n_tasks,
                    "ipopt_status": statuses,
                    "paper": dict(
                        zip(
                            ("pct_infeasible", "pct_invalid", "pct_valid", "mean_time_s"),
                            PAPER_TABLE_I[(horizon, objective, use_margin)],
                            strict=True,
                        )
                    )
                    if (horizon, objective, use_margin) in PAPER_TABLE_I
                    else None,
                }
                rows.append(row)
                if log:
                    print(
                        f"N={horizon} {objective:5s} margin={use_margin!s:5s}: "
                        f"{row['pct_infeasible']:.1f}/{row['pct_invalid']:.1f}/{row['pct_valid']:.1f} % "
                        f"{row['mean_time_s'] * 1e3:.1f} ms",
                        file=sys.stderr,
                    )
    return rows


def table_markdown(rows: list[dict[str, Any]]) -> str:
    """Table I layout: one block per horizon, ours and the paper's numbers side by side."""
    lines: list[str] = []
    for horizon in sorted({r["horizon"] for r in rows}):
        block = [r for r in rows if r["horizon"] == horizon]
        head = " | ".join(f"{r['objective']} obj., {'margin' if r['margin'] else 'no margin'}" for r in block)
        lines += [
            f"### {horizon}-step horizon ({block[0]['n_tasks']} random tasks, "
            f"epsilon = {block[0].get('epsilon', 0.05)}; ours (paper, epsilon = 0.05))",
            "",
            f"| | {head} |",
            "|---" * (len(block) + 1) + "|",
        ]
        for key, label, fmt in (
            ("pct_infeasible", "Declared infeasible", "{:.1f} %"),
            ("pct_invalid", "Invalid solution", "{:.1f} %"),
            ("pct_valid", "Valid solution", "{:.1f} %"),
            ("mean_time_s", "Mean time (s)", "{:.3f}"),
        ):
            cells = []
            for r in block:
                ours = fmt.format(r[key])
                paper = fmt.format(r["paper"][key]) if r["paper"] else "-"
                cells.append(f"{ours} ({paper})")
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
        lines.append(
            "| Open-loop rollout valid | " + " | ".join(f"{r['pct_rollout_valid']:.1f} %" for r in block) + " |"
        )
        lines.append("")
    return "\n".join(lines)


def plot_fig5(out: Path, seed: int, bundle: Bundle | None = None, max_tries: int = 300) -> dict[str, Any]:
    """Fig. 5 style: a 3-step task whose margin plan is valid and whose no-margin plan is not.

    Each planned pair is simulated with the true aSLIP and the body paths are drawn end to
    end (each hop starts where the previous simulated hop ended).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    b = bundle if bundle is not None else load_bundle()
    with_m = FootstepPlanner(b.return_map, b.margin, PlannerConfig(horizon=3, objective="none"))
    without = FootstepPlanner(b.return_map, b.margin, PlannerConfig(horizon=3, objective="none", use_margin=False))
    s0s, goals = random_tasks(max_tries, seed + 1)
    chosen = None
    for s0, goal in zip(s0s, goals, strict=True):
        pm, pn = with_m.solve(s0, goal), without.solve(s0, goal)
        if pm.solved and pn.solved:
            pm, pn = validate_plan(pm), validate_plan(pn)
            if pm.valid and not pn.valid:
                chosen = (s0, goal, pm, pn)
                break
    if chosen is None:
        raise RuntimeError(f"no task among {max_tries} separates the two planners")
    s0, goal, pm, pn = chosen
    fig, ax = plt.subplots(figsize=(8.0, 3.2), dpi=110)
    for plan, colour, label in (
        (pm, "tab:green", "with margin constraints"),
        (pn, "tab:red", "without margin constraints"),
    ):
        x_start = 0.0
        for k, (s, a) in enumerate(zip(plan.states[:-1], plan.actions, strict=True)):
            hop = simulate_hop(s, a, record_path=True)
            path = hop.path
            assert path is not None
            ax.plot(path[:, 1] + x_start, path[:, 2], color=colour, label=label if k == 0 else None)
            if not hop.ok:
                ax.plot(hop.failure[0] + x_start, hop.failure[1], "x", color=colour, ms=10, mew=2)
                ax.annotate(
                    Status(hop.status).name,
                    (hop.failure[0] + x_start, hop.failure[1]),
                    textcoords="offset points",
                    xytext=(5, -12),
                    color=colour,
                    fontsize=8,
                )
                break
            x_start += hop.next_apex[0]
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xlabel("x [l0]")
    ax.set_ylabel("y [l0]")
    ax.set_title(
        f"3-step plan, s0=({s0[0]:.2f}, {s0[1]:.2f}) -> goal=({goal[0]:.2f}, {goal[1]:.2f}), no objective", fontsize=9
    )
    ax.set_aspect("equal")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return {"s0": s0.tolist(), "goal": goal.tolist(), "margin_steps": pm.step_status, "no_margin_steps": pn.step_status}


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="python -m margin_rl.slip.planner", description="Reproduce Table I (and a Fig. 5-style plot) of the paper."
    )
    ap.add_argument("--n-tasks", type=int, default=1000, help="random tasks per setting (paper: 1000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--horizons", type=int, nargs="+", default=[3, 4])
    ap.add_argument("--epsilon", type=float, default=0.05)
    ap.add_argument("--out", type=Path, required=True, help="directory for table1.md/.json and fig5.png")
    ap.add_argument("--no-fig5", action="store_true")
    return ap.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = _parse(argv)
    bundle = load_bundle()
    t0 = time.perf_counter()
    rows = run_table(args.n_tasks, args.seed, args.horizons, bundle, args.epsilon, log=True)
    report: dict[str, Any] = {
        "command": " ".join(["python -m margin_rl.slip.planner", *sys.argv[1:]]),
        "seconds": round(time.perf_counter() - t0, 1),
        "weights_card": bundle.card["files"],
        "rows": rows,
    }
    if not args.no_fig5:
        report["fig5"] = plot_fig5(args.out / "fig5.png", args.seed, bundle)
    args.out.mkdir(parents=True, exist_ok=True)
    md = "# Table I reproduction (aSLIP footstep planner)\n\n" + table_markdown(rows)
    (args.out / "table1.md").write_text(md)
    (args.out / "table1.json").write_text(json.dumps(report, indent=2) + "\n")
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
