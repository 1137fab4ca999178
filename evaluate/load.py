"""Read a run's prediction index and every set it lists, as per-flight padded batches.

A prediction set (formats.predictions) is a flat list of windows; the protocol works per flight, so
each set becomes a ``Flights`` batch: flights in dataset-row order, windows in time order, padded
at the end (``valid``). The dataset contributes only its per-flight arrays and the severity (for
the label-noise ceiling): the telemetry is never read. A fleet dataset's reference flights
(``reference_flight``) are left out of every set: they are what a vehicle reference is learned from,
so a model that reads the reference saw them, and no model is scored on them (docs/evaluation.md).
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.predictions import check_prediction_set, read_index

# What the protocol needs of a dataset (docs/formats.md); split_names is optional (paper datasets).
DATASET_KEYS = ("fault_class", "split", "onset_s", "detectable_s", "fault_motor", "severity", "time",
                "severity_threshold")
PAPER_SPLITS = ("train", "validation", "test")


@dataclass
class DatasetInfo:
    path: Path
    arrays: dict[str, np.ndarray]
    split_names: tuple[str, ...]


@dataclass
class Flights:
    """One prediction set as flights. rows (F,) dataset rows; proba (F, W, K); motor (F, W, 4) or None;
    y_true (F, W); t_end (F, W); valid (F, W) (False: padding); split (F,); stride_s the window spacing
    in s; decided (F, W) or None (the set's ``decided``: windows before the hover freeze do not vote)."""

    model: str
    sim_seed: int
    train_seed: int
    dataset: str
    class_names: tuple[str, ...]
    rows: np.ndarray
    proba: np.ndarray
    motor: np.ndarray | None
    y_true: np.ndarray
    t_end: np.ndarray
    valid: np.ndarray
    split: np.ndarray
    stride_s: float
    decided: np.ndarray | None = None  # (F, W) the set's optional ``decided``: None = every valid window

    def voting(self) -> np.ndarray:
        """(F, W) the windows the alarm policy reads (core.alarm ``valid``): real and decided."""
        return self.valid if self.decided is None else self.valid & self.decided

    def subset(self, keep: np.ndarray) -> "Flights":
        """The flights where ``keep`` (F,) is true."""
        pick = lambda a: None if a is None else a[keep]  # noqa: E731
        return Flights(self.model, self.sim_seed, self.train_seed, self.dataset, self.class_names, self.rows[keep],
                       self.proba[keep], pick(self.motor), self.y_true[keep], self.t_end[keep], self.valid[keep],
                       self.split[keep], self.stride_s, pick(self.decided))


def load_dataset_info(path: Path) -> DatasetInfo:
    """The per-flight arrays of a dataset.npz (lazily: the telemetry is not read)."""
    if not path.is_file():
        raise QuadfdiError(f"dataset {path} (listed in the prediction index) does not exist")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in DATASET_KEYS if k not in z.files]
            if missing:
                raise QuadfdiError(f"dataset {path} lacks {', '.join(missing)} (not a quadfdi dataset?)")
            arrays = {k: z[k] for k in DATASET_KEYS + (("reference_flight",) if "reference_flight" in z.files else ())}
            names = tuple(str(s) for s in z["split_names"]) if "split_names" in z.files else PAPER_SPLITS
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise QuadfdiError(f"dataset {path} is not a readable .npz (truncated or foreign file?): {exc}") from None
    return DatasetInfo(path, arrays, names)


def _read_set(path: Path) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise QuadfdiError(f"prediction set {path} (listed in the prediction index) does not exist")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise QuadfdiError(f"prediction set {path} is not a readable .npz: {exc}") from None
    check_prediction_set(arrays, str(path))
    return arrays


def to_flights(entry: dict, arrays: dict[str, np.ndarray], info: DatasetInfo) -> Flights:
    """Group a set's windows by flight (dataset row) and time; check them against the dataset."""
    where = entry["predictions"]
    traj, t_end = arrays["traj"].astype(np.int64), arrays["t_end"].astype(np.float64)
    n_rows = info.arrays["split"].shape[0]
    if traj.size == 0:
        raise QuadfdiError(f"prediction set {where} holds no windows")
    if traj.min() < 0 or traj.max() >= n_rows:
        raise QuadfdiError(f"prediction set {where}: traj outside 0..{n_rows - 1} of dataset {entry['dataset']}")
    if not np.array_equal(info.arrays["split"][traj], arrays["split"]):
        raise QuadfdiError(f"prediction set {where}: split codes differ from dataset {entry['dataset']}'s")
    order = np.lexsort((t_end, traj))
    traj, t_end = traj[order], t_end[order]
    rows, first, counts = np.unique(traj, return_index=True, return_counts=True)
    w = int(counts.max())
    pos = np.arange(traj.size) - np.repeat(first, counts)  # window index within its flight
    fi = np.repeat(np.arange(rows.size), counts)

    def pad(a: np.ndarray, fill) -> np.ndarray:
        out = np.full((rows.size, w) + a.shape[1:], fill, dtype=a.dtype)
        out[fi, pos] = a[order]
        return out

    steps = np.diff(t_end)[np.diff(traj) == 0]
    if steps.size and steps.min() <= 0:
        raise QuadfdiError(f"prediction set {where}: two windows of one flight share an end time")
    motor = pad(arrays["motor_proba"].astype(np.float64), 0.0) if "motor_proba" in arrays else None
    return Flights(model=str(entry["model"]), sim_seed=int(entry["sim_seed"]), train_seed=int(entry["train_seed"]),
                   dataset=str(entry["dataset"]), class_names=tuple(str(c) for c in arrays["class_names"]),
                   rows=rows, proba=pad(arrays["proba"].astype(np.float64), 0.0), motor=motor,
                   y_true=pad(arrays["y_true"].astype(np.int64), -1), t_end=pad(t_end, np.nan),
                   valid=pad(np.ones(traj.size, bool), False),
                   decided=pad(arrays["decided"].astype(bool), False) if "decided" in arrays else None,
                   split=info.arrays["split"][rows].astype(np.int64),
                   stride_s=float(np.median(steps)) if steps.size else 0.0)


def load_run(run_root: Path) -> tuple[list[Flights], dict[str, DatasetInfo]]:
    """Every indexed prediction set as Flights, and the datasets they refer to (by relative path)."""
    entries = read_index(run_root)
    if not entries:
        raise QuadfdiError(f"{run_root}/predictions/index.json lists no prediction set: run a producer first "
                           "(quadfdi train or the baselines write prediction sets and index them)")
    infos: dict[str, DatasetInfo] = {}
    sets = []
    for e in entries:
        if e["dataset"] not in infos:
            infos[e["dataset"]] = load_dataset_info(run_root / e["dataset"])
        fl = to_flights(e, _read_set(run_root / e["predictions"]), infos[e["dataset"]])
        if "reference_flight" in infos[e["dataset"]].arrays:
            fl = fl.subset(~infos[e["dataset"]].arrays["reference_flight"][fl.rows].astype(bool))
        sets.append(fl)
    names = {s.class_names for s in sets}
    if len(names) != 1:
        raise QuadfdiError(f"prediction sets disagree on the class names: {sorted(names)}")
    if "Healthy" not in next(iter(names)):
        raise QuadfdiError("the class names have no 'Healthy' class: the alarm policy needs one")
    return sets, infos
