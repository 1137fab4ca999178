"""``quadfdi real-flights OUT --export DIR``: steps 4 and 5 of quadfdi/real_flights.py for one export
made elsewhere (a fleet run's, say), nothing simulated or trained: every shared real quad log through
``quadfdi detect`` with both networks, both runtimes and both precisions (the UAVCAN mission again with
its gaps bridged), every CrazyPAD log too when the export's profile is a masked one (the Crazyflie logs
lack pitch, body rates, current and vibration: only a masked profile takes them), then
``OUT/real_flights.md`` and ``.json`` without the realistic suite's sections.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from quadfdi.core.errors import QuadfdiError

KEY = "export"  # the export's key in the detect passes' ``exports`` (real_flights_detect.detect_shared)


def run_export_only(args: argparse.Namespace, checked: tuple, command: str) -> dict:
    """The result dict ``real_flights_report.markdown`` reads (``suite`` None); ``checked``: real_flights'
    ``_checked_args`` (profiles, logs, log names, CrazyPAD folder or None)."""
    from quadfdi.core.profiles import is_masked
    from quadfdi.formats.export_folder import Export
    from quadfdi.real_flights_crazypad import detect_crazypad
    from quadfdi.real_flights_detect import detect_shared

    _, logs, names, crazypad = checked
    folder = Path(args.export).resolve()
    if not (folder / "manifest.json").is_file():
        raise QuadfdiError(f"--export {args.export}: no manifest.json in it (give RUN/export)")
    profile = Export.open(folder).profile()
    t0 = time.monotonic()
    out = Path(args.out)
    result = {"command": command, "logs": str(logs), "exports": {KEY: str(folder)}, "export_refused": {},
              "suite": None, "profile": profile}
    result.update(detect_shared(out, {KEY: folder}, logs, names, {KEY: profile}))
    t1 = time.monotonic()
    result["crazypad"] = None
    if crazypad is None or not is_masked(profile):
        print("real-flights: CrazyPAD logs skipped: " + (f"profile {profile} is not a masked one"
                                                         if crazypad is not None else "no CrazyPAD folder"))
    else:
        result["crazypad"] = detect_crazypad(out / "crazypad", folder, crazypad, args.workers or os.cpu_count(),
                                             profile)
    result["times"] = {"detect_shared_s": round(t1 - t0, 1), "total_s": round(time.monotonic() - t0, 1)}
    return result
