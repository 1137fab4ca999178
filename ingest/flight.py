"""Assemble, write and read ``flight.npz`` (the contract: docs/flight_format.md).

One file per log: every channel at its logged times (``raw.<name>.t`` / ``raw.<name>.v``), the same
channels on the 25 Hz grid (``telemetry`` with ``mask``), what each channel is and where it came
from, the flight's intervals, the log's sha256 and the vehicle facts read from it.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.npzio import read_npz, write_npz
from quadfdi.ingest import resample, segments
from quadfdi.ingest.model import ANGLE_CHANNELS, CHANNEL_NAMES, CHANNEL_UNITS, LogRead

FORMAT_VERSION = 1
REQUIRED = ("format_version", "time", "telemetry", "mask", "channel_names", "channel_units", "channel_sources",
            "channel_status", "channel_rates_hz", "channel_counts", "airborne", "airborne_segments",
            "armed_segments", "log_sha256", "log_file", "autopilot", "vehicle", "resampling", "notes")


def sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def flight_span(lr: LogRead) -> tuple[float, float]:
    """From the first arming (or take-off) to the last disarm (or landing), within the data."""
    iv = lr.armed + lr.airborne
    t0, t1 = min(a for a, _ in iv), max(b for _, b in iv)
    return max(t0, lr.data_span[0]), min(t1, lr.data_span[1])


def _segments_array(iv) -> np.ndarray:
    return np.array(iv, dtype=np.float64).reshape(-1, 2)


def build(lr: LogRead, log_path: str | Path, gap_factor: float = resample.GAP_FACTOR) -> dict[str, np.ndarray]:
    t0, t1 = flight_span(lr)
    grid = resample.make_grid(t0, t1)
    n, c = len(grid), len(CHANNEL_NAMES)
    tel, mask = np.full((n, c), np.nan), np.zeros((n, c), bool)
    sources, status, rates, counts = [], [], np.zeros(c), np.zeros(c, np.int64)
    arrays: dict[str, np.ndarray] = {}
    for j, name in enumerate(CHANNEL_NAMES):
        ch = lr.channels.get(name)
        if ch is None:
            sources.append("")
            status.append(lr.status.get(name, "absent: not in this log"))
            continue
        keep = (ch.t >= t0) & (ch.t <= t1)
        arrays[f"raw.{name}.t"] = ch.t[keep].astype(np.float64)
        arrays[f"raw.{name}.v"] = ch.v[keep].astype(np.float64)
        tel[:, j], mask[:, j] = resample.resample(ch.t, ch.v, grid, angle=name in ANGLE_CHANNELS, gap_factor=gap_factor)
        sources.append(ch.source)
        status.append(lr.status.get(name, "ok"))
        rates[j], counts[j] = ch.rate_hz, int(keep.sum())
    air = np.zeros(n, bool)
    for a, b in lr.airborne:
        air |= (grid >= a) & (grid <= b)
    arrays.update({
        "format_version": np.array(FORMAT_VERSION), "time": grid, "telemetry": tel.astype(np.float32), "mask": mask,
        "channel_names": np.array(CHANNEL_NAMES), "channel_units": np.array([CHANNEL_UNITS[k] for k in CHANNEL_NAMES]),
        "channel_sources": np.array(sources), "channel_status": np.array(status),
        "channel_rates_hz": rates, "channel_counts": counts, "airborne": air,
        "airborne_segments": _segments_array(lr.airborne), "armed_segments": _segments_array(lr.armed),
        "log_sha256": np.array(sha256(log_path)), "log_file": np.array(Path(log_path).name),
        "autopilot": np.array(lr.autopilot),
        "vehicle": np.array(json.dumps(dict(lr.vehicle, airborne_source=lr.airborne_source,
                                            data_span_s=list(lr.data_span)), sort_keys=True, default=float)),
        "resampling": np.array(json.dumps(resample.spec(gap_factor), sort_keys=True)),
        "notes": np.array(json.dumps(lr.notes)),
    })
    return arrays


def read_log(path: str | Path):
    """LogRead of a ULog (.ulg) or DataFlash (.bin) file, chosen by its first bytes, not its name."""
    p = Path(path)
    if not p.is_file():
        raise QuadfdiError(f"log {p} does not exist")
    with open(p, "rb") as fh:
        head = fh.read(8)
    if head.startswith(b"ULog"):
        from quadfdi.ingest.px4 import read_px4

        return read_px4(str(p))
    if head[:2] == b"\xa3\x95":  # DataFlash message header
        from quadfdi.ingest.ardupilot import read_ardupilot

        return read_ardupilot(str(p))
    raise QuadfdiError(f"{p} is neither a PX4 ULog nor an ArduPilot DataFlash log (first bytes {head[:4]!r})")


def ingest(log: str | Path, min_airborne_s: float = segments.MIN_AIRBORNE_S,
           gap_factor: float = resample.GAP_FACTOR) -> tuple[LogRead, dict[str, np.ndarray]]:
    """Read, check and assemble one log; raises QuadfdiError (one line) for a refused log."""
    resample.check_gap_factor(gap_factor)
    try:
        lr = read_log(log)
        segments.check_airborne(lr.airborne, min_airborne_s, lr.data_span)  # the log flew: the land detector's word
        segments.cut_landings(lr)  # the flight.npz's airborne ends at each touchdown
    except QuadfdiError as exc:
        raise QuadfdiError(f"{Path(log).name}: refused: {exc}") from None
    return lr, build(lr, log, gap_factor)


def write_flight(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    write_npz(path, arrays)


def load_flight(path: str | Path) -> dict[str, np.ndarray]:
    """A flight.npz's arrays, checked against the contract (one-line error naming the field)."""
    arrays = read_npz(path, "flight")
    for key in REQUIRED:
        if key not in arrays:
            raise QuadfdiError(f"{path}: missing field {key!r} (not a quadfdi flight.npz)")
    if int(arrays["format_version"]) != FORMAT_VERSION:
        raise QuadfdiError(f"{path}: format_version {int(arrays['format_version'])}, this quadfdi reads {FORMAT_VERSION}")
    n, c = arrays["telemetry"].shape
    if arrays["mask"].shape != (n, c) or arrays["time"].shape != (n,) or arrays["channel_names"].shape != (c,):
        raise QuadfdiError(f"{path}: telemetry {arrays['telemetry'].shape}, mask, time and channel_names disagree")
    return arrays
