"""A real flight -> the model's input windows under its channel profile, or a one-line refusal.

Refused (QuadfdiError, before anything is written): a channel the profile needs absent or marked
unusable by ingest (a disconnected battery monitor is an unusable channel, never a battery fault);
an ArduPilot log for a profile reading PX4's vibration metric (VIBE is another quantity); no
cell count; not a multirotor (ingest refuses VTOLs and planes itself); no 2 s of steady hover for
the hover estimate; too short for one decided window.

A window decides when it ends at or after the hover estimate's freeze and every sample of every
channel the profile reads is backed by logged data (flight.npz ``mask``); the others are kept on
the window grid, marked undecided (the alarm policy skips them: core.alarm ``valid``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfdi.core import hover
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.profiles import apply_profile, channel_names, required_raw, uses_hover

MULTIROTOR_FRAMES = ("quadrotor", "quad", "quad-x", "quad-plus", "x", "plus")


@dataclass
class FlightInputs:
    name: str  # the log's file name
    time: np.ndarray  # (T,) grid times, s
    x: np.ndarray  # (T, C') profile channels (NaN where undefined)
    used: np.ndarray  # (T,) bool: every raw channel the profile reads is backed by data
    starts: np.ndarray  # (n,) window first-sample indices
    decided: np.ndarray  # (n,) bool
    hover: hover.Hover
    cells: int
    channel_names: list[str]
    airborne_s: float


def read_flight(path: str | Path) -> dict[str, np.ndarray]:
    """A flight.npz, or a .ulg / .BIN log ingested on the fly (ingest's own refusals apply)."""
    p = Path(path)
    if not p.is_file():
        raise QuadfdiError(f"flight {p} does not exist")
    if p.suffix == ".npz":
        from quadfdi.formats.flight import load_flight

        return load_flight(p)
    from quadfdi.ingest.flight import ingest

    return ingest(p)[1]


def _raw_channels(arrays: dict, profile: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """name -> (T,) float32 for every raw channel the profile reads, and the (T,) all-backed mask."""
    names = [str(n) for n in arrays["channel_names"]]
    status = {n: str(s) for n, s in zip(names, arrays["channel_status"])}
    where = str(arrays["log_file"])
    raw, used = {}, np.ones(len(arrays["time"]), bool)
    for r in required_raw(profile, names):
        src = r
        if src not in names:
            raise QuadfdiError(f"{where}: profile {profile!r} needs channel {src!r}, which flight.npz does not have")
        if status[src] != "ok":
            raise QuadfdiError(f"{where}: profile {profile!r} needs channel {src!r}, which is {status[src]}")
        j = names.index(src)
        raw[r] = np.asarray(arrays["telemetry"][:, j], np.float32)
        used &= np.asarray(arrays["mask"][:, j], bool)
    if "I_b" in names and "I_b" not in raw and status["I_b"] == "ok":
        raw["I_b"] = np.asarray(arrays["telemetry"][:, names.index("I_b")], np.float32)  # the hover current, if any
    return raw, used


def _cells(arrays: dict) -> int:
    vehicle = json.loads(str(arrays["vehicle"]))
    frame = str(vehicle.get("frame", "")).lower()
    if frame and frame not in MULTIROTOR_FRAMES:
        raise QuadfdiError(f"{arrays['log_file']}: not a quadrotor (frame {frame!r})")
    cells = (vehicle.get("battery") or {}).get("cells")
    if not cells:
        raise QuadfdiError(f"{arrays['log_file']}: the pack's cell count is unknown (no BAT*_N_CELLS nor cell_count)")
    return int(cells)


def flight_inputs(arrays: dict, profile: str, window: int, stride: int) -> FlightInputs:
    """The profile's windows of one ingested flight (``arrays``: ingest.flight's), or a refusal."""
    where = str(arrays["log_file"])
    if not uses_hover(profile):
        raise QuadfdiError(f"{where}: profile {profile!r} is the simulator's telemetry (motor temperatures, "
                           "thrust-fraction commands): train with --set train.profile=flightlog-min for real flights")
    cells = _cells(arrays)
    raw, used = _raw_channels(arrays, profile)
    airborne = np.asarray(arrays["airborne"], bool)
    cols = np.stack([raw.get(c, np.full(len(airborne), np.nan, np.float32)) for c in hover.INPUTS], axis=1)
    est = hover.estimate(cols, airborne)
    if not est.ok:
        raise QuadfdiError(f"{where}: never {hover.STEADY_SAMPLES} steady airborne samples in a row "
                           f"({hover.STEADY_SAMPLES * 0.04:.0f} s of hover) for the hover estimate (core.hover)")
    if "i_rel" in channel_names(profile, []) and not np.isfinite(est.cur):
        raise QuadfdiError(f"{where}: the current has gaps during the hover estimate's steady seconds")
    x = apply_profile(profile, raw, cells, est.cmd, est.cur)
    t = len(airborne)
    starts = np.arange(0, t - window + 1, stride, dtype=np.int64) if t >= window else np.zeros(0, np.int64)
    ok = used & airborne & np.isfinite(x).all(axis=1)
    cs = np.concatenate([[0], np.cumsum(ok)])
    decided = (starts + window - 1 >= est.freeze) & (cs[starts + window] - cs[starts] == window)
    if not decided.any():
        raise QuadfdiError(f"{where}: too short: no window of {window} samples ({window * 0.04:.1f} s) with every "
                           f"channel backed after the hover estimate froze at {arrays['time'][est.freeze]:.1f} s "
                           f"({float(airborne.sum()) * 0.04:.1f} s airborne)")
    return FlightInputs(name=Path(where).name, time=np.asarray(arrays["time"], np.float64), x=x, used=ok,
                        starts=starts, decided=decided, hover=est, cells=cells,
                        channel_names=channel_names(profile, []), airborne_s=float(airborne.sum()) * 0.04)


def windows(fi: FlightInputs, window: int) -> np.ndarray:
    """(n_decided, W, C') float32: the decided windows (undecided ones are never run)."""
    s = fi.starts[fi.decided]
    return np.ascontiguousarray(fi.x[s[:, None] + np.arange(window)[None, :]], dtype=np.float32)
