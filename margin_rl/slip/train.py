r"""Train :math:`P(s, a)` and :math:`M(s, a)` on a generated data set (paper §III, §V-A).

* :math:`P` is fitted on valid samples only, minimising the weighted squared prediction error
  :math:`e^\top Q e` with :math:`Q = \mathrm{diag}(0.250, 6.25, 0.250)` on
  :math:`e = P(z) - [\Delta x, y_1, \dot x_1]`.
* :math:`M` is fitted on all samples, minimising the squared error to the k-d-tree oriented
  distance :math:`b` (eq. 5).

Both use Adam with learning rate :math:`10^{-3}` and mini-batches.  Metrics are computed on a
held-out split by the exported networks, folded from the float32 arrays written to the files (so the
export itself is tested).  Fig. 4 is
reproduced as the *valid-label precision* :math:`|\{M > \varepsilon\} \cap V| / |\{M > \varepsilon\}|`
and the *recall of valid points* :math:`|\{M > \varepsilon\} \cap V| / |V|` against the
threshold :math:`\varepsilon`.

CLI::

    python -m margin_rl.slip.train --data DIR --out margin_rl/slip/weights --iters 20000
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from margin_rl.network import DenseNetwork, torch_sequential
from margin_rl.slip.dataset import SlipDataset, load_dataset
from margin_rl.slip.margin import PREDICTION_WEIGHTS
from margin_rl.slip.models import (
    ACTIVATION,
    BUNDLE_DIR,
    box_normalisation,
    network_arrays,
    network_from_arrays,
    save_bundle,
)

__all__ = [
    "PAPER_OPERATING_POINT",
    "TorchMLP",
    "TrainConfig",
    "fit",
    "main",
    "margin_metrics",
    "plot_threshold_curve",
    "return_map_metrics",
    "threshold_curve",
]

FloatArray = NDArray[np.float64]

#: Paper §V-A: at epsilon = 0.05, 97 % of valid-labelled points are valid and 59 % of all
#: valid points are labelled valid.
PAPER_OPERATING_POINT = {"epsilon": 0.05, "precision": 0.97, "recall": 0.59}


class TorchMLP(nn.Module):
    """The trainable network: ``out_offset + out_scale * body((z - in_offset) / in_scale)`` with ``body``
    the layers of :func:`margin_rl.network.torch_sequential` (2 x 64 ReLU by default), in normalised units."""

    def __init__(
        self,
        in_offset: FloatArray,
        in_scale: FloatArray,
        out_offset: FloatArray,
        out_scale: FloatArray,
        hidden: int = 64,
    ) -> None:
        super().__init__()
        n_in, n_out = int(np.size(in_offset)), int(np.size(out_offset))
        self.body = torch_sequential((n_in, hidden, hidden, n_out), ACTIVATION)
        for name, value in (
            ("in_offset", in_offset),
            ("in_scale", in_scale),
            ("out_offset", out_offset),
            ("out_scale", out_scale),
        ):
            self.register_buffer(name, torch.as_tensor(np.asarray(value), dtype=torch.float32))

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return self.out_offset + self.out_scale * self.body((z - self.in_offset) / self.in_scale)

    def export(self) -> dict[str, NDArray[np.float32]]:
        """The weights as the file content of :func:`margin_rl.slip.models.network_arrays` (float32, as trained)."""
        lin = [m for m in self.body if isinstance(m, nn.Linear)]

        def arr(t: torch.Tensor) -> NDArray[np.float32]:
            return t.detach().cpu().numpy().astype(np.float32)

        return network_arrays(
            tuple(arr(layer.weight) for layer in lin),
            tuple(arr(layer.bias) for layer in lin),
            arr(self.in_offset),
            arr(self.in_scale),
            arr(self.out_offset),
            arr(self.out_scale),
        )


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation settings shared by both networks."""

    iters: int = 20_000
    batch_size: int = 1024
    lr: float = 1e-3
    seed: int = 0
    hidden: int = 64

    def __post_init__(self) -> None:
        if self.iters < 1:
            raise ValueError(f"iters must be >= 1; got {self.iters}")
        if self.batch_size < 1:
            raise ValueError(f"batch_size must be >= 1; got {self.batch_size}")
        if not self.lr > 0:
            raise ValueError(f"lr must be positive; got {self.lr}")


