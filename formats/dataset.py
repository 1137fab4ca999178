"""The dataset file (``dataset.npz``) and windowing over it: the contract the next stages read.

The file is a plain ``.npz`` (one ``.npy`` per key, no pickle: it loads with
``np.load(path, allow_pickle=False)``); docs/formats.md lists every key. It is written with
fixed zip timestamps so that the same seed gives the same bytes, and atomically.

Windowing (SPEC section 2): windows of ``window`` samples every ``stride`` samples; a window is
labelled with its trajectory's fault class when the severity at its LAST sample is at or above
``severity_threshold``, else Healthy (0). Its end time is ``time[start + window - 1]``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from quadfdi.core.contracts import CLASS_NAMES, SPLITS
from quadfdi.core.npzio import read_npz, write_npz  # noqa: F401  (re-exported: the dataset's own I/O)
from quadfdi.core.config import Config, build_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.sections import section_dict


# key -> (dtype kind, number of dimensions); the contract of docs/formats.md.
REQUIRED_KEYS: dict[str, tuple[str, int]] = {
    "telemetry": ("f", 3),
    "time": ("f", 1),
    "channel_names": ("U", 1),
    "channel_units": ("U", 1),
    "states": ("f", 3),
    "state_names": ("U", 1),
    "state_units": ("U", 1),
    "severity": ("f", 2),
    "fault_class": ("i", 1),
    "onset_s": ("f", 1),
    "ramp_s": ("f", 1),
    "severity_max": ("f", 1),
    "fault_motor": ("i", 1),
    "detectable_s": ("f", 1),
    "split": ("i", 1),
    "traj_index": ("i", 1),
    "severity_threshold": ("f", 0),
    "config": ("U", 0),
}

@dataclass(frozen=True)
class Dataset:
    """The loaded dataset; ``arrays`` holds every key of the file."""

    path: Path
    arrays: dict[str, np.ndarray]
    config: Config

    def __getitem__(self, key: str) -> np.ndarray:
        return self.arrays[key]

    @property
    def n_channels(self) -> int:
        return int(self.arrays["telemetry"].shape[2])

    @property
    def channel_names(self) -> list[str]:
        return [str(c) for c in self.arrays["channel_names"]]

    @property
    def severity_threshold(self) -> float:
        return float(self.arrays["severity_threshold"])


def dataset_arrays(arrays: dict[str, np.ndarray], sim: Any) -> dict[str, np.ndarray]:
    """The simulator's arrays plus the config (JSON) that made them: what the file holds.

    Only the ``[sim]`` section (``sim``, i.e. ``cfg.sim``): it alone decides these bytes, so a change
    to a later stage's settings (or a new config section) neither changes the dataset nor makes it
    look stale.
    """
    if not all(hasattr(sim, key) for key in LATER_SIM_KEYS):
        raise TypeError(f"dataset_arrays takes the [sim] section (cfg.sim), found {type(sim).__name__}")
    out = dict(arrays)
    embedded = section_dict(sim)
    defaults = section_dict(type(sim)())
    for key in LATER_SIM_KEYS:  # absent = default: the paper dataset keeps the bytes it had before they existed
        if embedded[key] == defaults[key]:
            del embedded[key]
    out["config"] = np.array(json.dumps({"sim": embedded}, sort_keys=True))
    return out


# [sim] keys added after the paper dataset was fixed (the realistic suite); embedded only when not default.
LATER_SIM_KEYS = ("scenario", "classes", "ood_traj", "flights_per_vehicle", "reference_flights")


def class_names(arrays: dict[str, np.ndarray]) -> tuple[str, ...]:
    """The dataset's class names in label order: its ``class_names`` key, or the paper's four classes
    for a dataset without one (every paper-scenario dataset: that key would change its bytes)."""
    if "class_names" in arrays:
        return tuple(str(c) for c in arrays["class_names"])
    return CLASS_NAMES


def split_names(arrays: dict[str, np.ndarray]) -> tuple[str, ...]:
    """Split names by code (code i = name i): the ``split_names`` key, or train/validation/test."""
    if "split_names" in arrays:
        return tuple(str(c) for c in arrays["split_names"])
    return tuple(SPLITS)


# Per-flight fleet keys (the fleet suite, sim/fleet.py); absent from paper and realistic datasets.
FLEET_KEYS = ("vehicle_id", "vehicle_flight", "reference_flight", "airframe_class")


def vehicle_columns(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per flight: ``vehicle_id`` int32, ``vehicle_flight`` (its index on that vehicle) int16,
    ``reference_flight`` bool (a healthy reference flight), ``airframe_class`` int8 (code of
    ``airframe_class_names``). A dataset without them flew a new vehicle per flight: vehicle = row,
    flight 0, no reference flight, class 0 (the 450 class)."""
    n = arrays["telemetry"].shape[0]
    if all(k in arrays for k in FLEET_KEYS):
        return {k: np.asarray(arrays[k]) for k in FLEET_KEYS}
    return {"vehicle_id": np.arange(n, dtype=np.int32), "vehicle_flight": np.zeros(n, np.int16),
            "reference_flight": np.zeros(n, bool), "airframe_class": np.zeros(n, np.int8)}


