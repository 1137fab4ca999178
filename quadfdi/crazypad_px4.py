"""The scored network and policy, unchanged, on the shared healthy PX4 quad flights (``--logs``): no two
of them come from one vehicle, so each flight is its own reference. A flight is cut in time at the
sample where ``REFERENCE_FRACTION`` of its airborne samples lie before it: the first part (its
``flight.npz`` arrays up to the cut) is the reference's only flight (vehicle.learn), the rest is decided
with the reference and without it, scored by the four share rules against it, and its coverage by the
reference (vehicle/coverage.py: a first part that only took off and hovered does not cover a forward flight
after it). Both parts keep the flight's own time axis.

The UAVCAN mission, whose logger dropped messages, is read with its gaps bridged at
``MISSION_GAP_FACTOR`` x the median interval, as ``quadfdi real-flights`` reads it (docs/ingest.md, "Gaps").

A flight whose first part cannot give vehicle.learn's minimum (``MIN_AIRBORNE_S`` airborne) is refused in
one line as too short to split, as is one that ingest, learn or detect refuses; each is a line of the
table, not an error of the command.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.resample import GRID_DT
from quadfdi.vehicle.learn import MIN_AIRBORNE_S

REFERENCE_FRACTION = 0.4
GRID_KEYS = ("time", "telemetry", "mask", "airborne")  # the arrays with one row per 25 Hz grid sample


def _clip_segments(seg: np.ndarray, t0: float, t1: float) -> np.ndarray:
    s = np.asarray(seg, np.float64).reshape(-1, 2)
    s = np.clip(s, t0, t1)
    return s[s[:, 1] > s[:, 0]]


def cut(arrays: dict, lo: int, hi: int) -> dict:
    """flight.npz arrays ``[lo, hi)`` of the grid: grid rows sliced, each raw channel kept within the part's
    span (half a grid step either side), the airborne and armed intervals clipped to it."""
    t = np.asarray(arrays["time"], np.float64)
    t0, t1 = t[lo] - GRID_DT / 2, t[hi - 1] + GRID_DT / 2
    out = {}
    for key, v in arrays.items():
        if key in GRID_KEYS:
            out[key] = v[lo:hi]
        elif key.startswith("raw.") and key.endswith(".t"):
            keep = (v >= t0) & (v <= t1)
            out[key], out[key[:-2] + ".v"] = v[keep], arrays[key[:-2] + ".v"][keep]
        elif key.startswith("raw.") and key.endswith(".v"):
            continue
        elif key in ("airborne_segments", "armed_segments"):
            out[key] = _clip_segments(v, t0, t1)
        else:
            out[key] = v
    return out


def split(arrays: dict, name: str, fraction: float = REFERENCE_FRACTION) -> tuple[dict, dict, dict]:
    """(first part, rest, where it was cut) of one flight; one-line QuadfdiError when too short to split."""
    air = np.flatnonzero(np.asarray(arrays["airborne"], bool))
    total = len(air) * GRID_DT
    need = MIN_AIRBORNE_S / fraction
    if len(air) == 0 or fraction * total < MIN_AIRBORNE_S:
        raise QuadfdiError(f"{name}: {total:.1f} s airborne, too short to split: the reference's {fraction:.0%} must "
                           f"hold vehicle.learn's {MIN_AIRBORNE_S:g} s (at least {need:.0f} s airborne)")
    k = int(math.ceil(fraction * len(air)))
    at = int(air[k])
    t = np.asarray(arrays["time"], np.float64)
    info = {"cut_s": round(float(t[at]), 2), "airborne_s": round(total, 2),
            "reference_airborne_s": round(k * GRID_DT, 2), "test_airborne_s": round((len(air) - k) * GRID_DT, 2),
            "fraction": fraction}
    return cut(arrays, 0, at), cut(arrays, at, len(t)), info


def one_flight(export: str, net: str, path: Path, fraction: float = REFERENCE_FRACTION) -> dict:
    """One shared log: split, reference learned from its first part, the rest decided with and without it
    and scored by the rules; ``refused`` (one line) instead when any step refuses."""
    from quadfdi.crazypad_decide import decide_one
    from quadfdi.vehicle.coverage import coverage
    from quadfdi.vehicle.flights import Flight, read_flight
    from quadfdi.vehicle.learn import learn
    from quadfdi.vehicle.rules import score_flight, thresholds

    from quadfdi.real_flights_detect import MISSION, MISSION_GAP_FACTOR

    name = path.stem
    gap = MISSION_GAP_FACTOR if path.name == MISSION else None
    try:
        fl = read_flight(path, name, gap)
        head, tail, info = split(fl.arrays, name, fraction)
        info["gap_factor"] = gap
        ref = learn([Flight(f"{name} (first {fraction:.0%})", path, fl.sha256, head)])
        test = Flight(f"{name} (rest)", path, fl.sha256, tail)
        row = score_flight(test, ref, thresholds(ref))
        shares = {m["log_motor"]: m["mean"] for m in ref["motor_share"]}
        out = {"flight": name, "split": info, "reference_shares": shares, "test_shares": row["shares"],
               "rules": row["rules"], "coverage": coverage(test, ref)}
        for mode, r in (("net_ref", ref), ("net_noref", None)):
            out[mode] = decide_one(export, net, test, r)
        return out
    except QuadfdiError as exc:
        return {"flight": name, "refused": " ".join(str(exc).split())}


def px4_part(export: str, net: str, logs: Path, names: tuple[str, ...], fraction: float = REFERENCE_FRACTION,
             log=print) -> dict:
    """Every log of ``names`` (file names) found in ``logs``; those absent are named in ``absent``."""
    found = [logs / n for n in names if (logs / n).is_file()]
    log(f"crazypad: {len(found)} shared PX4 flights in {logs}, reference from the first {fraction:.0%} of each")
    return {"logs": str(logs), "fraction": fraction, "flights": [one_flight(export, net, p, fraction) for p in found],
            "absent": [n for n in names if not (logs / n).is_file()]}
