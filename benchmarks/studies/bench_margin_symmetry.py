"""Left-right symmetry of the analytic and the learned margin on fresh Table I states.

Usage:
    python benchmarks/studies/bench_margin_symmetry.py --robot anymal_c --n 6000 [--weights path/to/weights.npz ...]

For every state lambda and its mirror image M lambda (:func:`margin_rl.stability.analytic.lambda_state.mirror_lambda`)
it reports, as a Markdown table:

* the analytic asymmetry |m_a(M lambda) - m_a(lambda)| (zero for a symmetric robot, up to the focus bracket);
* for each set of learned weights (the bundled ones by default): the RMSE against m_a of m_l(lambda), of
  m_l(M lambda) and of their mean (a symmetrised evaluation at twice the cost), the sign agreement, and the
  learned asymmetry RMS |m_l(M lambda) - m_l(lambda)|.
"""

from __future__ import annotations

import argparse

import numpy as np

from margin_rl.robot import load_robot
from margin_rl.stability.analytic.lambda_state import mirror_lambda
from margin_rl.stability.analytic.margin import STATUSES, analytic_margin_batch
from margin_rl.stability.analytic.sampling import sample_states
from margin_rl.stability.learned.model import LearnedMargin


def rmse_cm(error: np.ndarray) -> float:
    return 100 * float(np.sqrt(np.mean(error**2)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robot", default="anymal_c")
    parser.add_argument("--n", type=int, default=6000, help="Table I states drawn (about 2/3 are ok)")
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--weights", action="append", help="weights .npz (default: the bundled ones)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    lam = sample_states(load_robot(args.robot), args.n, seed=args.seed)
    mirrored = mirror_lambda(lam)
    direct = analytic_margin_batch(args.robot, lam, workers=args.workers)
    image = analytic_margin_batch(args.robot, mirrored, workers=args.workers)
    ok_index = STATUSES.index("ok")
    ok = (direct.status == ok_index) & (image.status == ok_index)
    m_a = direct.margin[ok]
    gap = np.abs(image.margin[ok] - m_a)
    print(
        f"{args.robot}: {ok.sum():,} of {args.n:,} states ok in both images; status agreement "
        f"{np.mean(direct.status == image.status):.4f}; analytic asymmetry median {1000 * np.median(gap):.3f} mm, "
        f"p99 {1000 * np.percentile(gap, 99):.3f} mm, max {1000 * gap.max():.3f} mm\n"
    )
    print(
        "| weights | RMSE m_l(lam) [cm] | RMSE m_l(M lam) [cm] | RMSE mean of both [cm] "
        "| sign agreement | asymmetry RMS [cm] |"
    )
    print("|---|---|---|---|---|---|")
    for source in args.weights or [args.robot]:
        model = LearnedMargin.load(source)
        plain, other = np.asarray(model(lam[ok])), np.asarray(model(mirrored[ok]))
        both = 0.5 * (plain + other)
        print(
            f"| {source} ({model.card.get('sha256', '')[:8]}) | {rmse_cm(plain - m_a):.2f} "
            f"| {rmse_cm(other - m_a):.2f} "
            f"| {rmse_cm(both - m_a):.2f} | {np.mean((plain >= 0) == (m_a >= 0)):.4f} | {rmse_cm(plain - other):.2f} |"
        )


if __name__ == "__main__":
    main()