def fit(
    z: FloatArray, target: FloatArray, weights: FloatArray, config: TrainConfig
) -> tuple[dict[str, NDArray[np.float32]], list[float]]:
    """Fit a :class:`TorchMLP` by Adam on the loss :math:`\\mathrm{mean}_i \\sum_j w_j e_{ij}^2`.

    Returns the exported network (its file content, :meth:`TorchMLP.export`; evaluate it with
    :func:`~margin_rl.slip.models.network_from_arrays`) and the loss history (one value per 100 iterations).
    """
    if z.ndim != 2 or target.ndim != 2 or z.shape[0] != target.shape[0]:
        raise ValueError(f"z {z.shape} and target {target.shape} must be (n, d) with equal n")
    if weights.shape != (target.shape[1],):
        raise ValueError(f"weights must have shape ({target.shape[1]},); got {weights.shape}")
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    in_off, in_scale = box_normalisation()
    net = TorchMLP(in_off, in_scale, target.mean(axis=0), target.std(axis=0) + 1e-12, config.hidden)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    zt = torch.as_tensor(z, dtype=torch.float32)
    tt = torch.as_tensor(target, dtype=torch.float32)
    wt = torch.as_tensor(weights, dtype=torch.float32)
    history: list[float] = []
    running = 0.0
    for it in range(config.iters):
        idx = torch.randint(0, zt.shape[0], (config.batch_size,), generator=gen)
        err = net(zt[idx]) - tt[idx]
        loss = (err * err * wt).sum(dim=1).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        running += float(loss.detach())
        if (it + 1) % 100 == 0:
            history.append(running / 100)
            running = 0.0
    return net.export(), history


# ---------------------------------------------------------------------------- metrics


def return_map_metrics(net: DenseNetwork, z: FloatArray, next_apex: FloatArray) -> dict[str, Any]:
    """Held-out accuracy of :math:`P` on valid samples."""
    err = net(z) - next_apex
    weighted = np.sum(PREDICTION_WEIGHTS * err * err, axis=1)
    var = np.var(next_apex, axis=0)
    return {
        "n": int(z.shape[0]),
        "weighted_mse": float(weighted.mean()),
        "rmse": dict(zip(("dx", "y", "xdot"), np.sqrt(np.mean(err * err, axis=0)).tolist(), strict=True)),
        "r2": dict(zip(("dx", "y", "xdot"), (1 - np.mean(err * err, axis=0) / var).tolist(), strict=True)),
    }


