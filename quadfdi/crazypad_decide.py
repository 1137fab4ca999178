"""Every CrazyPAD log of ``quadfdi crazypad`` decided: the scored network (ONNX Runtime, fp32) with the
vehicle reference and without it, and the four share rules (vehicle/rules.py, thresholds as they are),
one log per job, in ``workers`` processes.

A flight's network result in each mode (``net_ref``, ``net_noref``) has the same shape as a rule's
(``score``: the flight's largest p(fault) = 1 - p(Healthy) over its decided windows; ``alarm``: any
alarm under the policy; ``motor``: the first alarm's motor that names one, as the log names it, the
project rotor traced back through ingest's ``motor_map``), so vehicle.crazypad.table scores networks and
rules alike; beside it the alarms (class, log motor, start), the mean p(fault) over the decided windows
and their count, the windows that voted, and whether the policy could raise at all on the flight's decided
windows (``alarm_possible``, ``most_votes``: core.alarm.reach). A log ingest or detect refuses, or without a
decided window, is a refusal line.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError

MODES = {"net_ref": "with the reference", "net_noref": "without the reference"}


def log_motor_names(arrays: dict) -> list[str]:
    """The log's name of project rotor k (k = 0..3): ``log_motor_names[motor_map[k]]`` (ingest's vehicle
    record; M1..M4 for a log that names none)."""
    import json

    veh = json.loads(str(arrays["vehicle"]))
    names = list(veh.get("log_motor_names") or [f"M{i + 1}" for i in range(4)])
    return [names[m] for m in veh["motor_map"]]


def network_result(result: dict, names: list[str]) -> dict:
    """One flight's network outcome (module docstring) from detect.run.detect's ``result``."""
    rec, arr = result["record"], result["arrays"]
    decided = np.asarray(arr["decided"], bool)
    if not decided.any():
        raise QuadfdiError(f"{rec['flight']}: no decided window ({rec['windows']} windows)")
    healthy = [str(c) for c in arr["class_names"]].index("Healthy")
    pf = 1.0 - np.asarray(arr["proba"], np.float64)[decided, healthy]
    alarms = [{"class": a["class"], "motor": None if a["motor"] is None else names[a["motor"] - 1],
               "start_s": a["start_s"], "peak_p_fault": a["peak_p_fault"]} for a in rec["alarms"]]
    named = next((a["motor"] for a in alarms if a["motor"] is not None), None)
    votes = int((pf >= float(rec["policy"]["threshold"])).sum())
    return {"score": float(pf.max()), "alarm": bool(alarms), "motor": named, "alarms": alarms,
            "alarm_possible": bool(rec["alarm_reach"]["possible"]), "most_votes": rec["alarm_reach"]["most_votes"],
            "votes": votes,
            "p_fault_sum": float(pf.sum()), "mean_p_fault": float(pf.mean()), "decided_windows": int(decided.sum()),
            "windows": int(rec["windows"]), "exposure_s": rec["exposure_s"]}


def decide_one(export: str, net: str, fl, reference: dict | None) -> dict:
    """The network, under the policy the export runs for it, on one flight (vehicle.flights.Flight) with
    ``reference`` (None: without)."""
    from quadfdi.detect.run import detect

    return network_result(detect(export, fl.arrays, net, "fp32", "ort", vehicle=reference),
                          log_motor_names(fl.arrays))


def decide_log(export: str, net: str, path: str, name: str, reference: dict, limits: dict) -> dict:
    """One log (a job): its rules row (vehicle.rules.score_flight) with ``net_ref`` and ``net_noref`` added
    to its ``rules``, or ``{"flight", "refused"}`` with the one-line reason."""
    from quadfdi.vehicle.flights import read_flight
    from quadfdi.vehicle.rules import score_flight

    try:
        fl = read_flight(path, name)
        row = score_flight(fl, reference, limits)
        for mode, ref in (("net_ref", reference), ("net_noref", None)):
            try:
                row["rules"][mode] = decide_one(export, net, fl, ref)
            except QuadfdiError as exc:
                raise QuadfdiError(f"{name}, the network {MODES[mode]}: {exc}") from None
    except QuadfdiError as exc:
        return {"flight": name, "path": path, "refused": " ".join(str(exc).split())}
    except Exception as exc:  # noqa: BLE001 (a reader's own exception on a damaged log: this log only)
        return {"flight": name, "path": path, "refused": f"{type(exc).__name__}: {' '.join(str(exc).split())}"}
    row["path"] = path
    return row


def _run(jobs: list[tuple], workers: int):
    from quadfdi.detect.batch import in_workers

    yield from in_workers(decide_log, jobs, workers)


def decide_all(export: str, net: str, found: list[tuple[Path, str]], reference: dict, workers: int,
               log=print) -> dict:
    """Every (path, name) of ``found`` decided (module docstring), in ``found``'s order: ``rows`` (the
    decided, labelled by vehicle.crazypad.label), ``refused``, the wall time and the worker processes."""
    from quadfdi.vehicle import crazypad
    from quadfdi.vehicle.rules import thresholds

    limits = thresholds(reference)
    jobs = [(export, net, str(p), name, reference, limits) for p, name in found]
    workers = max(1, min(int(workers), len(jobs)))
    log(f"crazypad: {len(jobs)} logs, {net} (ONNX Runtime fp32) with and without the reference, in {workers} "
        "worker process(es)")
    t0, got = time.monotonic(), []
    for i, row in enumerate(_run(jobs, workers), 1):
        got.append(row)
        if i % 25 == 0 or i == len(jobs):
            log(f"crazypad: {i}/{len(jobs)} logs")
    order = {str(p): i for i, (p, _) in enumerate(found)}
    got.sort(key=lambda r: order[r["path"]])
    rows = [r for r in got if "refused" not in r]
    crazypad.label(rows, [Path(r["path"]) for r in rows], reference)
    return {"rows": rows, "refused": [r for r in got if "refused" in r], "limits": limits,
            "wall_s": round(time.monotonic() - t0, 1), "workers": workers}
