"""A real flight -> the model's input windows under its channel profile, or a one-line refusal.

Refused (QuadfdiError, before anything is written): a channel the profile needs absent or marked
unusable by ingest (a disconnected battery monitor is an unusable channel, never a battery fault);
an ArduPilot log for a profile reading PX4's vibration metric (VIBE is another quantity); no
cell count; not a multirotor (ingest refuses VTOLs and planes itself); no 2 s of steady hover for
the hover estimate; too short for one decided window.

A window decides when it ends at or after the hover estimate's freeze and every sample of every
channel the profile reads is backed by logged data (flight.npz ``mask``); the others are kept on
the window grid, marked undecided (the alarm policy skips them: core.alarm ``valid``).

The masked profile (``flightlog-mask``) refuses only a flight without the minimum (core/channels.py
MINIMUM_RAW: the refusal names the channel and ingest's status) or too short for one decided window.
A group (core/channels.py AVAILABILITY_GROUPS) is available when each of its channels is "ok" in
flight.npz's ``channel_status``; ``battery`` also needs the pack's cell count, ``current`` a current
during the hover estimate's steady seconds. A lacking group's channels take their fills
(core.profiles.apply_profile), an absent pitch enters the hover estimate as 0 (core.hover), and
``FlightRaw.absent`` says why each of its channels is absent (for alarms.json). ``flight_raw`` is
what detect and ``quadfdi stream-file`` both read of a flight, so the stream carries the channels
detect uses.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfdi.core import hover
from quadfdi.core.channels import AVAILABILITY_GROUPS, MINIMUM_RAW
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.profiles import apply_profile, channel_names, is_masked, required_raw, uses_hover

MULTIROTOR_FRAMES = ("quadrotor", "quad", "quad-x", "quad-plus", "x", "plus")
NOT_IN_FLIGHT = "absent: not in flight.npz"


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
    available: dict[str, bool] | None = None  # the masked profile: group -> the flight has it
    absent: dict[str, str] | None = None  # the masked profile: raw channel -> why it is absent


@dataclass
class FlightRaw:
    """What a profile reads of one flight: the raw channels it uses (name -> (T,) float32), the (T,)
    all-backed mask, the cell count (0: unknown, the masked profile without the battery group), the
    hover estimate, and for the masked profile the groups' availability and why channels are absent."""

    raw: dict[str, np.ndarray]
    used: np.ndarray
    cells: int
    hover: hover.Hover
    available: dict[str, bool] | None = None
    absent: dict[str, str] | None = None


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


def _cells(arrays: dict, required: bool = True) -> int:
    """The pack's cell count; unknown: a refusal, or 0 when not ``required``."""
    vehicle = json.loads(str(arrays["vehicle"]))
    frame = str(vehicle.get("frame", "")).lower()
    if frame and frame not in MULTIROTOR_FRAMES:
        raise QuadfdiError(f"{arrays['log_file']}: not a quadrotor (frame {frame!r})")
    cells = (vehicle.get("battery") or {}).get("cells")
    if not cells and required:
        raise QuadfdiError(f"{arrays['log_file']}: the pack's cell count is unknown (no BAT*_N_CELLS nor cell_count)")
    return int(cells or 0)


def _masked_raw(arrays: dict, profile: str, cells: int) -> tuple[dict, np.ndarray, dict, dict]:
    """The masked profile's raw channels: the minimum (or a refusal naming the channel and its status)
    and every available group's; the (T,) all-backed mask, group -> available, channel -> why absent."""
    names = [str(n) for n in arrays["channel_names"]]
    status = {n: str(s) for n, s in zip(names, arrays["channel_status"])}
    where = str(arrays["log_file"])
    for r in MINIMUM_RAW:
        if status.get(r) != "ok":
            raise QuadfdiError(f"{where}: profile {profile!r} needs channel {r!r} (its minimum), which is "
                               f"{status.get(r, NOT_IN_FLIGHT)}")
    available, absent = {}, {}
    for g in AVAILABILITY_GROUPS:
        bad = {r: status.get(r, NOT_IN_FLIGHT) for r in g.raw if status.get(r) != "ok"}
        if not bad and g.name == "battery" and cells < 1:
            bad = {"V_b": "the pack's cell count is unknown (no BAT*_N_CELLS nor cell_count)"}
        available[g.name] = not bad
        first = next(iter(bad.items()), None)
        absent.update({r: bad.get(r, f"{first[0]} of its group ({g.name}) is {first[1]}") for r in g.raw} if bad else {})
    raw, used = {}, np.ones(len(arrays["time"]), bool)
    for r in [c for c in required_raw(profile) if c in MINIMUM_RAW or c not in absent]:
        j = names.index(r)
        raw[r] = np.asarray(arrays["telemetry"][:, j], np.float32)
        used &= np.asarray(arrays["mask"][:, j], bool)
    return raw, used, available, absent


