"""Paper network vs physics-informed model on the same labelled data, same split, same training budget.

    .venv/bin/python benchmarks/studies/bench_margin_architecture.py --data data/v2_anymal_c_300k --epochs 20 \\
        --train-subset 75000 --train-subset 0 --recipe paper --recipe physics --recipe physics:0

Every run uses one seeded train / validation / test split of the whole dataset (``training.split_indices``),
so the test states are the same for every row; ``--train-subset n`` trains on the first n samples of the
training split (0: all of it), for a learning-curve point. A recipe is ``paper``, ``physics[:w]`` (``w``
the proxy weight, default 1: the network learns the residual over the analytic proxy; 0: the features are
inputs only) or ``support[:K]`` (the support-function model of ``support_mlp`` with K fixed directions, default
32, trained on mirror-augmented data since it is not tied) or ``shifted[:K]`` (the same with the load-shifted
polygon as its prior). ``--mirror`` is shared by the other rows (default ``tied``, the bundled ANYmal C
recipe). Reported per row: test RMSE, sign agreement (TPR / TNR), RMSE per number
of contacts, the best validation RMSE and its epoch, the training time, with ``--walking`` the RMSE and sign
agreement on labelled walking states, and (last rows) the analytic proxy alone and its best affine rescaling;
``--reference`` adds shipped weights judged on the same test and walking states.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np
import torch

from margin_rl.robot import load_robot
from margin_rl.stability.learned.evaluation import reliability
from margin_rl.stability.learned.features import PROXY_INDEX, PhysicsConstants, physics_features
from margin_rl.stability.learned.mlp_weights import architecture_widths
from margin_rl.stability.learned.model import LearnedMargin
from margin_rl.stability.learned.support_mlp import DEFAULT_DIRECTIONS, build_support_model
from margin_rl.stability.learned.training import (
    TrainConfig,
    build_model,
    fit,
    load_training_data,
    model_inputs,
    split_indices,
    test_metrics,
    to_margin_weights,
    training_split,
    with_mirror_images,
)


def parse_recipe(text: str) -> tuple[str, float]:
    """``paper``, ``physics[:w]`` (w: the proxy weight, default 1), ``support[:K]`` or ``shifted[:K]`` (K fixed
    directions; the support model with the polygon prior, or with the load-shifted polygon)."""
    name, _, value = text.partition(":")
    if name not in ("paper", "physics", "support", "shifted"):
        raise argparse.ArgumentTypeError(f"recipe must be paper, physics[:w], support[:K] or shifted[:K], got {text!r}")
    if name in ("support", "shifted"):
        return name, float(value) if value else float(DEFAULT_DIRECTIONS)
    return name, float(value) if value else 1.0


class TorchMargin:
    """A torch margin model called like :class:`LearnedMargin` on a batch (N, 47) -> (N,) numpy, for test_metrics."""

    def __init__(self, module: torch.nn.Module) -> None:
        self.module = module.eval()

    def __call__(self, lam: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return self.module(torch.as_tensor(lam, dtype=torch.float32)).double().numpy()


def fit_support(
    lam: np.ndarray, margin: np.ndarray, split, train: np.ndarray, directions: int, prior: str, config, constants
) -> tuple[TorchMargin, dict]:
    """The support-function model (margin_rl.stability.learned.support_mlp) on raw lambda, mirror-augmented."""
    torch.manual_seed(config.seed)
    lam_fit, margin_fit = with_mirror_images(lam[train], margin[train])
    model = build_support_model(
        lam_fit, margin_fit, constants.foot_radius, constants.gravity, directions, prior, constants.mass
    )
    summary = fit(model, lam_fit, margin_fit, lam[split.val], margin[split.val], config, progress=False)
    return TorchMargin(model), summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, action="append", help="dataset directory; repeat to mix datasets")
    parser.add_argument("--recipe", type=parse_recipe, action="append", required=True)
    parser.add_argument("--train-subset", type=int, action="append", default=None, help="0: the whole train split")
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--mirror", default="tied")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-samples", type=int, default=None, help="read only the first N ok samples")
    parser.add_argument(
        "--walking",
        default=None,
        help="labelled walking states (npz: lam, margin, status; bench_margin_rollout_holdout's label cache): "
        "every model is also judged on their ok states",
    )
    parser.add_argument(
        "--table-i",
        default=None,
        help="labelled fresh Table I states (the same format): every model is also judged on their ok states",
    )
    parser.add_argument(
        "--reference", action="append", default=[], help="shipped weights judged on the same states (e.g. anymal_c)"
    )
    parser.add_argument("--out", default=None, help="write the rows as JSON here")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    ds, _ = load_training_data(args.data, TrainConfig(max_samples=args.max_samples))  # m_a on the ok samples
    lam, margin = ds.lam.astype(np.float64), ds.margin.astype(np.float64)
    robot = str(ds.manifest["robot"])
    constants = PhysicsConstants.for_robot(load_robot(robot))
    base = TrainConfig(
        epochs=args.epochs, batch_size=args.batch_size, lr=args.lr, patience=args.epochs, mirror=args.mirror,
        seed=args.seed, grad_check_states=0, protocol_states=0,
    )  # fmt: skip
    split = split_indices(len(lam), base)
    print(
        f"{' + '.join(args.data)}: {len(lam)} ok samples of {robot}; "
        f"split {len(split.train)} / {len(split.val)} / {len(split.test)}"
    )
    held_out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, path in (("walking", args.walking), ("table_i", args.table_i)):
        if path:
            with np.load(path) as z:
                ok = z["status"] == 0
                held_out[name] = z["lam"][ok].astype(np.float64), z["margin"][ok].astype(np.float64)
            print(f"{path}: {len(held_out[name][0])} {name} states with an analytic margin")

    def held_out_scores(model) -> dict[str, float]:
        scores = {}
        for name, (states, truth) in held_out.items():
            pred = np.asarray(model(states))
            scores[f"{name}_rmse_cm"] = 100 * float(np.sqrt(np.mean((pred - truth) ** 2)))
            scores[f"{name}_sign_agreement"] = reliability(pred, truth).sign_agreement
        return scores

    rows = []
    for name in args.reference:
        reference = LearnedMargin.load(name)
        metrics = test_metrics(reference, lam[split.test], margin[split.test])
        row = {
            "recipe": f"shipped {name}",
            "test_rmse_cm": metrics["rmse_cm"],
            "sign_agreement": metrics["sign_agreement"],
            **held_out_scores(reference),
        }
        rows.append(row)
        print(json.dumps(row), flush=True)
    for subset in args.train_subset or [0]:
        train = split.train if subset <= 0 else split.train[:subset]
        for architecture, value in args.recipe:
            t0 = time.perf_counter()
            if architecture in ("support", "shifted"):
                prior = "polygon" if architecture == "support" else "shifted"
                learned, summary = fit_support(lam, margin, split, train, int(value), prior, base, constants)
                recipe = f"{architecture}:{int(value)}"
            else:
                config = dataclasses.replace(base, architecture=architecture, proxy_weight=value)
                data_in = model_inputs(lam, config, constants)
                x, target = data_in.inputs, margin - data_in.offset
                torch.manual_seed(config.seed)
                model = build_model(x[train], target[train], config.mirror, architecture_widths(architecture))
                x_fit, target_fit = training_split(x[train], target[train], config)
                summary = fit(model, x_fit, target_fit, x[split.val], target[split.val], config, progress=False)
                learned = LearnedMargin(to_margin_weights(model, config, constants))
                recipe = architecture if architecture == "paper" else f"physics:{value:g}"
            seconds = time.perf_counter() - t0
            metrics = test_metrics(learned, lam[split.test], margin[split.test])
            row = {
                "recipe": recipe,
                "train_samples": len(train),
                "test_rmse_cm": metrics["rmse_cm"],
                "sign_agreement": metrics["sign_agreement"],
                "tpr": metrics["true_positive_rate"],
                "tnr": metrics["true_negative_rate"],
                "rmse_cm_by_contacts": {k: v["rmse_cm"] for k, v in metrics["rmse_cm_by_contacts"].items()},
                "best_val_rmse_cm": summary["best_val_rmse_cm"],
                "best_epoch": summary["best_epoch"],
                "last_train_rmse_cm": summary["last_train_rmse_cm"],
                "train_seconds": seconds,
                "epochs_run": summary["epochs_run"],
                **held_out_scores(learned),
            }
            rows.append(row)
            print(json.dumps(row), flush=True)

    proxy = physics_features(lam[split.test], constants)[:, PROXY_INDEX]
    truth = margin[split.test]
    fit_train = physics_features(lam[split.train], constants)[:, PROXY_INDEX]
    a, b = np.polyfit(fit_train, margin[split.train], 1)  # affine rescaling fitted on the training split
    for name, pred in (("proxy alone", proxy), (f"proxy, affine {a:.3f} p + {b:.3f}", a * proxy + b)):
        signs = reliability(pred, truth)
        row = {
            "recipe": name,
            "test_rmse_cm": 100 * float(np.sqrt(np.mean((pred - truth) ** 2))),
            "sign_agreement": signs.sign_agreement,
            "tpr": signs.true_positive_rate,
            "tnr": signs.true_negative_rate,
        }
        rows.append(row)
        print(json.dumps(row), flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
