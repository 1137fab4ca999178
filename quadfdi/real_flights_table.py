"""The full tables of ``quadfdi real-flights``' OUT/real_flights.md (quadfdi/real_flights.py; the
document is put together by quadfdi/real_flights_report.py):

- the realistic suite (quadfdi/real_flights_suite.py's table);
- the shared real logs: one row per profile, flight and network: the ONNX Runtime fp32 alarms (class,
  motor, start-end s, peak fault probability), the flight's airborne time, when the hover estimate
  froze, the decided windows and the exposure (decided flight time), whether C++ gave the same alarms
  as ONNX Runtime in both precisions, and whether int8 gave fp32's (else int8's alarms); below it
  every refusal (ingest's or detect's one-line reason), once per profile and flight; then what each
  network did on the healthy ones;
- C++ against ONNX Runtime in each precision and int8 against fp32 in each runtime, every pair of
  cases counted and every disagreement listed;
- CrazyPAD: per group (quadfdi/real_flights_crazypad.py) and session the logs decided and alarmed
  (ONNX Runtime fp32), the alarm classes and the motors named (the log's M1-M4), then one row per log.
"""

from __future__ import annotations

from collections import Counter

HEAD = ["| profile | net | flight | airborne s | hover frozen s | decided windows | exposure s | "
        "alarms, ORT fp32 (class, motor, s) | cpp = ort (fp32, int8) | int8 = fp32 |",
        "|---|---|---|---|---|---|---|---|---|---|"]
NETS = ("cnode", "gru")


def _key(record: dict | None) -> list | None:
    return None if record is None else [(a["class"], a["motor"], a["start_s"], a["end_s"]) for a in record["alarms"]]


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
    """The markdown table and the refusals of one detect pass (``real_flights_detect.detect_all``)."""
    groups: dict[tuple[str, str, str], list[dict]] = {}
    refused: dict[tuple[str, str], str] = {}
    for c in results:
        groups.setdefault((c["profile"], c["flight"], c["net"]), []).append(c)
        if "refused" in c:
            refused.setdefault((c["profile"], c["flight"]), c["refused"])
    first = {p: i for i, p in reversed(list(enumerate(c["profile"] for c in results)))}  # profiles as run
    order = sorted(groups, key=lambda k: (first[k[0]], k[1], NETS.index(k[2])))
    rows = [r for k in order if (r := _row(groups[k])) is not None]
    notes = [f"- {p} {f}: {why}" for (p, f), why in sorted(refused.items())]
    return "\n".join(HEAD + rows + ([""] + notes if notes else []))


def healthy_lines(results: list[dict], healthy: list[str]) -> list[str]:
    """Per profile and network: the healthy shared flights it decided and every alarm it raised on
    them, in any runtime and precision."""
    out, seen = [], {}
    for c in results:
        if c["flight"].split(" ")[0] in healthy:
            seen.setdefault((c["profile"], c["net"]), []).append(c)
    for (prof, net), cases in seen.items():
        fp32 = [c for c in cases if (c["runtime"], c["precision"]) == ("ort", "fp32") and "record" in c
                and c["record"]["decided_windows"] > 0]
        alarms = sorted({f"{c['flight']} {a['class']}{'' if a['motor'] is None else ' m' + str(a['motor'])} at "
                         f"{a['start_s']:.1f} s ({c['runtime']} {c['precision']})"
                         for c in cases if "record" in c for a in c["record"]["alarms"]})
        exposure = sum(c["record"]["exposure_s"] for c in fp32)
        out.append(f"- {prof} {net}: {len(fp32)} of {len({c['flight'] for c in cases})} healthy flights decided "
                   f"({exposure:.1f} s): " + ("no alarm in any runtime or precision" if not alarms
                                              else "ALARMS " + "; ".join(alarms)))
    return out