def validate_arrays(arrays: dict[str, Any], where: str) -> None:
    """Check keys, dtypes and shapes against the contract; one-line error naming the field."""
    for key, (kind, ndim) in REQUIRED_KEYS.items():
        if key not in arrays:
            raise QuadfdiError(f"{where}: missing field {key!r} (not a quadfdi dataset, or an older version)")
        a = arrays[key]
        if a.dtype.kind not in (kind, "u" if kind == "i" else kind) or a.ndim != ndim:
            raise QuadfdiError(f"{where}: field {key!r} must be {ndim}-d of kind {kind!r}, found {a.ndim}-d {a.dtype}")
    n, t, c = arrays["telemetry"].shape
    expect = {
        "time": (t,), "channel_names": (c,), "channel_units": (c,), "severity": (n, t),
        "fault_class": (n,), "onset_s": (n,), "ramp_s": (n,), "severity_max": (n,), "fault_motor": (n,),
        "detectable_s": (n,), "split": (n,), "traj_index": (n,),
    }
    for key, shape in expect.items():
        if arrays[key].shape != shape:
            raise QuadfdiError(f"{where}: field {key!r} must have shape {shape}, found {arrays[key].shape}")
    present = [k for k in FLEET_KEYS if k in arrays]
    if present and (len(present) != len(FLEET_KEYS) or any(arrays[k].shape != (n,) for k in present)):
        raise QuadfdiError(f"{where}: the fleet fields {list(FLEET_KEYS)} must all be present with shape {(n,)}, "
                           f"found {[(k, arrays[k].shape) for k in present]}")
    if arrays["states"].shape[:2] != (n, t) or arrays["states"].shape[2] != arrays["state_names"].shape[0]:
        raise QuadfdiError(f"{where}: field 'states' has shape {arrays['states'].shape}, inconsistent with telemetry {(n, t, c)}")
    if not np.isfinite(arrays["telemetry"]).all():
        bad = np.argwhere(~np.isfinite(arrays["telemetry"]))[0]
        raise QuadfdiError(f"{where}: telemetry holds NaN or Inf (trajectory {bad[0]}, sample {bad[1]}, channel {bad[2]})")


def load_dataset(path: str | Path) -> Dataset:
    """Load and check ``dataset.npz`` (see docs/formats.md)."""
    p = Path(path)
    arrays = read_npz(p, "dataset")
    validate_arrays(arrays, str(p))
    try:
        cfg = build_config(json.loads(str(arrays["config"])), source=f"{p}:config")
    except json.JSONDecodeError as exc:
        raise QuadfdiError(f"{p}: field 'config' is not JSON: {exc}") from None
    return Dataset(p, arrays, cfg)


