"""The learned margin judged by seed 000's own protocol (§V-A), beside the overall held-out metrics.

Seed 000 reports no overall error of m_l. It reports two things:

* **reliability**: the sign of m_l (stable when m >= 0) as a binary classifier, "based on the range of
  samples within two times the standard deviation of the dataset generated using the parameters sampled
  from the distributions given in Tab. I", over a batch of 2.5e4 samples: true positive rate 0.970, true
  negative rate 0.984. Read here as: every entry of lambda within two standard deviations of its mean over
  the training data (:func:`within_two_sigma`, with the mean and spread stored with the weights). For the
  uniform entries of Table I this keeps everything (a uniform variable never leaves +-1.73 sigma); it cuts
  the tails of the normal ones (external wrench, vertical velocity, yaw acceleration, contact normals) and
  of the kinematically conditioned feet.
* **accuracy along acceleration sweeps** (Fig. 4): m_a and m_l, and their derivatives, as the CoM
  acceleration c_ddot_x (or c_ddot_y) sweeps a range with the rest of the state fixed, in a double stance;
  "the prediction error of m_l is always below 1.0 cm for CoM accelerations within [-2, 2] m/s^2".
  :func:`acceleration_sweeps` runs such sweeps from many base states (the nominal stance of each contact
  pattern, and Table I draws), so the claim is measured over a distribution rather than one curve.

Command line (fresh states, any weights; prints JSON, optionally writes it and a Fig. 4-like picture)::

    python -m margin_rl.stability.learned.evaluation --robot anymal_c [--weights PATH] [--n 25000] [--sweeps 40] \\
        [--out report.json] [--figure docs/learned_margin/anymal_c_acc_sweeps.png] [--update-card]
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from margin_rl.atomic import atomic_write_text
from margin_rl.robot import load_robot
from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES, check_lambda, lambda_names
from margin_rl.stability.analytic.margin import STATUSES, AnalyticSettings, analytic_margin_batch
from margin_rl.stability.analytic.sampling import sample_states, standing_state
from margin_rl.stability.learned.model import LearnedMargin, weights_path

PAPER_RELIABILITY = {"true_positive_rate": 0.970, "true_negative_rate": 0.984, "n": 25_000}
"""Seed 000 §V-A, on samples within two standard deviations of the dataset."""

PAPER_SWEEP_SPAN = 2.0
"""[m/s^2] seed 000 §V-A: error below 1 cm for c_ddot_x, c_ddot_y in [-2, 2]."""

PAPER_SWEEP_TOLERANCE = 0.01
"""[m] the 1.0 cm of that claim."""

_COM_ACC = LAMBDA_SLICES["com_acc"]
_CONTACTS = LAMBDA_SLICES["contacts"]
_FEET_IN_CONTACT = {
    # Contact patterns (LF, RF, LH, RH) of the nominal sweep states: Fig. 4's double stance is a trot pair.
    "4 feet": (1, 1, 1, 1),
    "3 feet (LH lifted)": (1, 1, 0, 1),
    "2 feet (LF+RH)": (1, 0, 0, 1),
}


def within_two_sigma(lam: np.ndarray, mean: np.ndarray, std: np.ndarray, k: float = 2.0) -> np.ndarray:
    """True where every entry of lambda lies within ``k`` standard deviations of its dataset mean.

    The contact flags are exempt: Table I draws the number of lifted feet, X ~ U{0, 1, 2}, whose two-sigma
    range holds every value, while a per-flag test would drop every state with a foot in the air (a flag
    of mean 0.8 and deviation 0.4 puts 0 at the edge of its range).

    Args:
        lam: (N, 47) or (47,) lambda.
        mean, std: (47,) per-entry mean and standard deviation of the dataset (the training split's,
            stored with the weights as the input normalisation).
        k: the number of standard deviations (the paper: 2).

    Returns:
        (N,) bool, or a bool for one lambda.
    """
    x = check_lambda(lam)
    if not k > 0:
        raise ValueError(f"k must be positive, got {k}")
    inside_entries = np.abs(x - np.asarray(mean)) <= k * np.asarray(std)
    inside_entries[..., _CONTACTS] = True
    inside = inside_entries.all(axis=-1)
    return bool(inside) if inside.ndim == 0 else inside


@dataclass(frozen=True)
class Reliability:
    """Sign of the learned margin as a stability classifier (stable: m >= 0), against the analytic sign."""

    n: int
    stable_fraction: float  # of the analytic labels
    true_positive_rate: float  # stable states called stable
    true_negative_rate: float  # unstable states called unstable
    sign_agreement: float
    rmse_cm: float


def reliability(learned: np.ndarray, analytic: np.ndarray) -> Reliability:
    """Classification rates and RMSE of ``learned`` margins against ``analytic`` ones (both (N,) [m])."""
    learned, analytic = np.asarray(learned, dtype=float), np.asarray(analytic, dtype=float)
    if learned.shape != analytic.shape or learned.ndim != 1:
        raise ValueError(f"need two (N,) arrays of margins, got {learned.shape} and {analytic.shape}")
    stable, called_stable = analytic >= 0, learned >= 0
    nan = float("nan")
    return Reliability(
        n=len(analytic),
        stable_fraction=float(stable.mean()) if len(analytic) else nan,
        true_positive_rate=float(called_stable[stable].mean()) if stable.any() else nan,
        true_negative_rate=float((~called_stable[~stable]).mean()) if (~stable).any() else nan,
        sign_agreement=float((stable == called_stable).mean()) if len(analytic) else nan,
        rmse_cm=100 * float(np.sqrt(np.mean((learned - analytic) ** 2))) if len(analytic) else nan,
    )


def paper_reliability(model: LearnedMargin, lam: np.ndarray, margin: np.ndarray) -> dict[str, Reliability]:
    """:func:`reliability` on all labelled states and on those within two sigma (the paper's protocol).

    Args:
        model: the learned margin (its stored input mean and spread define "two sigma").
        lam: (N, 47) states whose analytic status is ok.
        margin: (N,) their analytic margins [m].
    """
    lam = check_lambda(lam, "lam")
    inside = within_two_sigma(lam, model.params.input_mean, model.params.input_std)
    learned = np.asarray(model(lam))
    return {
        "all": reliability(learned, margin),
        "within_2_sigma": reliability(learned[inside], margin[inside]),
    }


def acceleration_sweep_states(base: np.ndarray, axis: int, values: np.ndarray) -> np.ndarray:
    """(P, 47): ``base`` lambda with the CoM acceleration component ``axis`` (0: x, 1: y) set to each value.

    The acceleration is in the horizontal frame [m/s^2], as in lambda; nothing else changes (new array).
    """
    base = check_lambda(base, "base")
    if base.ndim != 1 or axis not in (0, 1):
        raise ValueError(f"need one base lambda (47,) and axis 0 or 1, got shape {base.shape}, axis {axis}")
    states = np.repeat(base[None, :], len(values), axis=0)
    states[:, _COM_ACC.start + axis] = values
    return states


def nominal_sweep_bases(robot_name: str) -> dict[str, np.ndarray]:
    """The standing robot (static, flat ground, mu 0.8) in each contact pattern of ``_FEET_IN_CONTACT``."""
    robot = load_robot(robot_name)
    return {name: standing_state(robot, contacts=np.array(c, float)) for name, c in _FEET_IN_CONTACT.items()}


@dataclass(frozen=True)
class SweepResult:
    """Margins along CoM-acceleration sweeps: arrays are (S, 2, P) for S base states, axes x and y, P points.

    ``analytic`` is NaN where the analytic status is not ok; ``learned_slope`` is dm_l/dc_ddot by
    backpropagation and ``analytic_slope`` central differences of m_a along the grid [m per m/s^2].
    """

    names: tuple[str, ...]
    values: np.ndarray  # (P,) [m/s^2]
    analytic: np.ndarray
    learned: np.ndarray
    analytic_slope: np.ndarray
    learned_slope: np.ndarray

    def subset(self, index: int) -> SweepResult:
        """The sweeps of base state ``index`` alone."""
        rows = slice(index, index + 1)
        return SweepResult(
            names=self.names[rows],
            values=self.values,
            analytic=self.analytic[rows],
            learned=self.learned[rows],
            analytic_slope=self.analytic_slope[rows],
            learned_slope=self.learned_slope[rows],
        )

    def summary(self, tolerance: float = PAPER_SWEEP_TOLERANCE) -> dict[str, object]:
        """Error statistics over all sweep points and per sweep (a sweep: one base state, one axis)."""
        err = np.abs(self.learned - self.analytic)
        ok = np.isfinite(err)
        per_sweep_max = np.where(ok, err, -np.inf).max(axis=-1)
        full = ok.all(axis=-1)  # sweeps where the analytic margin exists at every point
        slope_err = self.learned_slope - self.analytic_slope
        slope_ok = np.isfinite(slope_err)
        return {
            "sweeps": int(full.size),
            "points_ok": int(ok.sum()),
            "points_total": int(ok.size),
            "rmse_cm": 100 * float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else float("nan"),
            "max_error_cm": 100 * float(err[ok].max()) if ok.any() else float("nan"),
            "fraction_of_points_within_tolerance": float(np.mean(err[ok] <= tolerance)) if ok.any() else float("nan"),
            "fraction_of_full_sweeps_within_tolerance": float(np.mean(per_sweep_max[full] <= tolerance))
            if full.any()
            else float("nan"),
            "median_max_error_per_full_sweep_cm": 100 * float(np.median(per_sweep_max[full]))
            if full.any()
            else float("nan"),
            "slope_rmse_cm_per_mps2": 100 * float(np.sqrt(np.mean(slope_err[slope_ok] ** 2)))
            if slope_ok.any()
            else float("nan"),
            "tolerance_cm": 100 * tolerance,
        }


def acceleration_sweeps(
    robot_name: str,
    model: LearnedMargin,
    bases: dict[str, np.ndarray] | np.ndarray,
    span: float = PAPER_SWEEP_SPAN,
    points: int = 41,
    settings: AnalyticSettings | None = None,
    workers: int | None = None,
) -> SweepResult:
    """m_a and m_l (and slopes) as c_ddot_x and c_ddot_y sweep [-span, span] from each base state.

    Args:
        robot_name: the robot of the analytic margin.
        model: the learned margin.
        bases: named base states {name: (47,)} or an (S, 47) array (named by index).
        span: half-width of the sweep [m/s^2].
        points: grid points per sweep (odd keeps 0 on the grid).
        settings: analytic settings; pass those recorded with the training labels (default: the package's).
        workers: processes for the analytic margin.
    """
    if isinstance(bases, dict):
        names, base_array = tuple(bases), np.array(list(bases.values()), dtype=float)
    else:
        base_array = check_lambda(np.asarray(bases, dtype=float), "bases")
        names = tuple(str(i) for i in range(len(base_array)))
    if base_array.ndim != 2 or not len(base_array):
        raise ValueError(f"need at least one base state, got shape {base_array.shape}")
    if not span > 0 or points < 3:
        raise ValueError(f"need span > 0 and points >= 3, got span={span}, points={points}")
    values = np.linspace(-span, span, points)
    states = np.stack([[acceleration_sweep_states(b, axis, values) for axis in (0, 1)] for b in base_array])
    flat = states.reshape(-1, states.shape[-1])
    labels = analytic_margin_batch(robot_name, flat, settings, workers=workers)
    analytic = np.where(labels.status == STATUSES.index("ok"), labels.margin, np.nan).reshape(states.shape[:-1])
    learned, grad = model.value_and_grad(flat)
    learned = np.asarray(learned).reshape(states.shape[:-1])
    grad = grad.reshape(*states.shape[:-1], -1)
    learned_slope = np.stack([grad[:, axis, :, _COM_ACC.start + axis] for axis in (0, 1)], axis=1)
    analytic_slope = np.full_like(analytic, np.nan)
    h = values[1] - values[0]
    analytic_slope[..., 1:-1] = (analytic[..., 2:] - analytic[..., :-2]) / (2 * h)
    return SweepResult(names, values, analytic, learned, analytic_slope, learned_slope)


def sweep_figure(result: SweepResult, index: int, path: Path, title: str = "") -> Path:
    """Fig. 4 of seed 000 for base state ``index``: margins (top) and slopes (bottom) along x and y sweeps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True, constrained_layout=True)
    for axis, label in enumerate(("x", "y")):
        top, bottom = axes[0, axis], axes[1, axis]
        top.plot(result.values, 100 * result.analytic[index, axis], "r-", label="analytic $m_a$")
        top.plot(result.values, 100 * result.learned[index, axis], "b-", label="learned $m_l$")
        top.set(ylabel="margin [cm]", title=f"{title} sweep of $\\ddot c_{label}$".strip())
        bottom.plot(result.values, result.analytic_slope[index, axis], "r-", label="central differences of $m_a$")
        bottom.plot(result.values, result.learned_slope[index, axis], "b-", label="backpropagation of $m_l$")
        bottom.set(xlabel=f"$\\ddot c_{label}$ [m/s$^2$]", ylabel=f"$\\partial m / \\partial \\ddot c_{label}$ [s$^2$]")
    axes[0, 0].legend()
    axes[1, 0].legend()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


GRADIENT_FOCUS_TOL = 1e-5  # [m] the margin bracket of the gradient check's analytic margins


def finite_difference_steps(input_std: np.ndarray) -> np.ndarray:
    """Central-difference step per lambda entry: 2 % of its training spread (smaller for e_g, kept unit)."""
    h = 0.02 * np.asarray(input_std, dtype=float)
    h[LAMBDA_SLICES["gravity_axis"]] = np.minimum(h[LAMBDA_SLICES["gravity_axis"]], 2e-4)
    return h


def gradient_check(
    model: LearnedMargin, robot_name: str, lam: np.ndarray, settings: AnalyticSettings, workers: int | None = None
) -> dict[str, object]:
    """Cosine similarity of dm_l/dlambda with central finite differences of m_a (2 x 43 analytic calls each).

    Contact flags are binary and skipped; an entry is used only when both perturbed states are ``ok``.
    The analytic margins are computed with ``settings`` (those of the labels) but a tight focus bracket,
    :data:`GRADIENT_FOCUS_TOL`, so that bracket noise stays far below the finite-difference signal.
    """
    settings = replace(settings, focus_tol=GRADIENT_FOCUS_TOL)
    steps = finite_difference_steps(model.params.input_std)
    contacts = set(range(LAMBDA_SLICES["contacts"].start, LAMBDA_SLICES["contacts"].stop))
    dims = [j for j in range(lam.shape[1]) if j not in contacts]
    plus = np.repeat(lam[:, None, :], len(dims), axis=1).astype(np.float64)
    minus = plus.copy()
    for k, j in enumerate(dims):
        plus[:, k, j] += steps[j]
        minus[:, k, j] -= steps[j]
    both = np.concatenate([plus.reshape(-1, lam.shape[1]), minus.reshape(-1, lam.shape[1])])
    labels = analytic_margin_batch(robot_name, both, settings, workers=workers)
    ok = labels.status == STATUSES.index("ok")
    m = labels.margin.reshape(2, len(lam), len(dims))
    ok = ok.reshape(2, len(lam), len(dims)).all(axis=0)
    fd = (m[0] - m[1]) / (2 * steps[dims])
    learned = model.grad(lam.astype(np.float64))[:, dims]
    cosines = []
    for i in range(len(lam)):
        a, b = learned[i][ok[i]], fd[i][ok[i]]
        if len(a) >= len(dims) // 2 and np.linalg.norm(a) > 0 and np.linalg.norm(b) > 0:
            cosines.append(float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b))))
    cos = np.asarray(cosines)
    return {
        "n_states": len(cos),
        "analytic_calls": len(both),
        "median_cosine": float(np.median(cos)) if len(cos) else float("nan"),
        "p10_cosine": float(np.percentile(cos, 10)) if len(cos) else float("nan"),
        "fraction_above_0.9": float(np.mean(cos >= 0.9)) if len(cos) else float("nan"),
        "step": {name: float(s) for name, s in zip(lambda_names(), steps, strict=True) if s > 0},
    }