def threshold_curve(pred: FloatArray, valid: NDArray[np.bool_], eps: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Valid-label precision and recall of valid points for each threshold in ``eps``."""
    labelled = pred[None, :] > eps[:, None]
    n_lab = labelled.sum(axis=1)
    hits = (labelled & valid[None, :]).sum(axis=1)
    precision = np.where(n_lab > 0, hits / np.maximum(n_lab, 1), np.nan)
    recall = hits / max(int(valid.sum()), 1)
    return precision, recall


def margin_metrics(net: DenseNetwork, z: FloatArray, margin: FloatArray, valid: NDArray[np.bool_]) -> dict[str, Any]:
    """Held-out accuracy of :math:`M`: regression error and valid/invalid classification."""
    pred = net(z)[:, 0]
    prec, rec = threshold_curve(pred, valid, np.array([0.0, PAPER_OPERATING_POINT["epsilon"]]))
    return {
        "n": int(z.shape[0]),
        "valid_fraction": float(valid.mean()),
        "rmse": float(np.sqrt(np.mean((pred - margin) ** 2))),
        "sign_accuracy": float(np.mean((pred > 0) == valid)),
        "eps_0": {"precision": float(prec[0]), "recall": float(rec[0])},
        "eps_0.05": {"precision": float(prec[1]), "recall": float(rec[1])},
    }


def plot_threshold_curve(pred: FloatArray, valid: NDArray[np.bool_], path: Path) -> None:
    """Fig. 4: precision/recall against epsilon, with the paper's and our operating points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    eps = np.linspace(-0.05, 0.15, 201)
    prec, rec = threshold_curve(pred, valid, eps)
    e0 = PAPER_OPERATING_POINT["epsilon"]
    p0, r0 = threshold_curve(pred, valid, np.array([e0]))
    fig, ax = plt.subplots(figsize=(6.0, 4.0), dpi=110)
    ax.plot(eps, 100 * prec, label="valid-label accuracy (precision)", color="tab:blue")
    ax.plot(eps, 100 * rec, label="valid points included (recall)", color="tab:orange")
    ax.plot(
        [e0],
        [100 * PAPER_OPERATING_POINT["precision"]],
        "s",
        color="tab:blue",
        mfc="none",
        ms=9,
        label=f"paper, eps={e0}: {100 * PAPER_OPERATING_POINT['precision']:.0f}% / "
        f"{100 * PAPER_OPERATING_POINT['recall']:.0f}%",
    )
    ax.plot([e0], [100 * PAPER_OPERATING_POINT["recall"]], "s", color="tab:orange", mfc="none", ms=9)
    ax.plot(
        [e0, e0],
        [100 * p0[0], 100 * r0[0]],
        "o",
        color="k",
        label=f"ours, eps={e0}: {100 * p0[0]:.1f}% / {100 * r0[0]:.1f}%",
    )
    ax.axvline(e0, color="0.7", lw=0.8, ls="--")
    ax.set_xlabel(r"threshold $\varepsilon$ on $M(s, a)$")
    ax.set_ylabel("percent")
    ax.set_ylim(0, 102)
    ax.set_title("Failure-margin classification vs threshold (cf. paper Fig. 4)")
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# ---------------------------------------------------------------------------- driver


def _split(n: int, test_fraction: float, seed: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    perm = np.random.default_rng(seed).permutation(n)
    n_test = round(test_fraction * n)
    return perm[n_test:], perm[:n_test]


def train_bundle(
    data: SlipDataset,
    out: Path,
    config: TrainConfig,
    *,
    test_fraction: float = 0.1,
    figure: Path | None = None,
    extra_card: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Train both networks, write ``return_map.npz``, ``margin.npz`` and ``card.json`` to ``out``."""
    if data.margin is None:
        raise ValueError("the data set has no margins; run the dataset CLI without --no-margin")
    if not 0 < test_fraction < 1:
        raise ValueError(f"test_fraction must be in (0, 1); got {test_fraction}")
    train_idx, test_idx = _split(len(data), test_fraction, config.seed)
    valid = data.valid
    t0 = time.perf_counter()
    tr_v = train_idx[valid[train_idx]]
    p_arrays, p_hist = fit(data.z[tr_v], data.next_apex[tr_v], PREDICTION_WEIGHTS, config)
    t_p = time.perf_counter() - t0
    m_arrays, m_hist = fit(data.z[train_idx], data.margin[train_idx, None], np.ones(1), config)
    t_m = time.perf_counter() - t0 - t_p
    p_net, m_net = network_from_arrays(p_arrays), network_from_arrays(m_arrays)

    te_v = test_idx[valid[test_idx]]
    metrics = {
        "return_map": return_map_metrics(p_net, data.z[te_v], data.next_apex[te_v]),
        "margin": margin_metrics(m_net, data.z[test_idx], data.margin[test_idx], valid[test_idx]),
        "final_train_loss": {"return_map": p_hist[-1] if p_hist else None, "margin": m_hist[-1] if m_hist else None},
    }
    if figure is not None:
        plot_threshold_curve(m_net(data.z[test_idx])[:, 0], valid[test_idx], figure)
    card: dict[str, Any] = {
        "model": "aSLIP return map P(s,a) and failure margin M(s,a): MLP 4-64-64-{3,1}, ReLU",
        "command": " ".join(["python -m margin_rl.slip.train", *sys.argv[1:]]),
        "dataset": {
            "n_samples": len(data),
            "n_valid": int(valid.sum()),
            "n_train": int(train_idx.size),
            "n_test": int(test_idx.size),
            "n_train_valid": int(tr_v.size),
            "n_test_valid": int(te_v.size),
            **(extra_card or {}),
        },
        "training": {
            "optimizer": "Adam",
            "lr": config.lr,
            "iters_per_network": config.iters,
            "batch_size": config.batch_size,
            "seed": config.seed,
            "hidden": [config.hidden, config.hidden],
            "loss_return_map": "mean e^T diag(0.25, 6.25, 0.25) e on [dx, y1, xdot1]",
            "loss_margin": "mean squared error to the k-d-tree oriented distance",
            "seconds": {"return_map": round(t_p, 1), "margin": round(t_m, 1)},
            "torch": torch.__version__,
            "python": platform.python_version(),
        },
        "metrics_test": metrics,
        "paper": {"fig4_operating_point": PAPER_OPERATING_POINT},
    }
    return save_bundle(out, {"return_map": p_arrays, "margin": m_arrays}, card)


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python -m margin_rl.slip.train", description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="data set directory (margin_rl.slip.dataset)")
    ap.add_argument("--out", type=Path, default=BUNDLE_DIR, help="where to write the weights and card")
    ap.add_argument("--iters", type=int, default=20_000, help="Adam iterations per network")
    ap.add_argument("--batch-size", type=int, default=1024)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--test-fraction", type=float, default=0.1)
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads (1 is fastest for 2x64 nets)")
    ap.add_argument("--figure", type=Path, default=None, help="PNG path for the Fig. 4 curve")
    return ap.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = _parse(argv)
    torch.set_num_threads(max(1, args.threads))
    data = load_dataset(args.data)
    manifest = json.loads((args.data / "manifest.json").read_text())
    config = TrainConfig(iters=args.iters, batch_size=args.batch_size, lr=args.lr, seed=args.seed)
    ident = manifest["identity"]
    regenerate = (
        f"python -m margin_rl.slip.dataset --out {args.data} --n {manifest['n']} "
        f"--shard-size {ident['shard_size']} --seed {ident['seed']} --dt {ident['dt']}"
    )
    card = train_bundle(
        data,
        args.out,
        config,
        test_fraction=args.test_fraction,
        figure=args.figure,
        extra_card={"generator": manifest, "generator_command": regenerate},
    )
    print(json.dumps(card["metrics_test"], indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
