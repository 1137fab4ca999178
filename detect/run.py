"""``quadfdi detect``: an exported model on one real flight -> per-window probabilities, the alarm
timeline under the policy (core.alarm) and the alarms (docs/detect.md).

Writes into OUT (only once everything is computed; a refusal writes nothing):
- ``alarms.json``: the flight, model, precision, runtime, profile, the net's policy and where it came
  from (``policy_source``: the manifest's ``alarm_per_model`` source, or "manifest alarm"), hover estimate,
  exposure (flight-seconds covered by decided windows) and the alarms (start_s, end_s, class,
  motor, peak_p_fault); ``alarm_reach`` (core.alarm.reach): whether the policy could raise at all on
  the flight's decided windows (``possible`` false: "no alarm" is then no verdict); a masked-profile
  model adds ``channels``: the raw channels ``used``, the ``absent`` ones with why (ingest's status)
  and the availability ``groups`` (detect/inputs.py);
  ``vehicle_reference``: null here, filled by detect.reference when a reference is given;
  ``model_reference``: whether the model read the vehicle record (a ``flightlog-ref`` model given a
  reference), decided without one, or reads none (another profile);
- ``windows.npz``: per window on the grid ``t_end``, ``decided``, ``proba`` (NaN if undecided),
  ``votes``, ``active``, ``cls`` (-1 inactive), ``class_names``, ``motor`` (int8, 1..4 or 0: detect.motor)
  and, for a model with a motor head, ``motor_proba`` (n, 4) float32 (NaN if undecided);
- ``detect.png``: the profile's channels, the availability mask, alarms shaded.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from quadfdi.core.alarm import alarm_records, reach, run_alarm
from quadfdi.core.errors import QuadfdiError
from quadfdi.core import vehicle_record as vr
from quadfdi.core.profiles import has_reference, required_raw
from quadfdi.core.resample import GRID_DT
from quadfdi.formats.flight import GRID_TOL_S, check_time
from quadfdi.detect.inputs import FlightInputs, flight_inputs, read_flight, windows
from quadfdi.detect.motor import window_motor
from quadfdi.formats.export_folder import Export


def softmax(logits: np.ndarray) -> np.ndarray:
    z = np.asarray(logits, np.float64)
    e = np.exp(z - z.max(axis=1, keepdims=True))
    return e / e.sum(axis=1, keepdims=True)


def model_logits(export: Export, net: str, precision: str, runtime: str,
                 x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(n, K) float32 logits of ``x`` from ORT (the exported graph) or the C++ reference (weights.bin),
    and (n, 4) motor logits for a model with a motor head (else None)."""
    from quadfdi.runtimes.fwref import cpp_outputs
    from quadfdi.runtimes.ort import outputs

    motor = export.has_motor(net)
    if runtime == "ort":
        out = outputs(export.artifact(net, precision), x, ["logits"] + (["motor_logits"] if motor else []))
        return out[0], out[1] if motor else None
    return cpp_outputs(export.weights_path, net, precision == "int8", x, motor)


def exposure_s(fi: FlightInputs, window: int, dt: float) -> float:
    """Flight-seconds covered by at least one decided window."""
    cover = np.zeros(len(fi.time), bool)
    for s in fi.starts[fi.decided]:
        cover[s:s + window] = True
    return float(cover.sum()) * dt


