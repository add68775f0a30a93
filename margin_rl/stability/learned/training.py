"""Train the learned stability margin on an analytic-margin dataset (seed 000 §IV-A).

Command line::

    python -m margin_rl.stability.learned.training --data data/anymal_c --out margin_rl/stability/weights/anymal_c \\
        [--epochs 200 --batch-size 1024 --lr 1e-3 --patience 10 --seed 0 --logdir runs/margin]

Only samples whose analytic status is ``ok`` are used (the dataset loader counts and drops the rest).
``--mirror tied`` trains the same-size network with weights tied so that it is exactly invariant under
the left-right mirror of lambda, a symmetry of the analytic margin (``--mirror augment`` adds mirrored
copies of the training samples instead).
``--architecture physics`` trains the physics-informed model instead of the paper's network: the same
hidden layers on [lambda, physics features] (:mod:`margin_rl.stability.learned.features`: capture point, load-shifted
support polygon, friction terms), learning the residual over ``--proxy-weight`` x the analytic proxy
(``support_margin``); the features are computed once per sample in float64 before training.
The split is seeded (train / validation / test); the input normalisation and the output scaling are
fitted on the training split and stored with the weights. Adam on the mean squared error of the
normalised margin, learning rate halved on validation plateaus, early stopping on the validation
loss (the best epoch is kept). ``--init WEIGHTS`` continues saved weights (a robot name or an .npz with its
card) with their normalisation instead of a fresh network, e.g. a fit stopped by ``--max-seconds`` before its
learning rate had decayed; pass a lower ``--lr``. TensorBoard logs go to ``--logdir``. The model card records the
dataset and its generation command, the analytic settings, the package commit, this command and the
held-out test metrics:

* RMSE of m_l vs m_a overall and per band of |c_ddot_xy| and per number of contacts [cm];
* sign agreement (stable m >= 0 vs unstable), true positive and true negative rates;
* median cosine similarity between dm_l/dlambda and central finite differences of m_a;
* the paper's own protocol on fresh states (:mod:`margin_rl.stability.learned.evaluation`): sign rates within two
  standard deviations of the dataset, and the error along CoM-acceleration sweeps.
"""

from __future__ import annotations

import argparse
import dataclasses
import shlex
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from margin_rl.network import input_scaling
from margin_rl.provenance import git_commit
from margin_rl.robot import load_robot
from margin_rl.stability.analytic.lambda_state import LAMBDA_DIM, LAMBDA_SLICES
from margin_rl.stability.analytic.margin import AnalyticSettings
from margin_rl.stability.learned.dataset import TARGETS, Dataset, DatasetError, load_dataset
from margin_rl.stability.learned.evaluation import evaluate as evaluate_protocol
from margin_rl.stability.learned.evaluation import gradient_check, reliability
from margin_rl.stability.learned.features import PROXY_INDEX, PhysicsConstants, mirror_inputs, physics_inputs
from margin_rl.stability.learned.margin_mlp import MarginMLP
from margin_rl.stability.learned.mlp_weights import ARCHITECTURES, MarginWeights, architecture_widths
from margin_rl.stability.learned.model import ARCHITECTURE, LearnedMargin, save_weights

ACC_BANDS: tuple[tuple[float, float], ...] = ((0.0, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, np.inf))
"""Bands of |c_ddot_xy| [m/s^2] for the per-band error (the paper: < 1 cm for |c_ddot_x,y| <= 2)."""


