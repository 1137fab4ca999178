"""Prediction sets of a run and the index that lists them (docs/formats.md, "Prediction sets").

A *prediction set* is one model's class probabilities on every evaluation window of one dataset:
an .npz with

- ``proba``   (n, K) float32, rows summing to 1, columns in ``class_names`` order;
- ``y_true``  (n,) int64 window labels (the dataset's window-label rule);
- ``traj``    (n,) int64 row of the window's flight in the dataset's per-flight arrays;
- ``t_end``   (n,) float64 end time of the window in s;
- ``split``   (n,) int8 split code of the window's flight (1 validation, 2 test, 3.. the
  out-of-distribution test sets of the realistic suite; never 0 = train);
- ``class_names`` (K,) str;
- optional ``motor_proba`` (n, 4) float32: the suspected motor, for models that output it;
- optional ``decided`` (n,) bool: whether the window has a decision on a vehicle (False before the
  flight's hover freeze for a profile with a hover estimate); evaluate's alarm policy skips the
  others (core.alarm ``valid``), as detect does. Absent: every window decides.

``<run>/predictions/index.json`` lists the sets: ``{"entries": [{"model", "sim_seed",
"train_seed", "dataset", "predictions"}]}`` with the two paths relative to the run folder. The
producers (training, the seed study, the baselines) add entries; the evaluation reads them. An
entry is keyed by (model, sim_seed, train_seed): adding it again replaces it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json, write_json

INDEX_NAME = Path("predictions") / "index.json"
REQUIRED = ("proba", "y_true", "traj", "t_end", "split", "class_names")
ENTRY_KEYS = ("model", "sim_seed", "train_seed", "dataset", "predictions")


def index_path(run_root: str | Path) -> Path:
    return Path(run_root) / INDEX_NAME


def prediction_path(run_root: str | Path, model: str, sim_seed: int, train_seed: int) -> Path:
    """Where a producer writes a prediction set by default."""
    return Path(run_root) / "predictions" / f"{model}_sim{int(sim_seed)}_train{int(train_seed)}.npz"


def check_prediction_set(arrays: Mapping[str, Any], where: str) -> None:
    """A one-line error for a prediction set that breaks the format above."""
    missing = [k for k in REQUIRED if k not in arrays]
    if missing:
        raise QuadfdiError(f"{where}: prediction set lacks {', '.join(missing)}")
    proba = np.asarray(arrays["proba"])
    n = proba.shape[0] if proba.ndim == 2 else -1
    k = len(np.asarray(arrays["class_names"]).reshape(-1))
    if proba.ndim != 2 or proba.shape[1] != k:
        raise QuadfdiError(f"{where}: proba has shape {proba.shape}, expected (n, {k}) for {k} class names")
    for key in ("y_true", "traj", "t_end", "split"):
        if np.asarray(arrays[key]).shape != (n,):
            raise QuadfdiError(f"{where}: {key} has shape {np.asarray(arrays[key]).shape}, expected ({n},)")
    if "motor_proba" in arrays and np.asarray(arrays["motor_proba"]).shape != (n, 4):
        raise QuadfdiError(f"{where}: motor_proba has shape {np.asarray(arrays['motor_proba']).shape}, expected ({n}, 4)")
    if "decided" in arrays and np.asarray(arrays["decided"]).shape != (n,):
        raise QuadfdiError(f"{where}: decided has shape {np.asarray(arrays['decided']).shape}, expected ({n},)")
    if n and (np.asarray(arrays["split"]) == 0).any():
        raise QuadfdiError(f"{where}: holds training windows (split 0); a prediction set is evaluation windows only")


def read_index(run_root: str | Path) -> list[dict]:
    """The entries of the run's index ([] when no producer wrote one)."""
    path = index_path(run_root)
    if not path.exists():
        return []
    data = read_json(path, "prediction index")
    entries = data.get("entries") if isinstance(data, dict) else None
    if not isinstance(entries, list) or any(not isinstance(e, dict) or set(ENTRY_KEYS) - set(e) for e in entries):
        raise QuadfdiError(f"{path}: not a prediction index (expected {{'entries': [{{{', '.join(ENTRY_KEYS)}}}]}})")
    return entries


def add_entries(run_root: str | Path, entries: list[Mapping[str, Any]]) -> Path:
    """Add (or replace, by model x sim_seed x train_seed) entries; one writer at a time (the
    process that gathers a stage's results), the file replaced atomically."""
    root = Path(run_root)
    keyed = {(e["model"], int(e["sim_seed"]), int(e["train_seed"])): dict(e) for e in read_index(root)}
    for e in entries:
        missing = set(ENTRY_KEYS) - set(e)
        if missing:
            raise ValueError(f"index entry lacks {sorted(missing)}")
        for k in ("dataset", "predictions"):
            p = Path(e[k])
            if p.is_absolute():
                raise ValueError(f"index entry {k} must be relative to the run folder, got {p}")
        keyed[(e["model"], int(e["sim_seed"]), int(e["train_seed"]))] = {
            "model": str(e["model"]), "sim_seed": int(e["sim_seed"]), "train_seed": int(e["train_seed"]),
            "dataset": str(e["dataset"]), "predictions": str(e["predictions"])}
    path = index_path(root)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json(path, {"entries": [keyed[k] for k in sorted(keyed)]}, indent=2)
    return path