@dataclass(frozen=True)
class Windows:
    """Windows over a dataset. ``x`` (n, window, channels) float32 raw telemetry."""

    x: np.ndarray  # (n, W, C) float32
    y: np.ndarray  # (n,) int64 class label
    traj: np.ndarray  # (n,) int64 row of the trajectory in the dataset
    start: np.ndarray  # (n,) int64 first sample index
    t_end: np.ndarray  # (n,) float64 time of the last sample, time[start + W - 1]

    def __len__(self) -> int:
        return int(self.y.shape[0])


def window_starts(n_samples: int, window: int, stride: int) -> np.ndarray:
    """First-sample indices of every full window: 0, stride, ... (33 at paper scale)."""
    if n_samples < window:
        return np.zeros(0, dtype=np.int64)
    return np.arange(0, n_samples - window + 1, stride, dtype=np.int64)


def split_rows(ds: Dataset, split: str | int | None) -> np.ndarray:
    """Dataset rows of the flights in ``split``: a name of ``split_names`` ('train', 'validation',
    'test', or an out-of-distribution set of the realistic suite), its code, or None for all."""
    rows = np.arange(ds["telemetry"].shape[0])
    if split is None:
        return rows
    names = split_names(ds.arrays)
    if isinstance(split, str):
        if split not in names:
            raise QuadfdiError(f"unknown split {split!r}; valid: {', '.join(names)}")
        split = names.index(split)
    if not 0 <= int(split) < len(names):
        raise QuadfdiError(f"unknown split code {split}; valid: 0..{len(names) - 1} ({', '.join(names)})")
    return rows[ds["split"] == int(split)]


def window_index(ds: Dataset, rows: np.ndarray, window: int | None = None,
                 stride: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(traj, start) of every window of the flights ``rows``: flight by flight, windows in time order."""
    window = ds.config.sim.window if window is None else window
    stride = ds.config.sim.stride if stride is None else stride
    starts = window_starts(ds["telemetry"].shape[1], window, stride)
    rows = np.asarray(rows, dtype=np.int64)
    return np.repeat(rows, len(starts)), np.tile(starts, len(rows))


def gather_windows(ds: Dataset, traj: np.ndarray, start: np.ndarray, window: int | None = None) -> Windows:
    """The windows (traj[i], start[i]) with their labels.

    Label: the trajectory's fault class when ``severity[start + W - 1] >= severity_threshold``,
    else 0 (Healthy) -- SPEC section 2.
    """
    window = ds.config.sim.window if window is None else window
    tel, sev, time = ds["telemetry"], ds["severity"], ds["time"]
    traj, start = np.asarray(traj, dtype=np.int64), np.asarray(start, dtype=np.int64)
    last = start + window - 1
    # (n_windows, W) gather via broadcasting: one fancy-index, no Python loop per window.
    x = tel[traj[:, None], start[:, None] + np.arange(window)[None, :]]
    fault = sev[traj, last] >= ds.severity_threshold
    y = np.where(fault, ds["fault_class"][traj].astype(np.int64), 0)
    return Windows(x=np.ascontiguousarray(x, dtype=np.float32), y=y.astype(np.int64), traj=traj,
                   start=start, t_end=time[last].astype(np.float64))


def make_windows(ds: Dataset, split: str | int | None = None, window: int | None = None,
                 stride: int | None = None) -> Windows:
    """All windows of the trajectories in ``split`` (a name or code of ``split_names``, None for all).

    Order: trajectory by trajectory, windows in time order; labels as ``gather_windows``.
    """
    traj, start = window_index(ds, split_rows(ds, split), window, stride)
    return gather_windows(ds, traj, start, window)


def flights_by_class(ds: Dataset, n: int) -> list[int]:
    """Up to ``n`` test flights of ``ds``: round-robin over the classes (the first of each, then the
    second ...), the flights the stream checks replay."""
    test = [i for i, s in enumerate(split_names(ds.arrays)) if s == "test"]
    rows = np.flatnonzero(np.isin(ds["split"], test))
    per_class = [rows[ds["fault_class"][rows] == c].tolist() for c in range(len(class_names(ds.arrays)))]
    out: list[int] = []
    for j in range(max((len(p) for p in per_class), default=0)):
        out += [int(p[j]) for p in per_class if j < len(p)]
    return out[:n]