@dataclass(frozen=True)
class TrainConfig:
    """Hyperparameters of the margin MLP training."""

    epochs: int = 200
    batch_size: int = 1024
    lr: float = 1e-3
    patience: int = 10  # epochs without validation improvement before stopping
    lr_patience: int = 3  # epochs without improvement before halving the learning rate ("plateau")
    schedule: str = "plateau"  # "plateau": halve on validation plateaus; "cosine": anneal lr -> min_lr per step
    min_lr: float = 1e-5  # end of the cosine schedule
    val_fraction: float = 0.05
    test_fraction: float = 0.05
    seed: int = 0
    max_samples: int | None = None
    grad_check_states: int = 200
    # The paper's protocol on fresh Table I states (margin_rl.stability.learned.evaluation): states labelled for the
    # two-sigma reliability (0 skips the whole protocol), and Table I base states for acceleration sweeps
    # beside the nominal stances (0: the nominal stances only).
    protocol_states: int = 25_000
    protocol_sweeps: int = 40
    # Left-right symmetry (the analytic margin of ANYmal B and C is invariant under mirror_lambda):
    # "none" trains the plain network on the data as it is; "augment" adds the mirror image of every
    # training sample (twice the data, the plain network); "tied" trains a network whose weights are tied
    # so that it is exactly mirror-invariant (margin_mlp module docstring; same size and saved format).
    mirror: str = "none"
    # "paper": the 47-256-128-128-1 network on raw lambda; "physics": the same hidden layers on [lambda,
    # physics features], output + proxy_weight x the analytic proxy (margin_rl.stability.learned.features).
    architecture: str = "paper"
    proxy_weight: float = 1.0  # physics only: the network learns m_a - proxy_weight * support_margin
    # What is learned (margin_rl.stability.learned.dataset.TARGETS): "analytic" m_a on ok states, or "extended" m_x
    # (margin_rl.stability.analytic.extended) on every state that has one, so that the reward has a slope there too.
    target: str = "analytic"
    device: str = "cpu"  # torch device of the fit ("cuda" on a GPU machine); the weights are saved the same
    max_seconds: float | None = None  # wall-time budget of the fit: no new epoch starts after it (None: no limit)
    # Continue from saved weights (a robot name or an .npz with its card) instead of a fresh network: their
    # normalisation is kept, so the fit goes on where a budget-bound fit stopped (use a lower lr than a fresh one).
    init: str | None = None


SCHEDULES = ("plateau", "cosine")
MIRROR_MODES = ("none", "augment", "tied")


def check_config(config: TrainConfig) -> TrainConfig:
    """Refuse hyperparameters that cannot train, naming the field."""
    if config.schedule not in SCHEDULES:
        raise ValueError(f"TrainConfig.schedule must be one of {SCHEDULES}, got {config.schedule!r}")
    if config.mirror not in MIRROR_MODES:
        raise ValueError(f"TrainConfig.mirror must be one of {MIRROR_MODES}, got {config.mirror!r}")
    if config.target not in TARGETS:
        raise ValueError(f"TrainConfig.target must be one of {TARGETS}, got {config.target!r}")
    if config.architecture not in ARCHITECTURES:
        raise ValueError(f"TrainConfig.architecture must be one of {ARCHITECTURES}, got {config.architecture!r}")
    if not np.isfinite(config.proxy_weight):
        raise ValueError(f"TrainConfig.proxy_weight must be finite, got {config.proxy_weight!r}")
    for name in ("epochs", "batch_size"):
        if getattr(config, name) < 1:
            raise ValueError(f"TrainConfig.{name} must be >= 1, got {getattr(config, name)}")
    for name in ("grad_check_states", "protocol_states", "protocol_sweeps"):
        if getattr(config, name) < 0:
            raise ValueError(f"TrainConfig.{name} must be >= 0, got {getattr(config, name)}")
    if config.max_seconds is not None and not config.max_seconds > 0:
        raise ValueError(f"TrainConfig.max_seconds must be > 0 or None, got {config.max_seconds!r}")
    if config.init is not None and config.architecture != "paper":
        raise ValueError(f"TrainConfig.init continues the paper network only, got architecture {config.architecture!r}")
    if not config.lr > 0 or not 0 <= config.min_lr <= config.lr:
        raise ValueError(f"need lr > 0 and 0 <= min_lr <= lr, got lr={config.lr}, min_lr={config.min_lr}")
    return config


@dataclass(frozen=True)
class Split:
    train: np.ndarray
    val: np.ndarray
    test: np.ndarray


def split_indices(n: int, config: TrainConfig) -> Split:
    """Seeded random split into train / validation / test indices."""
    perm = np.random.default_rng(config.seed).permutation(n)
    n_test = max(1, round(config.test_fraction * n))
    n_val = max(1, round(config.val_fraction * n))
    return Split(train=perm[n_test + n_val :], val=perm[n_test : n_test + n_val], test=perm[:n_test])


