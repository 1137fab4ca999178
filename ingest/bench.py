"""Ingest throughput: wall seconds per flight-hour of log, from whole ``ingest`` calls (read,
convert, resample; not the file write, which is I/O-bound). The shared logs are at most ~80 s long,
so the figure is measured on them and extrapolated linearly per flight-hour (ingest is linear in
the number of logged messages); the printed JSON says so."""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

from quadfdi.core.errors import QuadfdiError


def bench(logs: list[str], repeat: int = 3) -> dict:
    from quadfdi.ingest.flight import ingest

    rows = []
    for log in logs:
        lr, arrays = ingest(log)  # warm-up (imports, page cache); refusals raise here
        span = float(lr.data_span[1] - lr.data_span[0])
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            ingest(log)
            times.append(time.perf_counter() - t0)
        med = statistics.median(times)
        rows.append({"log": Path(log).name, "bytes": os.path.getsize(log), "log_span_s": round(span, 2),
                     "median_s": round(med, 4), "runs_s": [round(t, 4) for t in times],
                     "s_per_flight_hour": round(med * 3600.0 / span, 1)})
    if not rows:
        raise QuadfdiError("no log to bench")
    total_span = sum(r["log_span_s"] for r in rows)
    total_s = sum(r["median_s"] for r in rows)
    per_hour = total_s * 3600.0 / total_span
    return {"logs": rows, "s_per_flight_hour": round(per_hour, 1),
            "s_per_10_min_flight": round(per_hour / 6.0, 2), "target_s_per_10_min_flight": 20.0,
            "meets_target": per_hour / 6.0 < 20.0, "cpus": os.cpu_count(),
            "method": f"median of {repeat} whole ingest() calls per log after one warm-up; "
                      "extrapolated linearly from the logs' spans to one flight-hour"}