def evaluate(
    robot_name: str,
    model: LearnedMargin,
    n: int = PAPER_RELIABILITY["n"],
    sweeps: int = 40,
    seed: int = 424242,
    workers: int | None = None,
    settings: AnalyticSettings | None = None,
) -> tuple[dict[str, object], SweepResult]:
    """The paper's protocol on fresh Table I states: reliability (all / within two sigma) and sweeps.

    ``n`` states are drawn (seed ``seed``) and labelled with ``settings`` (those of the training labels;
    default settings if omitted); the sweeps start from the nominal stances of :func:`nominal_sweep_bases`
    and from ``sweeps`` further Table I draws (another seed). Returns the report and the nominal sweeps.
    """
    if n < 1 or sweeps < 0:
        raise ValueError(f"need n >= 1 and sweeps >= 0, got n={n}, sweeps={sweeps}")
    robot = load_robot(robot_name)
    lam = sample_states(robot, n, seed=seed)
    labels = analytic_margin_batch(robot_name, lam, settings, workers=workers)
    ok = labels.status == STATUSES.index("ok")
    rel = paper_reliability(model, lam[ok], labels.margin[ok])
    bases = nominal_sweep_bases(robot_name)
    nominal = acceleration_sweeps(robot_name, model, bases, settings=settings, workers=workers)
    report: dict[str, object] = {
        "robot": robot_name,
        "weights": model.card.get("sha256"),
        "analytic_settings": (settings or AnalyticSettings()).as_dict(),
        "reliability": {
            "states_drawn": n,
            "states_ok": int(ok.sum()),
            "seed": seed,
            **{k: asdict(v) for k, v in rel.items()},
            "paper": PAPER_RELIABILITY,
        },
        "acceleration_sweeps": {
            "span_mps2": PAPER_SWEEP_SPAN,
            "points": len(nominal.values),
            "nominal": {name: nominal.subset(i).summary() for i, name in enumerate(nominal.names)},
        },
    }
    if sweeps:
        random_bases = sample_states(robot, sweeps, seed=seed + 1)
        random_result = acceleration_sweeps(robot_name, model, random_bases, settings=settings, workers=workers)
        report["acceleration_sweeps"]["table_i"] = {"base_states": sweeps, **random_result.summary()}  # type: ignore[index]
    return report, nominal


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m margin_rl.stability.learned.evaluation", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--robot", required=True, help="robot of the analytic margin (anymal_b, anymal_c)")
    parser.add_argument("--weights", default=None, help="weights .npz (default: the robot's bundled weights)")
    parser.add_argument("--n", type=int, default=PAPER_RELIABILITY["n"], help="fresh Table I states to label")
    parser.add_argument("--sweeps", type=int, default=40, help="Table I base states for acceleration sweeps")
    parser.add_argument("--seed", type=int, default=424242)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--out", default=None, help="write the report as JSON here")
    parser.add_argument("--figure", default=None, help="write a Fig. 4-like PNG of the nominal double stance")
    parser.add_argument(
        "--gradient-states",
        type=int,
        default=0,
        help="also compare dm_l/dlambda with finite differences of m_a on this many fresh Table I states",
    )
    parser.add_argument(
        "--update-card",
        action="store_true",
        help="store the report as 'paper_protocol' in the weights' model card (the checksum is of the .npz)",
    )
    args = parser.parse_args(argv)
    npz = weights_path(args.weights or args.robot)
    model = LearnedMargin.load(npz)
    if model.card.get("robot", args.robot) != args.robot:
        parser.error(f"{npz} holds the learned margin of {model.card['robot']!r}, not of --robot {args.robot!r}")
    recorded = model.card.get("analytic_settings")  # the settings of the labels the network learned
    settings = AnalyticSettings.from_dict(recorded) if isinstance(recorded, dict) else None
    report, nominal = evaluate(args.robot, model, args.n, args.sweeps, args.seed, args.workers, settings)
    if args.gradient_states > 0:  # the training card's check, on fresh Table I states (not the protocol's seed)
        lam = sample_states(load_robot(args.robot), args.gradient_states, seed=args.seed + 2)
        report["gradient_check"] = gradient_check(
            model, args.robot, lam, settings or AnalyticSettings(), workers=args.workers
        )
    report["command"] = "python -m margin_rl.stability.learned.evaluation " + " ".join(argv or sys.argv[1:])
    text = json.dumps(report, indent=2)
    print(text)
    if args.out:
        atomic_write_text(Path(args.out), text + "\n")
    if args.update_card:
        card_path = npz.with_suffix(".json")
        card = json.loads(card_path.read_text())
        if "gradient_check" in report:
            check = report["gradient_check"]
            card["gradient_check"] = {**check, "states": "fresh Table I", "command": report["command"]}
        card["paper_protocol"] = {k: v for k, v in report.items() if k != "gradient_check"}
        atomic_write_text(card_path, json.dumps(card, indent=2) + "\n")
    if args.figure:
        double = nominal.names.index("2 feet (LF+RH)")
        sweep_figure(nominal, double, Path(args.figure), title=f"{args.robot}, LF+RH stance:")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
