"""The tables of ``quadfdi real-flights`` (quadfdi/real_flights.py) from its detect results.

One row per profile, flight and network: the ONNX Runtime fp32 alarms (class, motor, start-end s,
peak fault probability), the flight's airborne time, when the hover estimate froze, the decided
windows and the exposure (decided flight time), whether C++ gave the same alarms as ONNX Runtime in
both precisions, and whether int8 gave fp32's (else int8's alarms). Below each table, every
refusal (ingest's or detect's one-line reason), once per profile and flight.
"""

from __future__ import annotations

HEAD = ["| profile | net | flight | airborne s | hover frozen s | decided windows | exposure s | "
        "alarms, ORT fp32 (class, motor, s) | cpp = ort (fp32, int8) | int8 = fp32 |",
        "|---|---|---|---|---|---|---|---|---|---|"]


def _key(record: dict) -> list:
    return [(a["class"], a["motor"], a["start_s"], a["end_s"]) for a in record["alarms"]]


def alarms_text(record: dict) -> str:
    """``BatteryFault m2 3.2-end (peak 0.91); ...`` or ``none``."""
    if not record["alarms"]:
        return "none"
    return "; ".join(f"{a['class']}{'' if a['motor'] is None else ' m' + str(a['motor'])} {a['start_s']:.1f}-"
                     f"{'end' if a['end_s'] is None else format(a['end_s'], '.1f')} (peak {a['peak_p_fault']:.2f})"
                     for a in record["alarms"])


def _row(cases: list[dict]) -> str | None:
    """The row of one profile, flight and network (its four runtime x precision cases), or None
    when ONNX Runtime fp32 refused it."""
    res = {(c["runtime"], c["precision"]): c["record"] for c in cases if "record" in c}
    if ("ort", "fp32") not in res:
        return None
    a, c = res["ort", "fp32"], cases[0]
    same_rt = all(_key(res["ort", p]) == _key(res["cpp", p]) for p in ("fp32", "int8")
                  if ("ort", p) in res and ("cpp", p) in res)
    i8 = res.get(("ort", "int8"))
    same_pr = "yes" if i8 is not None and _key(i8) == _key(a) else "int8: " + (alarms_text(i8) if i8 else "refused")
    return (f"| {c['profile']} | {c['net']} | {c['flight']} | {a['airborne_s']:.1f} | {a['hover']['freeze_s']:.1f} | "
            f"{a['decided_windows']}/{a['windows']} | {a['exposure_s']:.1f} | {alarms_text(a)} | "
            f"{'yes' if same_rt else 'NO'} | {same_pr} |")


def table(results: list[dict]) -> str:
    """The markdown table and the refusals of one detect pass (``real_flights.detect_all``)."""
    groups: dict[tuple[str, str, str], list[dict]] = {}
    refused: dict[tuple[str, str], str] = {}
    for c in results:
        groups.setdefault((c["profile"], c["flight"], c["net"]), []).append(c)
        if "refused" in c:
            refused.setdefault((c["profile"], c["flight"]), c["refused"])
    first = {p: i for i, p in reversed(list(enumerate(c["profile"] for c in results)))}  # profiles as run
    order = sorted(groups, key=lambda k: (first[k[0]], k[1], ("cnode", "gru").index(k[2])))
    rows = [r for k in order if (r := _row(groups[k])) is not None]
    notes = [f"- {p} {f}: {why}" for (p, f), why in sorted(refused.items())]
    return "\n".join(HEAD + rows + ([""] + notes if notes else []))


def markdown(results: list[dict], gap_results: list[dict], gap_factor: float) -> str:
    """real_flights.md: every log with the default gap rule, then the mission with ``gap_factor``."""
    text = "# Real flights\n\nEvery shared real quad log, default gap rule:\n\n" + table(results) + "\n"
    if gap_results:
        text += (f"\nThe UAVCAN mission with logging gaps bridged up to {gap_factor:g} x the median interval "
                 f"(`quadfdi ingest --gap-factor {gap_factor:g}`):\n\n" + table(gap_results) + "\n")
    return text
