"""``quadfdi train scnode``: train the streaming CNODE on a run's dataset, on the run's channel profile
([train].profile), and publish it beside the windowed networks and the streaming GRU.

Writes into the run folder:
- ``scnode_train<T>.pt``: the checkpoint (plain dict, ``torch.load(weights_only=True)``): ``architecture``
  (``models.stream_cnode.stream_signature``), ``state_dict``, ``config`` (the [scnode] section),
  ``profile``, ``class_names``, ``channel_names`` (the profile's), ``history``;
- ``predictions/scnode_sim<S>_train<T>.npz``: the stream's class probabilities at the end sample of every
  evaluation window, z = 0 at take-off, one step per sample, each flight under its own mask pattern for
  a masked profile (train/stream_gru_run.py ``stream_prediction_set``), and its index entry;
- ``predictions/scnode_sim<S>_train<T>.json``: settings, history, and the multiply-accumulates per
  sample and per second of flight of the streaming CNODE beside the streaming GRU and the windowed
  networks (``compute_rows``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from quadfdi.core.atomic import atomic_path
from quadfdi.core.config import Config
from quadfdi.core.jsonio import write_json
from quadfdi.formats.dataset import Dataset, class_names, load_dataset
from quadfdi.formats.predictions import add_entries, prediction_path
from quadfdi.models.inputs import PROFILE_KEY, profiled_dataset
from quadfdi.models.networks import build_model
from quadfdi.models.stream_cnode import StreamCNODE, stream_from_signature, stream_signature
from quadfdi.models.stream_gru import StreamGRU
from quadfdi.train.config import StreamCnodeConfig
from quadfdi.train.predsets import index_entry, write_prediction_set
from quadfdi.train.stream_cnode_fit import fit_stream_cnode
from quadfdi.train.stream_gru_fit import config_dict
from quadfdi.train.stream_gru_run import stream_prediction_set

MODEL = "scnode"


def compute_rows(cfg: Config, model: StreamCNODE) -> list[dict[str, Any]]:
    """Multiply-accumulates per decision and per second of flight: the streams decide at every sample,
    the windowed models at every stride (a full window each); the streaming GRU at the run's [sgru] width."""
    rate = 1.0 / cfg.sim.sample_dt_s
    per_s_stride = rate / cfg.sim.stride
    c, k, w = model.n_channels, model.n_classes, cfg.sim.window
    sgru = StreamGRU(c, cfg.sgru.hidden, k)
    rows = [{"model": MODEL, "decisions_per_s": rate, "macs_per_decision": model.macs_per_step()},
            {"model": "sgru", "decisions_per_s": rate, "macs_per_decision": sgru.macs_per_step()}]
    for kind in ("gru", "cnode"):
        net = build_model(kind, c, cfg.train, window=w, n_classes=k)
        rows.append({"model": kind, "decisions_per_s": per_s_stride, "macs_per_decision": net.macs_per_window()})
    for r in rows:
        r["macs_per_s"] = r["macs_per_decision"] * r["decisions_per_s"]
    return rows


def save_checkpoint(path: str | Path, model: StreamCNODE, fit: StreamCnodeConfig, ds: Dataset, profile: str,
                    history: dict) -> None:
    blob = {"version": 1, "architecture": stream_signature(model),
            "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
            "config": config_dict(fit), PROFILE_KEY: profile, "class_names": list(class_names(ds.arrays)),
            "channel_names": list(ds.channel_names), "history": history}
    with atomic_path(path, "wb") as fh:
        torch.save(blob, fh)


def load_checkpoint(path: str | Path) -> tuple[StreamCNODE, dict[str, Any]]:
    blob = torch.load(path, weights_only=True)
    model = stream_from_signature(blob["architecture"])
    model.load_state_dict(blob["state_dict"])
    model.eval()
    return model, blob


def train_scnode_run(root: str | Path, cfg: Config, log: Callable[[str], None] = print) -> list[Path]:
    """Train with the [scnode] settings of ``cfg`` on the profile of [train], then write the checkpoint,
    the prediction set, its record and its index entry."""
    root = Path(root)
    fit, profile = cfg.scnode, cfg.train.profile
    raw = load_dataset(root / "dataset.npz")
    sim_seed = int(raw.config.sim.seed)
    ds = profiled_dataset(raw, profile, patterns=False)  # every channel: masks are drawn per segment
    val_ds = profiled_dataset(raw, profile, patterns=True)  # each flight under its own pattern
    model, hist = fit_stream_cnode(ds, val_ds, fit, profile, log)
    history = {"loss": hist.loss, "val_macro_f1": hist.val_macro_f1, "epoch_s": hist.epoch_s,
               "best_epoch": hist.best_epoch}
    ckpt = root / f"{MODEL}_train{fit.seed}.pt"
    pred_path = prediction_path(root, MODEL, sim_seed, fit.seed)
    record_path = pred_path.with_suffix(".json")
    arrays = stream_prediction_set(model, val_ds)
    save_checkpoint(ckpt, model, fit, ds, profile, history)
    write_prediction_set(pred_path, arrays)
    write_json(record_path, {"model": MODEL, "sim_seed": sim_seed, "train_seed": fit.seed, "profile": profile,
                             "settings": config_dict(fit), "history": history, "compute": compute_rows(cfg, model),
                             "checkpoint": ckpt.name, "predictions": pred_path.relative_to(root).as_posix()})
    index = add_entries(root, [index_entry(MODEL, sim_seed, fit.seed)])
    return [ckpt, pred_path, record_path, index]
