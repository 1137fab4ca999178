"""The shared real quad logs of ``quadfdi real-flights`` (quadfdi/real_flights.py, step 4): every log
ingested once into ``OUT/flights/ingest/<flight>``, then ``quadfdi detect`` with each profile's export,
both networks, both runtimes (ort, cpp) and both precisions into
``OUT/flights/<P>/<flight>/<net>/<runtime>/<precision>/`` (the flightlog-esc model only on logs with
ESC telemetry: it refuses the others); the UAVCAN mission again with the gap rule bridged at 7 x the
median interval (``OUT/flights_gap7``).
"""

from __future__ import annotations

import shutil
from pathlib import Path

from quadfdi.core.errors import QuadfdiError

ESC_LOGS = {"px4_quad_6s_uavcan_mission.ulg", "px4_quad_6s_vibration_tipover.ulg", "px4_sitl_quad_esc.ulg"}
MISSION = "px4_quad_6s_uavcan_mission.ulg"
MISSION_GAP_FACTOR = 7.0  # the mission's logging gaps: bridged up to 7 x the median interval
CASES = tuple((net, rt, pr) for net in ("cnode", "gru") for rt in ("ort", "cpp") for pr in ("fp32", "int8"))
# The shared real flights of a vehicle without a fault (the battery-monitor flight: a sensing fault, the
# vehicle healthy; the vibration tip-over and the SITL log are not counted).
HEALTHY = ("px4_quad_6s_uavcan_mission", "px4_quad_6s_gps_interference", "px4_fmuv5_quad_real_short",
           "px4_quad_battery_monitor_disconnected")


def one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def detect_shared(out: Path, exports: dict[str, Path], logs: Path, names: list[str], profiles: dict[str, str]) -> dict:
    """``flights`` (every log, default gap rule) and ``flights_gap7`` (the mission bridged), each a
    list of ``detect_all``'s cases; ``profiles``: export key -> profile name."""
    return {"flights": detect_all(out / "flights", exports, logs, names, profiles),
            "flights_gap7": detect_all(out / "flights_gap7", exports, logs, [n for n in names if n == MISSION],
                                       profiles, MISSION_GAP_FACTOR),
            "gap_factor": MISSION_GAP_FACTOR, "healthy": list(HEALTHY)}


def _ingest(log: Path, out: Path, gap: float | None) -> tuple[Path | None, str | None]:
    """(flight.npz, None) or (None, ingest's one-line refusal)."""
    from quadfdi.core.jsonio import write_json
    from quadfdi.core.resample import GAP_FACTOR
    from quadfdi.formats.flight import write_flight
    from quadfdi.ingest import segments
    from quadfdi.ingest.cli import summary
    from quadfdi.ingest.flight import ingest

    shutil.rmtree(out, ignore_errors=True)
    try:
        lr, arrays = ingest(str(log), segments.MIN_AIRBORNE_S, GAP_FACTOR if gap is None else gap)
    except QuadfdiError as exc:
        return None, one_line(exc)
    write_flight(out / "flight.npz", arrays)
    write_json(out / "ingest.json", summary(lr, arrays))
    return out / "flight.npz", None


def detect_all(out: Path, exports: dict[str, Path], logs: Path, names: list[str], profiles: dict[str, str],
               gap: float | None = None) -> list[dict]:
    """Every case (module docstring) of every log: one dict each, with ``record`` (what alarms.json
    holds) or ``refused`` (the one-line reason)."""
    from quadfdi.detect.run import detect, write_detect

    results = []
    for name in names:
        stem = name.split(".")[0]
        flight, refused = _ingest(logs / name, out / "ingest" / stem, gap)
        for prof, export in exports.items():
            if prof == "esc" and name not in ESC_LOGS:
                continue
            shutil.rmtree(out / prof / stem, ignore_errors=True)
            for net, rt, pr in CASES:
                case = {"profile": profiles[prof], "flight": stem, "net": net, "runtime": rt, "precision": pr}
                if flight is None:
                    case["refused"] = f"ingest: {refused}"
                else:
                    try:
                        result = detect(export, flight, net, pr, rt)
                        write_detect(out / prof / stem / net / rt / pr, result, log=lambda _: None)
                        case["record"] = result["record"]
                    except QuadfdiError as exc:
                        case["refused"] = one_line(exc)
                print(prof, stem, net, rt, pr, "refused: " + case["refused"][:160] if "refused" in case else "ok",
                      flush=True)
                results.append(case)
    return results
