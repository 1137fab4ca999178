"""Prediction sets of a trained network: its class probabilities on every evaluation window of a
dataset (split code >= 1: validation, test, the realistic suite's out-of-distribution sets), in the
format of ``formats.predictions`` (docs/formats.md, "Prediction sets"); a model with a motor head
(models.motor) adds ``motor_proba`` (n, 4), the softmax of its motor logits; every set carries
``decided`` (models.inputs.decided: False before the flight's hover freeze, where detect and
the streaming runtime give no decision; evaluate treats those windows as not voting).
``prediction_sets`` makes several sets from the same windows, each turned by its own variant (the
masked profile's windows under each mask pattern: train.study_apply.run_patterns).

The windows are made and scored a few flights at a time, so the full evaluation set (38 880
windows of 80 x 25 float32 on the realistic suite, 311 MB) is never held at once.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
import torch

from quadfdi.core.npzio import write_npz
from quadfdi.formats.predictions import check_prediction_set, prediction_path
from quadfdi.formats.dataset import Dataset, class_names, gather_windows, window_index
from quadfdi.train.data import evaluation_rows
from quadfdi.train.loop import predict_proba
from quadfdi.models.motor import N_MOTORS, has_motor_head, predict_motor_proba
from quadfdi.models.inputs import decided

FLIGHTS_PER_CHUNK = 16
NO_REFERENCE = "_noref"  # a reference profile's network without the vehicle record: model name <kind>_noref  # 16 x 90 windows x 80 x 25 float32 = 11.5 MB at a time


def prediction_set(model: torch.nn.Module, ds: Dataset, flights_per_chunk: int = FLIGHTS_PER_CHUNK,
                   max_flights: int | None = None) -> dict[str, np.ndarray]:
    """``model``'s prediction set on ``ds``: every window of every evaluation flight (the first
    ``max_flights`` of them when given: a check, not a set to publish), flight by flight in dataset
    order, windows in time order (the order of ``formats.dataset.make_windows``)."""
    return prediction_sets(model, ds, evaluation_rows(ds)[:max_flights], {"": None}, flights_per_chunk)[""]


def reference_sets(model: torch.nn.Module, ds: Dataset, kind: str, masker) -> dict[str, dict[str, np.ndarray]]:
    """A reference profile's two prediction sets of ``kind``: ``kind`` with each flight's vehicle record and
    ``kind + NO_REFERENCE`` with none (``masker``: train.masks.Masker; the windows made once for both)."""
    drop = lambda x: masker.drop_reference(x.copy(), np.arange(len(x)))  # noqa: E731
    sets = prediction_sets(model, ds, evaluation_rows(ds), {"": None, NO_REFERENCE: drop})
    return {kind: sets[""], kind + NO_REFERENCE: sets[NO_REFERENCE]}


def prediction_sets(model: torch.nn.Module, ds: Dataset, rows: np.ndarray,
                    variants: Mapping[str, Callable[[np.ndarray], np.ndarray] | None],
                    flights_per_chunk: int = FLIGHTS_PER_CHUNK) -> dict[str, dict[str, np.ndarray]]:
    """Variant name -> ``model``'s prediction set on the windows of the flights ``rows`` (dataset
    rows, in order) as ``variant`` (n, W, C) -> (n, W, C) turns them (None: as made), e.g. one
    mask pattern each (train.masks.Masker). The windows are made once a chunk for every variant."""
    names = class_names(ds.arrays)
    keys = ("proba", "y_true", "traj", "t_end", "decided") + (("motor_proba",) if has_motor_head(model) else ())
    parts = {v: {k: [] for k in keys} for v in variants}
    for i in range(0, len(rows), flights_per_chunk):
        traj, start = window_index(ds, rows[i:i + flights_per_chunk])
        w = gather_windows(ds, traj, start)
        common = {"y_true": w.y, "traj": w.traj, "t_end": w.t_end, "decided": decided(ds, w.traj, w.start)}
        for name, variant in variants.items():
            x = w.x if variant is None else variant(w.x)
            parts[name]["proba"].append(predict_proba(model, x))
            if "motor_proba" in keys:
                parts[name]["motor_proba"].append(predict_motor_proba(model, x))
            for k, v in common.items():
                parts[name][k].append(v)
    return {name: _set_arrays(p, ds, names) for name, p in parts.items()}


def _set_arrays(parts: dict[str, list[np.ndarray]], ds: Dataset, names: list[str]) -> dict[str, np.ndarray]:
    """The chunks of one prediction set joined, in the format's dtypes."""
    out = {k: np.concatenate(v) if v else np.zeros((0, len(names)) if k == "proba" else 0) for k, v in parts.items()}
    out["proba"] = out["proba"].astype(np.float32).reshape(-1, len(names))  # the format's dtype
    if "motor_proba" in out:
        out["motor_proba"] = out["motor_proba"].astype(np.float32).reshape(-1, N_MOTORS)
    out["y_true"] = out["y_true"].astype(np.int64)
    out["traj"] = out["traj"].astype(np.int64)
    out["t_end"] = out["t_end"].astype(np.float64)
    out["decided"] = out["decided"].astype(bool)
    out["split"] = np.asarray(ds["split"])[out["traj"]].astype(np.int8)
    out["class_names"] = np.array(names)
    return out


def split_part(pred: dict[str, np.ndarray], split_code: int) -> dict[str, np.ndarray]:
    """The windows of one split of a prediction set (same order), e.g. the test split's."""
    keep = pred["split"] == split_code
    return {k: (v if k == "class_names" else v[keep]) for k, v in pred.items()}


def write_prediction_set(path: str | Path, arrays: dict[str, Any]) -> Path:
    """Check ``arrays`` against the prediction-set format and write them atomically."""
    check_prediction_set(arrays, str(path))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_npz(path, arrays)
    return Path(path)


def relative_prediction_path(model: str, sim_seed: int, train_seed: int) -> str:
    """``formats.predictions.prediction_path`` relative to the run folder (what the index stores)."""
    return prediction_path(Path("."), model, sim_seed, train_seed).as_posix()


def index_entry(model: str, sim_seed: int, train_seed: int, dataset: str = "dataset.npz") -> dict[str, Any]:
    """The index entry of a prediction set written at its default path; ``dataset`` relative to the run."""
    return {"model": model, "sim_seed": int(sim_seed), "train_seed": int(train_seed), "dataset": dataset,
            "predictions": relative_prediction_path(model, sim_seed, train_seed)}


def drop_missing_entries(run_root: str | Path) -> int:
    """Remove the index entries whose prediction set no longer exists (a stage re-run with another
    seed unpublishes the sets of the previous one); returns how many were removed. Same format and
    atomic write as ``formats.predictions.add_entries``."""
    from quadfdi.core.jsonio import write_json
    from quadfdi.formats.predictions import index_path, read_index

    entries = read_index(run_root)
    keep = [e for e in entries if (Path(run_root) / e["predictions"]).is_file()]
    if len(keep) != len(entries):
        write_json(index_path(run_root), {"entries": keep}, indent=2)
    return len(entries) - len(keep)