def detect(model: str | Path, flight: str | Path | dict, net: str = "cnode", precision: str = "fp32",
           runtime: str = "ort", vehicle: dict | None = None) -> dict:
    """Everything ``quadfdi detect`` writes, computed (nothing written): a dict with ``record``
    (alarms.json), ``arrays`` (windows.npz) and ``inputs`` (FlightInputs, for the figure).
    ``flight``: a log or flight.npz path, or flight.npz's arrays (sim.flight_npz.flight_arrays).
    ``vehicle``: the vehicle reference (vehicle.json's dict), read by a reference profile's model
    (``flightlog-ref``: its vehicle record, core/vehicle_record.py); other profiles never read it."""
    folder = Path(model)
    export = Export.open(folder)
    profile, window, stride, dt = export.profile(), export.window, export.stride, export.sample_dt_s
    if abs(dt - GRID_DT) > GRID_TOL_S:
        raise QuadfdiError(f"{folder}: the model reads samples every {dt:g} s; flights are on the {GRID_DT:g} s grid")
    names = export.class_names
    if "Healthy" not in names:
        raise QuadfdiError(f"{folder}: the model has no Healthy class ({names})")
    arrays = flight if isinstance(flight, dict) else read_flight(flight)
    check_time(arrays["time"], str(arrays.get("log_file", flight) if isinstance(flight, dict) else flight))
    reads = has_reference(profile)
    try:
        record = vr.from_reference(vehicle) if reads and vehicle is not None else None
    except ValueError as exc:
        raise QuadfdiError(f"vehicle reference refused: {exc}") from None
    fi = flight_inputs(arrays, profile, window, stride, record)
    if export.channel_names != fi.channel_names:
        raise QuadfdiError(f"{folder}: the manifest's channels are not profile {profile!r}'s")
    logits, motor_logits = model_logits(export, net, precision, runtime, windows(fi, window))
    n, k = len(fi.starts), len(names)
    proba = np.full((n, k), np.nan)
    proba[fi.decided] = softmax(logits)
    motor_p = None
    if motor_logits is not None:
        motor_p = np.full((n, 4), np.nan)
        motor_p[fi.decided] = softmax(motor_logits)
    pol, pol_source = export.policy(net)
    healthy = names.index("Healthy")
    p_in = np.where(fi.decided[:, None], proba, 0.0)
    p_in[~fi.decided, healthy] = 1.0  # undecided windows never vote (and are marked not valid)
    m_in = None if motor_p is None else np.where(fi.decided[:, None], motor_p, 0.0)  # undecided: never voting
    trace = run_alarm(p_in[None], pol["threshold"], pol["k"], pol["n"], pol["clear_m"], pol["latch"],
                      healthy=healthy, valid=fi.decided[None], motor_proba=None if m_in is None else m_in[None])
    t_end = fi.time[fi.starts + window - 1]
    rotor = export.rotor_side()
    alarms = alarm_records(trace, t_end[None], p_in[None], names, rotor=rotor)
    record = {"flight": fi.name, "model": str(folder), "net": net, "precision": precision, "runtime": runtime,
              "profile": profile, "policy": pol,
              "policy_source": pol_source,
              "hover": {"cmd": float(fi.hover.cmd),
                        "cur_a": None if not np.isfinite(fi.hover.cur) else float(fi.hover.cur),
                        "freeze_s": float(fi.time[fi.hover.freeze]), "cells": fi.cells},
              "airborne_s": round(fi.airborne_s, 2), "windows": int(n), "decided_windows": int(fi.decided.sum()),
              "exposure_s": round(exposure_s(fi, window, dt), 2), "alarms": alarms,
              "alarm_reach": reach(fi.decided, pol["k"], pol["n"], window, stride, dt),
              "vehicle_reference": None,  # detect.reference: what the vehicle's own healthy flights say
              "model_reference": ("reads the vehicle record" if record is not None else
                                  "no vehicle reference: the model decides without one" if reads else
                                  "the model's profile reads no vehicle reference")}
    if fi.available is not None:  # the masked profile: what the decision read and what it went without
        record["channels"] = {"used": [r for r in required_raw(profile) if r not in fi.absent],
                              "absent": dict(fi.absent), "groups": dict(fi.available)}
    arrays = {"t_end": t_end, "decided": fi.decided, "proba": proba.astype(np.float32), "votes": trace.votes[0],
              "active": trace.active[0], "cls": trace.cls[0], "class_names": np.array(names),
              "motor": window_motor(proba, motor_p, healthy, rotor)}
    if motor_p is not None:
        arrays["motor_proba"] = motor_p.astype(np.float32)
    return {"record": record, "arrays": arrays, "inputs": fi, "window": window}


def write_detect(out: str | Path, result: dict, log: Callable[[str], None] = print) -> None:
    from quadfdi.core.atomic import ensure_dir
    from quadfdi.core.jsonio import write_json
    from quadfdi.core.npzio import write_npz
    from quadfdi.detect.figure import draw

    folder = ensure_dir(out)
    draw(folder / "detect.png", result)
    write_npz(folder / "windows.npz", result["arrays"])
    write_json(folder / "alarms.json", result["record"], indent=2)
    rec = result["record"]
    log(f"detect: {rec['flight']}: {len(rec['alarms'])} alarm(s) over {rec['exposure_s']:.1f} s of decided flight "
        f"({rec['decided_windows']}/{rec['windows']} windows); wrote {folder / 'alarms.json'}")
