"""``quadfdi ingest LOG --out DIR``: one real flight log -> DIR/flight.npz (+ DIR/ingest.json);
``quadfdi ingest bench LOG...``: ingest throughput (seconds per flight-hour), printed as JSON.

A refused log (not a multirotor, never airborne, too short, unreadable) is one line on stderr,
exit 2, and nothing is written.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from quadfdi.core.errors import QuadfdiError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ingest", help="read a PX4 ULog, ArduPilot .BIN or Crazyflie uSD flight log into flight.npz",
                       description="Ingest a real flight log into <out>/flight.npz (docs/flight_format.md). "
                                   "`quadfdi ingest bench LOG...` measures throughput instead; `quadfdi ingest "
                                   "rates LOG...` prints each channel group's logged rate.")
    p.add_argument("logs", nargs="+", metavar="LOG", help="the log file (or: bench LOG..., rates LOG...)")
    p.add_argument("--out", default=None, help="folder to write flight.npz and ingest.json into")
    p.add_argument("--min-airborne", type=float, default=None,
                   help="refuse logs with less airborne time, s (default: 2)")
    p.add_argument("--gap-factor", type=float, default=None,
                   help="a channel's run ends at an interval above this many times its median interval "
                        "(default: 3; docs/ingest.md \"Gaps\")")
    p.add_argument("--repeat", type=int, default=3, help="bench: timed repetitions per log (default: %(default)s)")
    p.set_defaults(func=run)


def summary(lr, arrays) -> dict:
    names = [str(n) for n in arrays["channel_names"]]
    return {
        "log_file": str(arrays["log_file"]), "log_sha256": str(arrays["log_sha256"]), "autopilot": lr.autopilot,
        "span_s": [float(arrays["time"][0]), float(arrays["time"][-1])], "samples": int(len(arrays["time"])),
        "airborne_s": [list(s) for s in lr.airborne], "airborne_source": lr.airborne_source,
        "channels": {n: {"status": str(st), "source": str(src), "rate_hz": round(float(r), 2),
                         "grid_coverage": round(float(m), 3)}
                     for n, st, src, r, m in zip(names, arrays["channel_status"], arrays["channel_sources"],
                                                 arrays["channel_rates_hz"], arrays["mask"].mean(axis=0))},
        "vehicle": json.loads(str(arrays["vehicle"])), "notes": lr.notes,
    }


def run(args: argparse.Namespace) -> int:
    from quadfdi.core.jsonio import write_json
    from quadfdi.ingest import segments
    from quadfdi.formats.flight import write_flight
    from quadfdi.ingest.flight import ingest

    if args.logs[0] == "bench":
        from quadfdi.ingest.bench import bench

        if len(args.logs) < 2:
            raise QuadfdiError("quadfdi ingest bench needs at least one LOG")
        print(json.dumps(bench(args.logs[1:], max(1, args.repeat)), indent=2))
        return 0
    if args.logs[0] == "rates":
        from quadfdi.ingest.rates import group_rates

        if len(args.logs) < 2:
            raise QuadfdiError("quadfdi ingest rates needs at least one LOG")
        print(json.dumps(group_rates(args.logs[1:]), indent=2))
        return 0
    if len(args.logs) != 1:
        raise QuadfdiError("quadfdi ingest takes one LOG per call (give --out per flight)")
    if args.out is None:
        raise QuadfdiError("quadfdi ingest needs --out <folder>")
    min_air = segments.MIN_AIRBORNE_S if args.min_airborne is None else args.min_airborne
    from quadfdi.core.resample import GAP_FACTOR

    gap = GAP_FACTOR if args.gap_factor is None else args.gap_factor
    lr, arrays = ingest(args.logs[0], min_air, gap)  # refusals raise before anything is written
    out = Path(args.out)
    write_flight(out / "flight.npz", arrays)
    write_json(out / "ingest.json", summary(lr, arrays))
    ok = [str(n) for n, s in zip(arrays["channel_names"], arrays["channel_status"]) if str(s) == "ok"]
    print(f"wrote {out / 'flight.npz'}: {len(arrays['time'])} samples at 25 Hz, "
          f"{sum(b - a for a, b in lr.airborne):.1f} s airborne; channels: {', '.join(ok)}")
    return 0