def with_mirror_images(lam: np.ndarray, margin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(2N, in), (2N,): the samples followed by their mirror images (same labels; new arrays).

    ``lam`` is lambda (N, 47) or the physics network's input [lambda, features] (N, 47 + N_FEATURES).
    """
    return np.concatenate([lam, mirror_inputs(lam)]), np.concatenate([margin, margin])


@dataclass(frozen=True)
class ModelInputs:
    """What the network sees for an architecture: its raw inputs and the offset its output is added to."""

    inputs: np.ndarray  # (N, 47) lambda, or (N, 47 + N_FEATURES) [lambda, features]
    offset: np.ndarray  # (N,) proxy_weight x proxy [m] (zeros for the paper network)


def model_inputs(lam: np.ndarray, config: TrainConfig, constants: PhysicsConstants | None = None) -> ModelInputs:
    """The network inputs and output offset of ``lam`` (N, 47) for ``config.architecture``."""
    if config.architecture == "paper":
        return ModelInputs(lam, np.zeros(len(lam)))
    if constants is None:
        raise ValueError("the physics architecture needs the robot's PhysicsConstants")
    inputs = physics_inputs(lam, constants)
    return ModelInputs(inputs, config.proxy_weight * inputs[:, LAMBDA_DIM + PROXY_INDEX])


def to_margin_weights(core: MarginMLP, config: TrainConfig, constants: PhysicsConstants | None = None) -> MarginWeights:
    """The trained network as saved weights: the core as is (paper), or with the physics constants."""
    weights = core.to_weights()
    if config.architecture == "paper":
        return weights
    assert constants is not None
    return dataclasses.replace(
        weights,
        lam_low=weights.lam_low[:LAMBDA_DIM],
        lam_high=weights.lam_high[:LAMBDA_DIM],
        architecture="physics",
        physics=constants.to_array(),
        proxy_weight=config.proxy_weight,
    )


def training_split(lam_train: np.ndarray, margin_train: np.ndarray, config: TrainConfig) -> tuple[np.ndarray, ...]:
    """The samples the optimiser sees: with their mirror images for ``mirror="augment"``, else as given.

    A tied network gives a sample and its mirror image the same loss, so ``"tied"`` needs no copies.
    ``lam_train`` may be [lambda, features] (the physics architecture).
    """
    if config.mirror == "augment":
        return with_mirror_images(lam_train, margin_train)
    return lam_train, margin_train


def build_model(
    lam_train: np.ndarray, margin_train: np.ndarray, mirror: str = "none", widths: tuple[int, ...] = ARCHITECTURE
) -> MarginMLP:
    """A fresh MLP whose normalisation is fitted on the training split (``widths``: see :class:`MarginMLP`).

    ``lam_train`` is the network's raw input: lambda, or [lambda, features] with
    ``widths=architecture_widths("physics")`` (:func:`model_inputs`).

    With ``mirror`` "augment" or "tied" the normalisation and the recorded input ranges are those of the
    split together with its mirror images, so they are mirror-symmetric (needed by the tied network, and
    the ranges then cover the mirrored states the network was trained for).
    """
    if mirror != "none":
        lam_train, margin_train = with_mirror_images(lam_train, margin_train)
    input_mean, input_std = input_scaling(lam_train)
    return MarginMLP(
        input_mean=input_mean,
        input_std=input_std,
        output_mean=float(margin_train.mean()),
        output_std=float(margin_train.std()),
        lam_low=lam_train.min(axis=0),
        lam_high=lam_train.max(axis=0),
        mirror_tied=mirror == "tied",
        widths=widths,
    )


def continued_model(
    source: str, robot: str, lam_train: np.ndarray, mirror: str = "none"
) -> tuple[MarginMLP, dict[str, object]]:
    """The trainable network of saved weights (``LearnedMargin.load(source)``) and its record for the card.

    The saved normalisation stays (it is part of the function being continued); the recorded input ranges
    grow to cover ``lam_train`` (with its mirror images unless ``mirror`` is "none"). Samples the saved network
    trained on may fall into the new validation and test splits: judge a continued network on held-out states.

    Raises:
        ValueError: weights of another robot, or not mirror-tied where ``mirror`` is "tied" (names both).
    """
    learned = LearnedMargin.load(source)
    if learned.card.get("robot") != robot:
        raise ValueError(f"--init {source} holds weights of {learned.card.get('robot')!r}, the data is of {robot!r}")
    model = MarginMLP.from_weights(learned.params, mirror_tied=mirror == "tied")
    if mirror != "none":  # the ranges of what the network is trained for, mirror images included
        lam_train = np.concatenate([lam_train, mirror_inputs(lam_train)])
    low = torch.as_tensor(lam_train.min(axis=0), dtype=model.lam_low.dtype)
    high = torch.as_tensor(lam_train.max(axis=0), dtype=model.lam_high.dtype)
    model.lam_low.copy_(torch.minimum(model.lam_low, low))
    model.lam_high.copy_(torch.maximum(model.lam_high, high))
    return model, {"source": str(source), "sha256": learned.card.get("sha256")}


def mean_squared_error(model: MarginMLP, lam: torch.Tensor, margin: torch.Tensor, batch: int = 65536) -> float:
    """Mean squared error [m^2] of the model on a split."""
    model.eval()
    total = 0.0
    with torch.no_grad():
        for i in range(0, len(lam), batch):
            total += float(((model(lam[i : i + batch]) - margin[i : i + batch]) ** 2).sum())
    return total / max(len(lam), 1)


def fit(
    model: MarginMLP,
    lam_train: np.ndarray,
    margin_train: np.ndarray,
    lam_val: np.ndarray,
    margin_val: np.ndarray,
    config: TrainConfig,
    logdir: str | Path | None = None,
    progress: bool = True,
) -> dict[str, object]:
    """Adam + learning-rate schedule + early stopping; the model ends with its best validation weights.

    ``schedule="plateau"`` halves the rate after ``lr_patience`` epochs without validation improvement;
    ``schedule="cosine"`` anneals it from ``lr`` to ``min_lr`` over all ``epochs`` (stepped per batch), for
    large-batch runs with a fixed budget. On the full ANYmal datasets the plateau schedule with batch 256
    generalised better than cosine with batch 1024 (BENCHMARKS.md, "Training recipe").
    """
    check_config(config)
    torch.manual_seed(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    device = torch.device(config.device)
    model.to(device)
    x = torch.as_tensor(lam_train, dtype=torch.float32, device=device)
    y = torch.as_tensor(margin_train, dtype=torch.float32, device=device)
    xv = torch.as_tensor(lam_val, dtype=torch.float32, device=device)
    yv = torch.as_tensor(margin_val, dtype=torch.float32, device=device)
    mean, std = model.input_mean, model.input_std
    x_norm = (x - mean) / std  # normalise once; the loss is on the normalised output
    y_norm = (y - model.output_scale[0]) / model.output_scale[1]
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    steps_per_epoch = -(-len(x_norm) // config.batch_size)
    if config.schedule == "cosine":
        scheduler = torch.optim.lr_scheduler.CosineAnnealingLR(
            optimizer, T_max=config.epochs * steps_per_epoch, eta_min=config.min_lr
        )
    else:
        scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(optimizer, factor=0.5, patience=config.lr_patience)
    writer = None
    if logdir is not None:
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(str(logdir))
    best, best_state, best_epoch, history = np.inf, None, -1, []
    stopped_by_budget = False
    t0 = time.perf_counter()
    for epoch in range(config.epochs):
        model.train()
        order = torch.randperm(len(x_norm), generator=generator).to(device)
        running = 0.0
        for i in range(0, len(order), config.batch_size):
            idx = order[i : i + config.batch_size]
            loss = torch.mean((model.normalized_forward(x_norm[idx]) - y_norm[idx]) ** 2)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            if config.schedule == "cosine":
                scheduler.step()
            running += float(loss.detach()) * len(idx)
        train_mse = running / len(order) * float(model.output_scale[1]) ** 2
        val_mse = mean_squared_error(model, xv, yv)
        if config.schedule == "plateau":
            scheduler.step(val_mse)
        lr = optimizer.param_groups[0]["lr"]
        history.append({"epoch": epoch, "train_rmse_cm": 100 * train_mse**0.5, "val_rmse_cm": 100 * val_mse**0.5})
        if writer is not None:
            writer.add_scalar("loss/train_mse", train_mse, epoch)
            writer.add_scalar("loss/val_mse", val_mse, epoch)
            writer.add_scalar("metrics/val_rmse_cm", 100 * val_mse**0.5, epoch)
            writer.add_scalar("optim/lr", lr, epoch)
        if progress:
            print(
                f"epoch {epoch:3d}  train rmse {100 * train_mse**0.5:.3f} cm  val rmse {100 * val_mse**0.5:.3f} cm"
                f"  lr {lr:.1e}  {time.perf_counter() - t0:.0f} s",
                file=sys.stderr,
                flush=True,
            )
        if val_mse < best:
            best, best_epoch = val_mse, epoch
            best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        elif epoch - best_epoch >= config.patience:
            break
        if config.max_seconds is not None and time.perf_counter() - t0 > config.max_seconds:
            stopped_by_budget = True
            break
    if best_state is not None:
        model.load_state_dict(best_state)
    model.to("cpu")
    if writer is not None:
        writer.close()
    return {
        "epochs_run": len(history),
        "best_epoch": best_epoch,
        "best_val_rmse_cm": 100 * float(best) ** 0.5,
        "last_train_rmse_cm": history[-1]["train_rmse_cm"] if history else float("nan"),  # last epoch, running mean
        "final_lr": float(optimizer.param_groups[0]["lr"]),
        "train_seconds": time.perf_counter() - t0,
        "stopped_by_time_budget": stopped_by_budget,
    }


def test_metrics(model: LearnedMargin, lam: np.ndarray, margin: np.ndarray) -> dict[str, object]:
    """Held-out metrics: RMSE overall, per |c_ddot_xy| band and per contact count; sign agreement."""
    pred = np.asarray(model(lam))
    err = pred - margin
    acc_xy = np.linalg.norm(lam[:, LAMBDA_SLICES["com_acc"]][:, :2], axis=1)
    n_contacts = lam[:, LAMBDA_SLICES["contacts"]].sum(axis=1).round().astype(int)
    signs = reliability(pred, margin)
    bands = {}
    for lo, hi in ACC_BANDS:
        sel = (acc_xy >= lo) & (acc_xy < hi)
        if sel.any():
            bands[f"{lo:g}-{hi:g}"] = {"n": int(sel.sum()), "rmse_cm": 100 * float(np.sqrt(np.mean(err[sel] ** 2)))}
    by_contacts = {
        str(k): {"n": int((n_contacts == k).sum()), "rmse_cm": 100 * float(np.sqrt(np.mean(err[n_contacts == k] ** 2)))}
        for k in (4, 3, 2)
        if (n_contacts == k).any()
    }
    return {
        "n": len(margin),
        "rmse_cm": 100 * float(np.sqrt(np.mean(err**2))),
        "mae_cm": 100 * float(np.mean(np.abs(err))),
        "rmse_cm_by_acc_xy_band": bands,
        "rmse_cm_by_contacts": by_contacts,
        "sign_agreement": signs.sign_agreement,
        "true_positive_rate": signs.true_positive_rate,
        "true_negative_rate": signs.true_negative_rate,
        "stable_fraction": signs.stable_fraction,
    }


def load_training_data(data: str | Path | Sequence[str | Path], config: TrainConfig) -> tuple[Dataset, list[dict]]:
    """One dataset directory, or several of the same robot and analytic settings concatenated (e.g. Table I
    mixed with rollout states); returns the merged :class:`Dataset` (the first one's manifest) and a
    record of each part for the model card. ``config.max_samples`` applies to each part.

    Raises:
        DatasetError: parts of different robots or analytic settings (names both).
    """
    paths = [data] if isinstance(data, (str, Path)) else list(data)
    if not paths:
        raise DatasetError("no dataset given: pass at least one --data directory")
    parts = [load_dataset(p, max_samples=config.max_samples, target=config.target) for p in paths]
    first = parts[0].manifest
    for path, part in zip(paths[1:], parts[1:], strict=True):
        # Labels of different settings measure different things; m_x also depends on its penalty and halvings.
        keys = ("robot", "analytic_settings") + (("extended_margin",) if config.target == "extended" else ())
        for key in keys:
            if part.manifest.get(key) != first.get(key):
                raise DatasetError(
                    f"{path} has {key} {part.manifest.get(key)!r}, {paths[0]} has {first.get(key)!r}: "
                    "only datasets of one robot and one set of label settings can be mixed"
                )
    record = [
        {
            "path": str(path),
            "distribution": part.manifest.get("distribution", "table_i"),
            "generation_command": part.manifest.get("command"),
            "samples_used": len(part.lam),
            "status_counts": part.counts,
        }
        for path, part in zip(paths, parts, strict=True)
    ]
    counts = {k: sum(p.counts.get(k, 0) for p in parts) for k in parts[0].counts}
    analytic = [p.analytic if p.analytic is not None else np.full(len(p.lam), np.nan) for p in parts]
    merged = Dataset(
        lam=np.concatenate([p.lam for p in parts]),
        margin=np.concatenate([p.margin for p in parts]),
        counts=counts,
        manifest=first,
        target=config.target,
        analytic=np.concatenate(analytic),
    )
    return merged, record


def train(
    data: str | Path | Sequence[str | Path],
    out: str | Path,
    config: TrainConfig,
    logdir: str | Path | None = None,
    command: str = "",
    progress: bool = True,
) -> dict[str, object]:
    """Train on ``data`` and write ``<out>.npz`` + ``<out>.json``; returns the model card."""
    check_config(config)
    ds, parts = load_training_data(data, config)
    lam, margin = ds.lam.astype(np.float64), ds.margin.astype(np.float64)
    split = split_indices(len(lam), config)
    manifest = ds.manifest
    robot = str(manifest["robot"])
    constants = PhysicsConstants.for_robot(load_robot(robot)) if config.architecture == "physics" else None
    data_in = model_inputs(lam, config, constants)
    x, target = data_in.inputs, margin - data_in.offset  # the network learns the residual over the offset
    torch.manual_seed(config.seed)  # the initial weights
    if config.init is None:
        widths = architecture_widths(config.architecture)
        model = build_model(x[split.train], target[split.train], config.mirror, widths)
        init_record = None
    else:
        model, init_record = continued_model(config.init, robot, x[split.train], config.mirror)
    x_fit, target_fit = training_split(x[split.train], target[split.train], config)
    summary = fit(model, x_fit, target_fit, x[split.val], target[split.val], config, logdir, progress)
    weights = to_margin_weights(model, config, constants)
    learned = LearnedMargin(weights)
    metrics = test_metrics(learned, lam[split.test], margin[split.test])
    if config.target == "extended":  # the same network judged on m_a where m_a exists (the paper's quantity)
        ok_test = split.test[np.isfinite(ds.analytic[split.test])]
        metrics["on_analytic"] = test_metrics(learned, lam[ok_test], ds.analytic[ok_test].astype(np.float64))
    settings_dict = dict(manifest["analytic_settings"])  # type: ignore[arg-type]
    settings = AnalyticSettings.from_dict(settings_dict)  # the labels' settings
    grad = {}
    if config.grad_check_states > 0:
        rng = np.random.default_rng(config.seed + 1)
        pick = rng.choice(split.test, size=min(config.grad_check_states, len(split.test)), replace=False)
        grad = gradient_check(learned, robot, lam[pick], settings)
    protocol = {}
    if config.protocol_states > 0:
        protocol, _ = evaluate_protocol(
            robot, learned, config.protocol_states, config.protocol_sweeps, settings=settings
        )
    card = {
        "robot": robot,
        "description": (
            "learned stability margin m_l(lambda) [m] of seed 000 §IV (47-256-128-128-1, softsign)"
            if config.architecture == "paper"
            else "physics-informed learned stability margin m_l(lambda) [m]: MLP (256-128-128-1, softsign) on "
            "[lambda, physics features] plus proxy_weight x the analytic proxy (margin_rl.stability.learned.features)"
        )
        + ("; weights tied to be exactly invariant under the left-right mirror" if config.mirror == "tied" else ""),
        "dataset": {
            "path": ", ".join(p["path"] for p in parts),
            "parts": parts,
            "samples_total": int(sum(ds.counts.values())),
            "status_counts": ds.counts,
            "samples_used": len(lam),
            "target": config.target,
            "distribution": "+".join(p["distribution"] for p in parts),
            "split": {"train": len(split.train), "val": len(split.val), "test": len(split.test)},
            "generation_command": manifest.get("command"),
            "sampler_version": manifest.get("sampler_version"),
            "seed": manifest.get("seed"),
            "package_version": manifest.get("package_version"),
        },
        "analytic_settings": settings_dict,
        "package_commit": git_commit(),
        "training_command": command,
        "training": {**config.__dict__, **summary},
        **({"continued_from": init_record} if init_record is not None else {}),
        "test_metrics": metrics,
        "gradient_check": grad,
        "paper_protocol": protocol,
        "robot_mass_kg": load_robot(robot).total_mass,
    }
    return save_weights(weights, out, card)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m margin_rl.stability.learned.training", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument(
        "--data",
        required=True,
        action="append",
        help="dataset directory (python -m margin_rl.stability.learned.dataset generate); repeat to mix datasets",
    )
    parser.add_argument("--out", required=True, help="output path without suffix: writes <out>.npz and <out>.json")
    defaults = TrainConfig()
    parser.add_argument("--epochs", type=int, default=defaults.epochs)
    parser.add_argument("--batch-size", type=int, default=defaults.batch_size)
    parser.add_argument("--lr", type=float, default=defaults.lr)
    parser.add_argument("--patience", type=int, default=defaults.patience)
    parser.add_argument("--schedule", choices=SCHEDULES, default=defaults.schedule, help="learning-rate schedule")
    parser.add_argument("--min-lr", type=float, default=defaults.min_lr, help="final rate of the cosine schedule")
    parser.add_argument(
        "--mirror",
        choices=MIRROR_MODES,
        default=defaults.mirror,
        help="left-right symmetry: none; augment (add mirrored copies); tied (exactly mirror-invariant network)",
    )
    parser.add_argument(
        "--architecture",
        choices=ARCHITECTURES,
        default=defaults.architecture,
        help="paper: 47-256-128-128-1 on raw lambda; physics: the same layers on [lambda, physics features] + proxy",
    )
    parser.add_argument(
        "--proxy-weight", type=float, default=defaults.proxy_weight, help="physics: output = net + w x proxy"
    )
    parser.add_argument(
        "--target", choices=TARGETS, default=defaults.target, help="analytic: m_a on ok states; extended: m_x on all"
    )
    parser.add_argument("--device", default=defaults.device, help="torch device of the fit, e.g. cuda")
    parser.add_argument("--max-seconds", type=float, default=None, help="wall-time budget of the fit [s]")
    parser.add_argument(
        "--init",
        default=None,
        metavar="WEIGHTS",
        help="continue from saved weights (robot name or .npz with its card) instead of a fresh network",
    )
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--max-samples", type=int, default=None)
    parser.add_argument("--grad-check-states", type=int, default=defaults.grad_check_states)
    parser.add_argument(
        "--protocol-states", type=int, default=defaults.protocol_states, help="fresh states for the paper's protocol"
    )
    parser.add_argument("--protocol-sweeps", type=int, default=defaults.protocol_sweeps)
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    parser.add_argument("--logdir", default=None, help="TensorBoard directory")
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    config = TrainConfig(
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        patience=args.patience,
        schedule=args.schedule,
        min_lr=args.min_lr,
        seed=args.seed,
        max_samples=args.max_samples,
        grad_check_states=args.grad_check_states,
        protocol_states=args.protocol_states,
        protocol_sweeps=args.protocol_sweeps,
        mirror=args.mirror,
        architecture=args.architecture,
        proxy_weight=args.proxy_weight,
        target=args.target,
        device=args.device,
        max_seconds=args.max_seconds,
        init=args.init,
    )
    arguments = " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]))
    command = f"python -m margin_rl.stability.learned.training {arguments}"
    card = train(args.data, args.out, config, args.logdir, command, progress=not args.quiet)
    m = card["test_metrics"]
    print(
        f"test RMSE {m['rmse_cm']:.3f} cm, sign agreement {m['sign_agreement']:.3%}, "
        f"gradient cosine median {card['gradient_check'].get('median_cosine', float('nan')):.3f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
