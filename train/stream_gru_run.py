"""``quadfdi train sgru``: train the streaming GRU on a run's dataset and publish it beside the
windowed networks.

Writes into the run folder:
- ``sgru_train<T>.pt``: the checkpoint (plain dict, ``torch.load(weights_only=True)``): ``architecture``
  (``models.stream_gru.stream_signature``), ``state_dict``, ``config`` (the [sgru] section), ``class_names``,
  ``channel_names``, ``history``;
- ``predictions/sgru_sim<S>_train<T>.npz``: a prediction set (formats/predictions.py) holding the stream's
  class probabilities at the end sample of every evaluation window, the stream started at h = 0 at
  take-off and stepped once per sample (so ``quadfdi evaluate`` scores it like the windowed models),
  and its index entry;
- ``predictions/sgru_sim<S>_train<T>.json``: settings, history and the compute per second of flight
  of the streaming GRU, the windowed GRU and the CNODE (``compute_rows``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from quadfdi.core.atomic import atomic_path
from quadfdi.core.config import Config
from quadfdi.core.jsonio import write_json
from quadfdi.formats.predictions import add_entries, prediction_path
from quadfdi.formats.dataset import Dataset, class_names, load_dataset
from quadfdi.train.data import evaluation_rows
from quadfdi.models.networks import build_model
from quadfdi.train.predsets import index_entry, write_prediction_set
from quadfdi.models.stream_gru import StreamGRU, stream_from_signature, stream_signature
from quadfdi.train.config import StreamFitConfig
from quadfdi.train.stream_gru_fit import (
    config_dict,
    fit_stream_gru,
    step_labels,
    stream_logits,
    window_end_index,
)

MODEL = "sgru"


def stream_prediction_set(model: StreamGRU, ds: Dataset, flights_per_chunk: int = 64) -> dict[str, np.ndarray]:
    """The stream's probabilities at every evaluation window end, in ``train.predsets`` order
    (flight by flight in dataset order, windows in time order)."""
    rows = evaluation_rows(ds)
    ends = window_end_index(ds)
    probas = []
    for i in range(0, len(rows), flights_per_chunk):
        part = rows[i:i + flights_per_chunk]
        logits = torch.from_numpy(stream_logits(model, ds["telemetry"][part])[:, ends]).double()
        probas.append(torch.softmax(logits, dim=-1).numpy().reshape(-1, model.n_classes))
    n_w = len(ends)
    return {"proba": np.concatenate(probas).astype(np.float32),
            "y_true": step_labels(ds, rows)[:, ends].reshape(-1).astype(np.int64),
            "traj": np.repeat(rows, n_w).astype(np.int64),
            "t_end": np.tile(np.asarray(ds["time"])[ends], len(rows)).astype(np.float64),
            "split": np.repeat(np.asarray(ds["split"])[rows], n_w).astype(np.int8),
            "class_names": np.array(class_names(ds.arrays))}


def compute_rows(cfg: Config, model: StreamGRU) -> list[dict[str, Any]]:
    """Multiply-accumulates per decision and per second of flight: the stream decides at every
    sample (one GRU step + head), the windowed models at every stride (a full window each)."""
    rate = 1.0 / cfg.sim.sample_dt_s
    per_s_stride = rate / cfg.sim.stride
    c, k, w = model.n_channels, model.n_classes, cfg.sim.window
    gru = build_model("gru", c, cfg.train, window=w, n_classes=k)
    cnode = build_model("cnode", c, cfg.train, window=w, n_classes=k)
    rows = [{"model": MODEL, "decisions_per_s": rate, "macs_per_decision": model.macs_per_step(),
             "macs_per_s": model.macs_per_step() * rate},
            {"model": "gru", "decisions_per_s": per_s_stride, "macs_per_decision": gru.macs_per_window(),
             "macs_per_s": gru.macs_per_window() * per_s_stride},
            {"model": "cnode", "decisions_per_s": per_s_stride, "macs_per_decision": cnode.macs_per_window(),
             "macs_per_s": cnode.macs_per_window() * per_s_stride}]
    for r in rows:
        r["ratio_to_gru"] = r["macs_per_s"] / rows[1]["macs_per_s"]
    return rows


def save_stream_checkpoint(path: str | Path, model: StreamGRU, fit: StreamFitConfig, ds: Dataset, history: dict) -> None:
    blob = {"version": 1, "architecture": stream_signature(model),
            "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
            "config": config_dict(fit), "class_names": list(class_names(ds.arrays)),
            "channel_names": list(ds.channel_names), "history": history}
    with atomic_path(path, "wb") as fh:
        torch.save(blob, fh)


def load_stream_checkpoint(path: str | Path) -> tuple[StreamGRU, dict[str, Any]]:
    blob = torch.load(path, weights_only=True)
    model = stream_from_signature(blob["architecture"])
    model.load_state_dict(blob["state_dict"])
    model.eval()
    return model, blob


def train_stream_run(root: str | Path, cfg: Config, log: Callable[[str], None] = print) -> list[Path]:
    """Train with the [sgru] settings of ``cfg``, then write the checkpoint, the prediction set, its
    record and its index entry."""
    root = Path(root)
    fit = cfg.sgru
    ds = load_dataset(root / "dataset.npz")
    sim_seed = int(ds.config.sim.seed)
    model, hist = fit_stream_gru(ds, fit, log)
    history = {"loss": hist.loss, "val_macro_f1": hist.val_macro_f1, "epoch_s": hist.epoch_s,
               "best_epoch": hist.best_epoch}
    ckpt = root / f"{MODEL}_train{fit.seed}.pt"
    pred_path = prediction_path(root, MODEL, sim_seed, fit.seed)
    record_path = pred_path.with_suffix(".json")
    arrays = stream_prediction_set(model, ds)
    save_stream_checkpoint(ckpt, model, fit, ds, history)
    write_prediction_set(pred_path, arrays)
    write_json(record_path, {"model": MODEL, "sim_seed": sim_seed, "train_seed": fit.seed, "settings": config_dict(fit),
                             "history": history, "compute": compute_rows(cfg, model),
                             "checkpoint": ckpt.name, "predictions": pred_path.relative_to(root).as_posix()})
    index = add_entries(root, [index_entry(MODEL, sim_seed, fit.seed)])
    return [ckpt, pred_path, record_path, index]
