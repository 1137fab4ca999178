"""One export on every shared real quad log and every CrazyPAD log, both networks, both runtimes, both
precisions, as ``quadfdi real-flights`` runs the realistic suite's exports (the same detect passes and
tables: quadfdi/real_flights_detect.py, real_flights_crazypad.py, real_flights_table.py), without
simulating or training anything: for an export made elsewhere (the fleet run's).

    python lab/export_real_flights.py EXPORT OUT [--logs DIR] [--crazypad DIR] [--workers N]

Writes OUT/export_real_flights.md and .json: the shared logs' table and refusals, the UAVCAN mission
again with its logging gaps bridged (7 x the median interval), the seconds decided on the three
healthy flights the decided-coverage goal counts (GPS interference, the bridged mission, battery monitor
disconnected) against their airborne seconds, every alarm on a healthy flight, the C++-against-ONNX
Runtime and int8-against-fp32 disagreements, and the CrazyPAD groups.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from quadfdi.formats.export_folder import Export
from quadfdi.real_flights import LOGS
from quadfdi.real_flights_crazypad import detect_crazypad
from quadfdi.real_flights_detect import MISSION, detect_shared
from quadfdi.real_flights_report import agreement_summary, crazypad_summary
from quadfdi.real_flights_table import healthy_lines, table

COVERAGE = ("px4_quad_6s_gps_interference", "px4_quad_6s_uavcan_mission (gaps bridged)",
            "px4_quad_battery_monitor_disconnected")


def coverage_lines(cases: list[dict]) -> list[str]:
    """Seconds decided (exposure) against airborne seconds on the COVERAGE flights, CNODE ORT fp32."""
    lines, dec, air = [], 0.0, 0.0
    for c in cases:
        if (c["net"], c["runtime"], c["precision"]) != ("cnode", "ort", "fp32") or c["flight"] not in COVERAGE:
            continue
        if "record" not in c:
            lines.append(f"- {c['flight']}: refused: {c['refused']}")
            continue
        r = c["record"]
        dec, air = dec + r["exposure_s"], air + r["airborne_s"]
        lines.append(f"- {c['flight']}: {r['exposure_s']:.1f} of {r['airborne_s']:.1f} s airborne decided "
                     f"({r['decided_windows']} of {r['windows']} windows), alarms: {len(r['alarms'])}")
    return lines + [f"- together: {dec:.1f} of {air:.1f} airborne seconds decided"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("export")
    ap.add_argument("out")
    ap.add_argument("--logs", default="../shared/data/flightlogs")
    ap.add_argument("--crazypad", default="../shared/data/crazypad/motor_data")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    export, out, logs = Path(a.export).resolve(), Path(a.out), Path(a.logs)
    profile = Export.open(export).profile()
    t0 = time.monotonic()
    shared = detect_shared(out, {"export": export}, logs, [n for n in LOGS if (logs / n).exists()],
                           {"export": profile})
    bridged = [dict(c, flight=f"{c['flight']} (gaps bridged)") for c in shared["flights_gap7"]]
    cp = detect_crazypad(out / "crazypad", export, Path(a.crazypad), a.workers, profile)
    cases = shared["flights"] + bridged
    text = [f"# {export} on the shared logs and CrazyPAD", "",
            f"`python lab/export_real_flights.py {a.export} {a.out} --logs {a.logs} --crazypad {a.crazypad} "
            f"--workers {a.workers}`: {time.monotonic() - t0:.0f} s", "", "## Shared logs", "", table(cases), "",
            f"The {MISSION} again with its gaps bridged at {shared['gap_factor']:g} x the median interval.", "",
            "Decided on the three healthy flights the coverage goal counts (CNODE, ONNX Runtime fp32):", ""]
    text += coverage_lines(cases) + ["", "Healthy shared flights:", ""]
    text += healthy_lines(cases, shared["healthy"]) + [""]
    text += agreement_summary(cases + cp["cases"]) + ["", "## CrazyPAD", ""] + crazypad_summary(cp)
    out.mkdir(parents=True, exist_ok=True)
    (out / "export_real_flights.md").write_text("\n".join(text) + "\n")
    (out / "export_real_flights.json").write_text(json.dumps({"shared": shared, "crazypad": cp}, indent=1))
    print("\n".join(text))


if __name__ == "__main__":
    main()
