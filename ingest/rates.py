"""Logged rates per channel group of real logs (``quadfdi ingest rates LOG...``): the table the
simulator draws its per-flight logging rates from (sim.realistic_params.LOG_HZ_MEASURED).

A group's rate is the highest of its channels' mean rates (``ingest.model.Channel.rate_hz``:
samples per second over the channel's own span) in each log that has it."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.channels import RATE_GROUP


def group_rates(logs: list[str]) -> dict:
    """{"logs": [{"log", "autopilot", "rates": {group: Hz}} or {"log", "refused"}], "groups": {group: sorted Hz}}."""
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.ingest.flight import read_log

    rows, groups = [], {g: set() for g in dict.fromkeys(RATE_GROUP.values())}
    for log in logs:
        try:
            lr = read_log(log)
        except QuadfdiError as exc:
            rows.append({"log": Path(log).name, "refused": str(exc)})
            continue
        rates: dict[str, float] = {}
        for name, ch in lr.channels.items():
            g = RATE_GROUP.get(name)
            if g is not None and ch.rate_hz > 0:
                rates[g] = max(rates.get(g, 0.0), round(ch.rate_hz, 1))
        for g, r in rates.items():
            groups[g].add(r)
        rows.append({"log": Path(log).name, "autopilot": lr.autopilot, "rates": rates})
    return {"logs": rows, "groups": {g: sorted(v) for g, v in groups.items()}}
