"""Train the selected models on a run's dataset and write every training artifact.

Writes into the run folder: ``<kind>.pt`` checkpoints, ``predictions_<kind>.npz`` (test split),
``metrics.json`` ({"cnode", "gru", "baseline"}), ``history.json`` and the figures.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
import torch

from core.config import Config, replace_section
from core.contracts import SPLITS
from core.errors import QuadfdiError
from core.jsonio import read_json, write_json
from core.npzio import write_npz
from core.rundir import RunDir
from sim.dataset import Dataset, Windows, load_dataset
from train.baseline import fit_baseline, predict_proba_baseline
from train.checkpoint import save_checkpoint
from train.data import class_weights, fit_normalisation, split_windows
from train.loop import predict_proba, train_model
from train.metrics import compute_metrics
from train.models import build_model


def kinds_of(model: str) -> list[str]:
    return ["cnode", "gru"] if model == "both" else [model]


def evaluate(ds: Dataset, test: Windows, proba: np.ndarray) -> dict:
    return compute_metrics(test.y, proba, test.traj, test.t_end, ds["fault_class"], ds["detectable_s"])


def train_all(ds: Dataset, cfg: Config, kinds: list[str], log: Callable[[str], None] = print) -> dict:
    """Train ``kinds`` and the baseline on ``ds``; return models, histories, probabilities, metrics."""
    torch.set_num_threads(cfg.train.threads)
    splits = split_windows(ds)
    for name in SPLITS:
        if len(getattr(splits, name)) == 0:
            raise QuadfdiError(f"the dataset has no {name} windows: raise sim.n_traj or sim.duration_s")
    mean, std = fit_normalisation(ds)
    weights = class_weights(splits.train.y)
    out: dict = {"models": {}, "history": {}, "proba": {}, "metrics": {}, "splits": splits}
    for kind in kinds:
        torch.manual_seed(cfg.train.seed)  # same initial weights for the same seed
        model = build_model(kind, ds.n_channels, cfg.train, window=cfg.sim.window)
        model.set_normalisation(mean, std)
        log(f"train {kind} (seed {cfg.train.seed}, {sum(p.numel() for p in model.parameters())} parameters):")
        t0 = time.perf_counter()
        hist = train_model(model, splits.train, splits.validation, cfg.train, weights, log)
        log(f"  {kind}: trained in {time.perf_counter() - t0:.1f} s (best epoch {hist.best_epoch + 1})")
        proba = predict_proba(model, splits.test.x)
        out["models"][kind], out["history"][kind], out["proba"][kind] = model, hist, proba
        out["metrics"][kind] = evaluate(ds, splits.test, proba)
    base = fit_baseline(splits.train.x, splits.train.y, cfg.train.seed)
    out["proba"]["baseline"] = predict_proba_baseline(base, splits.test.x)
    out["metrics"]["baseline"] = evaluate(ds, splits.test, out["proba"]["baseline"])
    return out


def write_outputs(run: RunDir, ds: Dataset, cfg: Config, result: dict) -> None:
    """Checkpoints, predictions, metrics.json (merged with models not retrained), history, figures."""
    from train.figures import draw_all

    test = result["splits"].test
    for kind, model in result["models"].items():
        save_checkpoint(run.checkpoint(kind), model, cfg.to_dict(), ds.channel_names,
                        extra={"history": result["history"][kind].to_dict(times=False)})
        write_npz(run.predictions(kind), {"y_true": test.y, "proba": result["proba"][kind],
                                          "traj": test.traj, "t_end": test.t_end})
    metrics = read_json(run.metrics, "metrics") if run.metrics.is_file() else {}
    metrics.update(result["metrics"])
    write_json(run.metrics, metrics, indent=2)
    hist_path = run.root / "history.json"
    hist = read_json(hist_path, "training history") if hist_path.is_file() else {}
    hist.update({k: h.to_dict() for k, h in result["history"].items()})
    write_json(hist_path, hist, indent=2)
    draw_all(run, ds, result)


def train_run(run: RunDir, cfg: Config, model: str = "both", seed: int | None = None,
              log: Callable[[str], None] = print) -> dict:
    if seed is not None:
        cfg = replace_section(cfg, "train", seed=seed)
    ds = load_dataset(run.dataset)
    result = train_all(ds, cfg, kinds_of(model), log)
    write_outputs(run, ds, cfg, result)
    return result