def _hover(raw: dict, airborne: np.ndarray, where: str) -> hover.Hover:
    """The hover estimate of the raw channels (an absent pitch: level; an absent current: NaN)."""
    t = len(airborne)
    fill = {"pitch": np.zeros(t, np.float32)}
    cols = np.stack([raw.get(c, fill.get(c, np.full(t, np.nan, np.float32))) for c in hover.INPUTS], axis=1)
    est = hover.estimate(cols, airborne)
    if not est.ok:
        raise QuadfdiError(f"{where}: never {hover.STEADY_SAMPLES} steady airborne samples in a row "
                           f"({hover.STEADY_SAMPLES * 0.04:.0f} s of hover) for the hover estimate (core.hover)")
    return est


def flight_raw(arrays: dict, profile: str) -> FlightRaw:
    """The raw channels, cell count, hover estimate and availability profile ``profile`` reads of one
    ingested flight, or a one-line refusal (module docstring)."""
    where = str(arrays["log_file"])
    airborne = np.asarray(arrays["airborne"], bool)
    if not is_masked(profile):
        cells = _cells(arrays)
        raw, used = _raw_channels(arrays, profile)
        est = _hover(raw, airborne, where)
        if "i_rel" in channel_names(profile, []) and not np.isfinite(est.cur):
            raise QuadfdiError(f"{where}: the current has gaps during the hover estimate's steady seconds")
        return FlightRaw(raw, used, cells, est)
    cells = _cells(arrays, required=False)
    raw, used, available, absent = _masked_raw(arrays, profile, cells)
    est = _hover(raw, airborne, where)
    if available["current"] and not np.isfinite(est.cur):  # no hover current: i_rel cannot be formed
        available["current"] = False
        absent["I_b"] = "gaps during the hover estimate's steady seconds"
        raw.pop("I_b")  # the estimate's command and freeze do not read the current
        used = _backed(arrays, raw)
    return FlightRaw(raw, used, cells, est, available, absent)


def _gaps_hint(arrays: dict, raw: dict, airborne: np.ndarray, est: hover.Hover) -> str:
    """When logging gaps, not the airborne time, leave no window: the channels with gaps after the freeze
    (their share of those airborne samples unbacked) and the ingest option that bridges longer gaps."""
    after = airborne & (np.arange(len(airborne)) >= max(est.freeze, 0))
    if after.sum() < 1:
        return ""
    names = [str(n) for n in arrays["channel_names"]]
    mask = np.asarray(arrays["mask"], bool)
    holes = {r: 1.0 - mask[after, names.index(r)].mean() for r in raw if r in names}
    worst = sorted(((v, r) for r, v in holes.items() if v > 0), reverse=True)[:3]
    if not worst:
        return ""
    return ("; logging gaps leave " + ", ".join(f"{v:.0%} of {r}" for v, r in worst) + " unbacked in the airborne "
            "samples after it (`quadfdi ingest LOG --gap-factor F` bridges gaps up to F x a channel's median interval)")


def _backed(arrays: dict, raw: dict) -> np.ndarray:
    """(T,) bool: every channel of ``raw`` backed by logged data (flight.npz ``mask``)."""
    names = [str(n) for n in arrays["channel_names"]]
    return np.asarray(arrays["mask"][:, [names.index(r) for r in raw]], bool).all(axis=1)


def flight_inputs(arrays: dict, profile: str, window: int, stride: int,
                  record: np.ndarray | None = None) -> FlightInputs:
    """The profile's windows of one ingested flight (``arrays``: ingest.flight's), or a refusal; ``record``:
    a reference profile's vehicle record (core/vehicle_record.py; None: the flight is read without one)."""
    where = str(arrays["log_file"])
    if not uses_hover(profile):
        raise QuadfdiError(f"{where}: profile {profile!r} is the simulator's telemetry (motor temperatures, "
                           "thrust-fraction commands): train with --set train.profile=flightlog-min for real flights")
    fr = flight_raw(arrays, profile)
    airborne, est = np.asarray(arrays["airborne"], bool), fr.hover
    x = apply_profile(profile, fr.raw, fr.cells, est.cmd, est.cur, fr.available, record)
    t = len(airborne)
    starts = np.arange(0, t - window + 1, stride, dtype=np.int64) if t >= window else np.zeros(0, np.int64)
    ok = fr.used & airborne & np.isfinite(x).all(axis=1)
    cs = np.concatenate([[0], np.cumsum(ok)])
    decided = (starts + window - 1 >= est.freeze) & (cs[starts + window] - cs[starts] == window)
    if not decided.any():
        raise QuadfdiError(f"{where}: too short: no window of {window} samples ({window * 0.04:.1f} s) with every "
                           f"channel backed after the hover estimate froze at {arrays['time'][est.freeze]:.1f} s "
                           f"({float(airborne.sum()) * 0.04:.1f} s airborne){_gaps_hint(arrays, fr.raw, airborne, est)}")
    return FlightInputs(name=Path(where).name, time=np.asarray(arrays["time"], np.float64), x=x, used=ok,
                        starts=starts, decided=decided, hover=est, cells=fr.cells,
                        channel_names=channel_names(profile, []), airborne_s=float(airborne.sum()) * 0.04,
                        available=fr.available, absent=fr.absent)


def windows(fi: FlightInputs, window: int) -> np.ndarray:
    """(n_decided, W, C') float32: the decided windows (undecided ones are never run)."""
    s = fi.starts[fi.decided]
    return np.ascontiguousarray(fi.x[s[:, None] + np.arange(window)[None, :]], dtype=np.float32)