def disagreements(cases: list[dict]) -> dict:
    """C++ against ONNX Runtime per precision and int8 against fp32 per runtime over every (profile,
    flight, network): the pairs compared and each pair whose alarms (or refusal) differ."""
    by: dict[tuple, dict] = {}
    for c in cases:
        by.setdefault((c["profile"], c["flight"], c["net"]), {})[(c["runtime"], c["precision"])] = c.get("record")
    pairs = {f"cpp_vs_ort_{p}": (("cpp", p), ("ort", p)) for p in ("fp32", "int8")}
    pairs.update({f"int8_vs_fp32_{r}": ((r, "int8"), (r, "fp32")) for r in ("ort", "cpp")})
    out = {name: {"compared": 0, "differ": []} for name in pairs}
    for (prof, flight, net), res in by.items():
        for name, (a, b) in pairs.items():
            if a not in res or b not in res or (res[a] is None and res[b] is None):
                continue
            out[name]["compared"] += 1
            if _key(res[a]) != _key(res[b]):
                text = lambda r: "refused" if r is None else alarms_text(r)  # noqa: E731
                out[name]["differ"].append({"profile": prof, "flight": flight, "net": net,
                                            "a": text(res[a]), "b": text(res[b])})
    return out


def agreement_lines(d: dict) -> list[str]:
    lines = []
    for name, v in d.items():
        a, _, b = name.partition("_vs_")
        lines.append(f"- {a.replace('_', ' ')} against {b.replace('_', ' ')}: {len(v['differ'])} of {v['compared']} "
                     "(profile, flight, network) differ" + (":" if v["differ"] else ""))
        lines += [f"  - {x['profile']} {x['flight']} {x['net']}: {x['a']} / {x['b']}" for x in v["differ"]]
    return lines


def _short(alarms: list[dict]) -> str:
    return "; ".join(f"{a['class']}{'' if a['log_motor'] is None else ' ' + a['log_motor']} {a['start_s']:.1f} s"
                     for a in alarms) or "none"


def crazypad_tables(cp: dict) -> tuple[str, str]:
    """(the per-group table, the per-log table with the refusals) of ``detect_crazypad``'s cases."""
    from quadfdi.real_flights_crazypad import group_key

    fp32 = {(c["flight"], c["net"]): c for c in cp["cases"] if (c["runtime"], c["precision"]) == ("ort", "fp32")}
    logs = {c["flight"]: c for c in fp32.values()}
    groups: dict[str, list[str]] = {}
    for f, c in logs.items():
        groups.setdefault(c["group"], []).append(f)
    head = ["| group | logs E8 / E9 | decided | CNODE alarmed E8 / E9 | GRU alarmed E8 / E9 | alarms CNODE / GRU "
            "(class: flights) | motors named CNODE / GRU (log's M1-M4) |", "|---|---|---|---|---|---|---|"]
    rows = []
    for g in sorted(groups, key=group_key):
        fl = groups[g]
        ses = lambda s, fs: [f for f in fs if logs[f]["session"] == s]  # noqa: E731
        dec = [f for f in fl if "record" in fp32[(f, "cnode")]]
        alarmed = {n: [f for f in fl if "record" in fp32[(f, n)] and fp32[(f, n)]["record"]["alarms"]] for n in NETS}
        classes = {n: Counter(k for f in alarmed[n] for k in {a["class"] for a in fp32[(f, n)]["record"]["alarms"]})
                   for n in NETS}
        motors = {n: Counter(a["log_motor"] for f in alarmed[n] for a in fp32[(f, n)]["record"]["alarms"]
                             if a["log_motor"]) for n in NETS}
        txt = lambda cnt: ", ".join(f"{k} {v}" for k, v in sorted(cnt.items())) or "—"  # noqa: E731
        rows.append(f"| {g} | {len(ses('E8', fl))} / {len(ses('E9', fl))} | {len(dec)} | "
                    + " | ".join(f"{len(ses('E8', alarmed[n]))} / {len(ses('E9', alarmed[n]))}" for n in NETS)
                    + f" | {txt(classes['cnode'])} / {txt(classes['gru'])} | {txt(motors['cnode'])} / "
                      f"{txt(motors['gru'])} |")
    per_log = ["| log | group | decided s | CNODE alarms, ORT fp32 | GRU alarms, ORT fp32 |", "|---|---|---|---|---|"]
    refused = []
    for f in sorted(logs, key=lambda f: (group_key(logs[f]["group"]), f)):
        c, g = fp32[(f, "cnode")], fp32[(f, "gru")]
        if "record" not in c:
            refused.append(f"- {f}: {c['refused']}")
            continue
        per_log.append(f"| {f} | {c['group']} | {c['record']['exposure_s']:.1f} | {_short(c['record']['alarms'])} | "
                       f"{_short(g['record']['alarms']) if 'record' in g else 'refused'} |")
    return "\n".join(head + rows), "\n".join(per_log + ([""] + refused if refused else []))
