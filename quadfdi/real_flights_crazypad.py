"""The CrazyPAD logs of ``quadfdi real-flights`` (quadfdi/real_flights.py, step 4): every Crazyflie log
under ``--crazypad`` (one folder per condition, found by content: detect.logfiles) read once and
decided by the masked export with both networks, both runtimes and both precisions, one log per
worker process; each case's alarms.json in ``OUT/crazypad/<condition>/<log>/<net>/<runtime>/<precision>/``.
Only the masked profile decides them: the fixed profiles need pitch, which no Crazyflie log has.

A condition folder belongs to one group of the CrazyPAD README (``group_of``): healthy, motor 3's
propeller cut (by the deepest cut of a blade), two damaged propellers, debris, added mass, swinging
load. The logs come from two sessions (``E8_``, ``E9_`` file prefixes) that the README says to keep apart.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.real_flights_detect import CASES, one_line

GROUP_ORDER = ("healthy", "M3 cut", "two damaged propellers", "debris (tape)", "added mass", "swinging load")
PROFILE = "flightlog-mask"


def group_of(folder: str) -> str:
    """The README group of a condition folder; motor 3's cuts by the deepest cut of a blade, in mm
    (``cut_propeller_M3_2mm_1.5mm_43.5mm``: 2 mm; the last number over 10 mm is the length left)."""
    if folder == "normal_flight":
        return "healthy"
    m = re.fullmatch(r"cut_(?:propeller_)?[Mm]3_(.+)", folder)
    if m:
        cuts = [float(v) for v in re.findall(r"(\d+(?:\.\d+)?)mm", m.group(1)) if float(v) < 10.0]
        return f"M3 cut {max(cuts):g} mm" if cuts else "M3 cut"
    for prefix, group in (("cut_M2_", "two damaged propellers"), ("tape_on_propeller_", "debris (tape)"),
                          ("add_weight_", "added mass"), ("weight_on_string_", "swinging load")):
        if folder.startswith(prefix):
            return group
    return folder


def group_key(group: str) -> tuple:
    """Table order: GROUP_ORDER, motor 3's cuts by depth, unknown folders last by name."""
    for i, g in enumerate(GROUP_ORDER):
        if group == g or group.startswith(g + " "):
            depth = re.findall(r"(\d+(?:\.\d+)?) mm", group)
            return i, float(depth[0]) if depth else 0.0, group
    return len(GROUP_ORDER), 0.0, group


def _trim(record: dict, motor_names: list[str] | None) -> dict:
    """What the tables read of an alarms.json record; each alarm's motor also by the log's own name
    (the Crazyflie's M1-M4 through ingest's motor_map)."""
    alarms = []
    for a in record["alarms"]:
        a = {k: a[k] for k in ("class", "motor", "start_s", "end_s", "peak_p_fault")}
        a["log_motor"] = None if a["motor"] is None or motor_names is None else motor_names[a["motor"] - 1]
        alarms.append(a)
    return {"airborne_s": record["airborne_s"], "windows": record["windows"],
            "decided_windows": record["decided_windows"], "exposure_s": record["exposure_s"], "alarms": alarms,
            "channels_absent": sorted(record.get("channels", {}).get("absent", {}))}


def _motor_names(flight: dict) -> list[str] | None:
    try:
        veh = json.loads(str(flight["vehicle"]))
        return [veh["log_motor_names"][i] for i in veh["motor_map"]]
    except (KeyError, IndexError, TypeError, ValueError):
        return None


def decide_log(export: str, log: str, rel: str, out: str, profile: str = PROFILE) -> list[dict]:
    """The eight cases of one log (a job of a worker process): each with ``record`` (trimmed) or
    ``refused`` (the one-line reason; a log that cannot be read refuses every case)."""
    from quadfdi.core.atomic import ensure_dir
    from quadfdi.core.jsonio import write_json
    from quadfdi.detect.inputs import read_flight
    from quadfdi.detect.run import detect

    folder = Path(rel).parts[0] if len(Path(rel).parts) > 1 else ""
    base = {"profile": profile, "flight": rel, "group": group_of(folder), "session": Path(rel).name.split("_")[0]}
    try:
        flight, why = read_flight(log), None
    except QuadfdiError as exc:
        flight, why = None, f"ingest: {one_line(exc)}"
    except Exception as exc:  # noqa: BLE001 (a reader's own exception on a damaged log: this log only)
        flight, why = None, f"ingest: {type(exc).__name__}: {one_line(exc)}"
    names = None if flight is None else _motor_names(flight)
    cases = []
    for net, rt, pr in CASES:
        case = dict(base, net=net, runtime=rt, precision=pr)
        if flight is None:
            case["refused"] = why
        else:
            try:
                result = detect(export, flight, net, pr, rt)
                write_json(ensure_dir(Path(out) / rel / net / rt / pr) / "alarms.json", result["record"], indent=2)
                case["record"] = _trim(result["record"], names)
            except QuadfdiError as exc:
                case["refused"] = one_line(exc)
        cases.append(case)
    return cases


def _run(jobs: list[tuple], workers: int):
    from quadfdi.detect.batch import in_workers

    yield from in_workers(decide_log, jobs, workers)


def detect_crazypad(out: Path, export: Path, root: Path, workers: int, profile: str = PROFILE) -> dict:
    """Every log under ``root`` (module docstring; ``profile``: the export's, as the cases name it):
    ``cases`` (flat, in log order), the wall time and the worker processes."""
    import shutil

    from quadfdi.detect.logfiles import find_logs
    from quadfdi.runtimes.build import build_host

    build_host(log=lambda _: None)  # built (locked) once here, so that the workers find it built
    found = [f for f, _ in find_logs([root])]
    if not found:
        raise QuadfdiError(f"--crazypad {root}: no Crazyflie log in it")
    shutil.rmtree(out, ignore_errors=True)
    jobs = [(str(export), str(f), f.relative_to(root).as_posix(), str(out), profile) for f in found]
    workers = max(1, min(int(workers), len(jobs)))
    print(f"real-flights: {len(jobs)} CrazyPAD logs x {len(CASES)} cases in {workers} worker process(es)", flush=True)
    t0, cases = time.monotonic(), []
    for i, got in enumerate(_run(jobs, workers), 1):
        cases += got
        if i % 20 == 0 or i == len(jobs):
            print(f"real-flights: CrazyPAD {i}/{len(jobs)} logs", flush=True)
    order = {j[2]: i for i, j in enumerate(jobs)}
    cases.sort(key=lambda c: order[c["flight"]])  # workers finish in any order: the cases in log order
    return {"root": str(root), "logs": len(jobs), "workers": workers, "wall_s": round(time.monotonic() - t0, 1),
            "cases": cases}
