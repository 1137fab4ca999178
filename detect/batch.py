"""``quadfdi detect`` on many logs at once: every log given and every log found in a folder given
(detect.logfiles), each ingested, decided and written into its own folder ``DIR/<flight>/``
(``alarms.json``, ``windows.npz``, ``evidence.json``, ``index.html``), flights in parallel worker
processes; then ``DIR/summary.json``, the fleet index ``DIR/index.html`` and the plotting library
``DIR/plotly.min.js`` that every page shares.

A log that cannot be read or decided is refused with its one-line reason (in the summary and the
index) and the others go on. The exit status says what a script over a fleet needs to know
(``EXIT``): 0 no alarm on any decided flight, 1 an alarm on at least one, 3 some logs refused and no
alarm, 4 an alarm and some logs refused; 2 (the CLI's) a bad usage or a one-line error, with nothing
written.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.vehicle.coverage import LIMIT

EXIT = {0: "no alarm on any decided flight", 1: "an alarm raised", 3: "some logs refused, no alarm",
        4: "an alarm raised and some logs refused"}
SPARK_POINTS = 120


@dataclass(frozen=True)
class Job:
    log: str
    name: str
    model: str
    net: str
    precision: str
    runtime: str
    out: str  # the fleet folder
    reference: object = None  # detect.reference.Reference or None
    reference_note: str | None = None  # why there is none


def exit_status(rows: list[dict], refused: list[dict]) -> int:
    alarm = any(r["alarms"] for r in rows)
    return (4 if alarm else 3) if refused else (1 if alarm else 0)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def spark(arrays: dict) -> list[list]:
    """[[t_end, p_fault or None]] over the flight: at most SPARK_POINTS, each the maximum of its
    bucket of windows (a short spike stays visible); None where no window of the bucket decided."""
    t = np.asarray(arrays["t_end"], np.float64)
    names = [str(c) for c in arrays["class_names"]]
    p = 1.0 - np.asarray(arrays["proba"], np.float64)[:, names.index("Healthy")]
    edges = np.linspace(0, len(t), min(len(t), SPARK_POINTS) + 1).astype(int)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        seg = p[a:b]
        best = float(np.nanmax(seg)) if np.isfinite(seg).any() else None
        out.append([round(float(t[b - 1]), 2), None if best is None else round(best, 4)])
    return out


def summary_row(result: dict, flight: dict, date: str | None, name: str, log: str) -> dict:
    from quadfdi.detect.page import vehicle_facts
    from quadfdi.detect.reference import summary as reference_summary

    rec, arr = result["record"], result["arrays"]
    time = np.asarray(flight["time"], np.float64)
    names = [str(c) for c in arr["class_names"]]
    p_fault = 1.0 - np.asarray(arr["proba"], np.float64)[:, names.index("Healthy")]
    worst = float(np.nanmax(p_fault)) if np.isfinite(p_fault).any() else math.nan
    veh = vehicle_facts(flight)
    return {"name": name, "log": log, "href": f"{name}/index.html", "date": date,
            "vehicle": {k: veh[k] for k in ("autopilot", "frame", "cells")},
            "duration_s": round(float(time[-1] - time[0]), 2), "airborne_s": rec["airborne_s"],
            "decided_s": rec["exposure_s"], "windows": rec["windows"], "decided_windows": rec["decided_windows"],
            "channels_absent": list(rec.get("channels_absent") or []),
            "alarms": [{k: a.get(k) for k in ("class", "motor", "start_s", "end_s", "peak_p_fault")}
                       for a in rec["alarms"]],
            "worst_p_fault": round(worst, 4), "alarm_possible": rec["alarm_reach"]["possible"],
            "threshold": float(rec["policy"]["threshold"]),
            "t0": float(time[0]), "t1": float(time[-1]), "spark": spark(arr),
            "vehicle_reference": reference_summary(rec.get("vehicle_reference")),
            "reference_note": result.get("reference_note")}


def decide_flight(log: str | Path | dict, model: str, net: str, precision: str, runtime: str,
                  reference=None, reference_note: str | None = None) -> tuple:
    """(detect result, flight arrays, evidence, date) of one log, flight.npz or flight arrays, read beside
    ``reference`` (detect.reference.Reference; a reference of another vehicle refuses the flight first)."""
    from quadfdi.detect.evidence import occlusion
    from quadfdi.detect.inputs import read_flight
    from quadfdi.detect.logfiles import log_date
    from quadfdi.detect.reference import NO_REFERENCE, add_to_evidence, apply
    from quadfdi.detect.run import detect
    from quadfdi.formats.export_folder import Export

    flight = log if isinstance(log, dict) else read_flight(log)
    ref_record, series = None, None
    if reference is not None:
        ref_record, series = apply(flight, reference, str(flight["log_file"]) if isinstance(log, dict) else log)
    result = detect(model, flight, net, precision, runtime, None if reference is None else reference.data)
    result["record"]["vehicle_reference"] = ref_record
    result["vehicle_series"], result["reference_note"] = series, None if series else reference_note or NO_REFERENCE
    evidence = occlusion(result, flight, Export.open(model), net, precision)
    add_to_evidence(evidence, series, flight["time"])
    date = None if isinstance(log, dict) else log_date(Path(log))
    return result, flight, evidence, date


def write_flight_folder(folder: Path, result: dict, flight: dict, evidence: list[dict], date: str | None,
                        script_src: str, index_href: str | None) -> None:
    """``evidence.json`` and the page ``index.html`` of one flight (alarms.json and windows.npz are
    detect.run's, written by the caller)."""
    from quadfdi.core.atomic import write_text
    from quadfdi.core.jsonio import write_json
    from quadfdi.detect.page import flight_page

    write_json(folder / "evidence.json", {"alarms": evidence}, indent=2)
    write_text(folder / "index.html", flight_page(result, flight, evidence, date, script_src, index_href))


def run_job(job: Job) -> dict:
    """One flight of a fleet, in a worker process: its summary row, or its refusal."""
    try:
        from quadfdi.core.atomic import ensure_dir
        from quadfdi.core.jsonio import write_json
        from quadfdi.core.npzio import write_npz

        result, flight, evidence, date = decide_flight(job.log, job.model, job.net, job.precision, job.runtime,
                                                       job.reference, job.reference_note)
        folder = ensure_dir(Path(job.out) / job.name)
        write_npz(folder / "windows.npz", result["arrays"])
        write_json(folder / "alarms.json", result["record"], indent=2)
        write_flight_folder(folder, result, flight, evidence, date, "../plotly.min.js", "../index.html")
        return summary_row(result, flight, date, job.name, job.log)
    except QuadfdiError as exc:
        return {"refused": True, "log": job.log, "name": job.name, "reason": _one_line(exc)}
    except (MemoryError, KeyboardInterrupt):
        raise
    except Exception as exc:  # noqa: BLE001 (a reader's own exception on a damaged log: this log only)
        return {"refused": True, "log": job.log, "name": job.name, "reason": f"{type(exc).__name__}: {_one_line(exc)}"}


def in_workers(fn: Callable, jobs: list[tuple], workers: int):
    """``fn(*job)`` for every job, in this process (``workers`` <= 1) or in worker processes (results in
    completion order): one log per job, so a reader's crash or a slow log stays that job's."""
    if workers <= 1 or len(jobs) <= 1:
        for job in jobs:
            yield fn(*job)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    ctx = mp.get_context("forkserver")  # no fork of a parent's threads; the server pre-imports once
    ctx.set_forkserver_preload(["quadfdi.detect.run", "quadfdi.ingest.flight", "quadfdi.runtimes.ort"])
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        for fut in as_completed([pool.submit(fn, *job) for job in jobs]):
            yield fut.result()


def _results(jobs: list[Job], workers: int, progress: bool):
    from tqdm import tqdm

    bar = tqdm(total=len(jobs), desc="detect", unit="log", disable=None if progress else True)  # None: a terminal only
    try:
        for result in in_workers(run_job, [(j,) for j in jobs], workers):
            yield result
            bar.update()
    finally:
        bar.close()


def detect_many(model: str | Path, logs: list[str | Path], out: str | Path, net: str = "cnode",
                precision: str = "fp32", runtime: str = "ort", workers: int | None = None,
                log: Callable[[str], None] = print, progress: bool = True, refs=None) -> dict:
    """Detect every log of ``logs`` (files or folders) into ``out``, each beside the reference ``refs``
    (detect.reference.References) gives it; the summary (also ``out/summary.json``), whose
    ``exit_status`` is the command's."""
    from quadfdi.core.atomic import ensure_dir, write_text
    from quadfdi.core.jsonio import write_json
    from quadfdi.detect.html import write_plotly_js
    from quadfdi.detect.index_page import index_page
    from quadfdi.detect.logfiles import find_logs
    from quadfdi.formats.export_folder import Export

    export = Export.open(model)  # a bad export is one line before anything is written
    if runtime == "cpp":  # built once here (locked), so that the workers find it built
        from quadfdi.runtimes.build import build_host

        build_host(log=lambda _: None)
    for p in logs:
        if not Path(p).exists():
            raise QuadfdiError(f"{p} does not exist")
    found = find_logs(logs)
    if not found:
        raise QuadfdiError(f"no flight log in {', '.join(str(p) for p in logs)} (PX4 ULog, ArduPilot DataFlash, "
                           "Crazyflie uSD or flight.npz, known by their first bytes)")
    folder = ensure_dir(out)
    write_plotly_js(folder)
    from quadfdi.detect.reference import References

    refs = refs or References()
    jobs = [Job(str(f), name, str(model), net, precision, runtime, str(folder), *refs.for_log(f)) for f, name in found]
    workers = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
    rows, refused = [], []
    for r in _results(jobs, workers, progress):
        (refused if r.get("refused") else rows).append(r)
    order = {j.name: i for i, j in enumerate(jobs)}
    rows.sort(key=lambda r: order[r["name"]])
    refused = sorted(({k: r[k] for k in ("log", "name", "reason")} for r in refused), key=lambda r: order[r["name"]])
    code = exit_status(rows, refused)
    summary = {"model": {"export": str(model), "net": net, "precision": precision, "runtime": runtime,
                         "profile": export.profile()},
               "exit_status": code, "exit_meaning": EXIT[code], "flights": rows, "refused": refused}
    write_json(folder / "summary.json", summary, indent=1)
    write_text(folder / "index.html", index_page(summary))
    n_alarm = sum(1 for r in rows if r["alarms"])
    log(f"detect: {len(jobs)} log(s): {len(rows)} decided ({n_alarm} with alarms), {len(refused)} refused; "
        f"wrote {folder / 'index.html'}")
    blind = [r for r in rows if not r["alarm_possible"]]
    if blind:
        log(f"detect: {len(blind)} of {len(rows)} decided flight(s) too short in decided windows for the policy to "
            "raise any alarm (alarms.json alarm_reach): their 'no alarm' is no verdict")
    without = [r for r in rows if r["vehicle_reference"] is None]
    if without:
        log(f"detect: {len(without)} of {len(rows)} decided flight(s) with no vehicle reference: the model judges "
            "them against the simulated vehicles")
    beyond = [r for r in rows if (r["vehicle_reference"] or {}).get("beyond")]
    if beyond:
        log(f"detect: {len(beyond)} of {len(rows)} decided flight(s) fly a forward speed or yaw rate past their "
            f"reference flights' on more than {LIMIT:.0%} of their airborne samples (the index's 'outside "
            "reference'): their share deviations are partly the reference's extrapolation")
    return summary
