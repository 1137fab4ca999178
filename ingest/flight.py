"""One log -> the arrays of ``flight.npz`` (the format: ``quadfdi.formats.flight``, docs/flight_format.md).

Reads the log (PX4 or ArduPilot), checks that it flew, cuts each landing back to its touchdown and
resamples every channel onto the 25 Hz grid, keeping each at its logged times too.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jobcache import file_sha256
from quadfdi.ingest import segments
from quadfdi.core import resample
from quadfdi.core.channels import ANGLE_CHANNELS, CHANNEL_NAMES, CHANNEL_UNITS
from quadfdi.formats.flight import FORMAT_VERSION
from quadfdi.ingest.logkind import head_kind
from quadfdi.ingest.model import LogRead

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
        "log_sha256": np.array(file_sha256(log_path)), "log_file": np.array(Path(log_path).name),
        "autopilot": np.array(lr.autopilot),
        "vehicle": np.array(json.dumps(dict(lr.vehicle, airborne_source=lr.airborne_source,
                                            data_span_s=list(lr.data_span)), sort_keys=True, default=float)),
        "resampling": np.array(json.dumps(resample.spec(gap_factor), sort_keys=True)),
        "notes": np.array(json.dumps(lr.notes)),
    })
    return arrays


def read_log(path: str | Path):
    """LogRead of a ULog (.ulg), DataFlash (.bin) or Crazyflie uSD log, chosen by its first bytes, not its name."""
    p = Path(path)
    if p.is_dir():
        raise QuadfdiError(f"log {p} is a folder, not a log file")
    if not p.exists():
        raise QuadfdiError(f"log {p} does not exist")
    if not p.is_file():
        raise QuadfdiError(f"log {p} is not a regular file (a FIFO or device?)")
    with open(p, "rb") as fh:
        head = fh.read(8)
    # any 0xBC start goes to the Crazyflie reader, which names an event-log version it does not know
    kind = head_kind(head) or ("crazyflie" if head[:1] == b"\xbc" else None)
    if kind == "ulog":
        from quadfdi.ingest.px4 import read_px4

        return read_px4(str(p))
    if kind == "dataflash":
        from quadfdi.ingest.ardupilot import read_ardupilot

        return read_ardupilot(str(p))
    if kind == "crazyflie":  # Crazyflie uSD event log (no extension)
        from quadfdi.ingest.crazyflie import read_crazyflie

        return read_crazyflie(str(p))
    raise QuadfdiError(f"{p} is neither a PX4 ULog, an ArduPilot DataFlash nor a Crazyflie uSD log "
                       f"(first bytes {head[:4]!r})")


def ingest(log: str | Path, min_airborne_s: float = segments.MIN_AIRBORNE_S,
           gap_factor: float = resample.GAP_FACTOR) -> tuple[LogRead, dict[str, np.ndarray]]:
    """Read, check and assemble one log; raises QuadfdiError (one line) for a refused log."""
    resample.check_gap_factor(gap_factor)
    segments.check_min_airborne(min_airborne_s)
    try:
        lr = read_log(log)
        segments.check_airborne(lr.airborne, min_airborne_s, lr.data_span)  # the log flew: the land detector's word
        segments.cut_landings(lr)  # the flight.npz's airborne ends at each touchdown
        segments.check_airborne(lr.airborne, min_airborne_s, lr.data_span)  # and still flew long enough after it
    except QuadfdiError as exc:
        raise QuadfdiError(f"{Path(log).name}: refused: {exc}") from None
    return lr, build(lr, log, gap_factor)
