"""``flight.npz``: one flight, real or simulated, as every later stage reads it (docs/flight_format.md).

Every channel at its logged times (``raw.<name>.t`` / ``raw.<name>.v``), the same channels on the
25 Hz grid (``telemetry`` with ``mask``), what each channel is and where it came from, the flight's
intervals, the log's sha256 and the vehicle facts read from it. ``quadfdi ingest`` writes it from a
log, the simulator from a simulated flight; both through ``write_flight``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.npzio import read_npz, write_npz
from quadfdi.core.resample import GRID_DT

# 2: each autopilot's vibration metric its own channel (vib_px4, vib_ap); version 1 held one vib_acc
# whose meaning depended on the autopilot (ArduPilot's as the 3-axis VIBE norm): re-ingest such files.
FORMAT_VERSION = 2
REQUIRED = ("format_version", "time", "telemetry", "mask", "channel_names", "channel_units", "channel_sources",
            "channel_status", "channel_rates_hz", "channel_counts", "airborne", "airborne_segments",
            "armed_segments", "log_sha256", "log_file", "autopilot", "vehicle", "resampling", "notes")


def write_flight(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    write_npz(path, arrays)


def load_flight(path: str | Path) -> dict[str, np.ndarray]:
    """A flight.npz's arrays, checked against the contract (one-line error naming the field)."""
    arrays = read_npz(path, "flight")
    for key in REQUIRED:
        if key not in arrays:
            raise QuadfdiError(f"{path}: missing field {key!r} (not a quadfdi flight.npz)")
    if int(arrays["format_version"]) != FORMAT_VERSION:
        raise QuadfdiError(f"{path}: format_version {int(arrays['format_version'])}, this quadfdi reads {FORMAT_VERSION} "
                           "(re-run `quadfdi ingest` on the log)")
    n, c = arrays["telemetry"].shape
    if arrays["mask"].shape != (n, c) or arrays["time"].shape != (n,) or arrays["channel_names"].shape != (c,):
        raise QuadfdiError(f"{path}: telemetry {arrays['telemetry'].shape}, mask, time and channel_names disagree")
    check_time(arrays["time"], str(path))
    return arrays


GRID_TOL_S = 1e-6  # s: a grid time differs from k x GRID_DT by float rounding only


def check_time(time, where: str) -> None:
    """A flight.npz time axis is the 25 Hz grid: finite, increasing by GRID_DT (within GRID_TOL_S) at
    every step. A reversed, stretched, gapped or NaN axis would place every decision at the wrong time
    and read every window at the wrong rate: refused in one line."""
    t = np.asarray(time, np.float64)
    if t.ndim != 1 or len(t) < 2:
        raise QuadfdiError(f"{where}: time must hold at least two samples, found shape {t.shape}")
    if not np.isfinite(t).all():
        raise QuadfdiError(f"{where}: time holds {int((~np.isfinite(t)).sum())} NaN or infinite values")
    d = np.diff(t)
    bad = np.flatnonzero(np.abs(d - GRID_DT) > GRID_TOL_S)
    if bad.size:
        i = int(bad[0])
        what = "goes backwards" if d[i] < 0 else "repeats" if d[i] == 0 else f"steps by {d[i]:.6g} s"
        raise QuadfdiError(f"{where}: time {what} at sample {i + 1} (t = {t[i]:.6g} -> {t[i + 1]:.6g} s); a flight.npz "
                           f"is on the {GRID_DT:g} s grid (re-run quadfdi ingest on the log)")
