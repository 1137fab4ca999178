"""``quadfdi real-flights``' OUT/real_flights.md (quadfdi/real_flights.py): the command and the
machine, a summary, then the full tables (quadfdi/real_flights_table.py, quadfdi/real_flights_suite.py).
The summary holds the same results made short enough to quote (docs/detect.md's real-flight section
quotes it):

- the realistic suite: one row per profile and channels (every channel, and the masked profile under
  each mask pattern), CNODE and GRU side by side: window macro F1, the paired difference to
  flightlog-min's network of the same kind, faulty flights detected and false alarms per healthy
  flight-hour, each with its interval; then the masked networks against the goal;
- the shared real logs: per profile the logs decided and refused (ONNX Runtime fp32), then every
  alarm on a healthy one, in any runtime and precision;
- C++ against ONNX Runtime and int8 against fp32: the pairs that differ of the pairs compared;
- CrazyPAD: one column per group, the logs, the logs decided and the logs each network alarmed on, by
  session (E8 / E9).
"""

from __future__ import annotations

import platform

from quadfdi.real_flights_crazypad import group_key
from quadfdi.real_flights_suite import NETS, suite_table
from quadfdi.real_flights_table import agreement_lines, crazypad_tables, disagreements, healthy_lines, table


def _iv(m: dict | None, digits: int = 3, sign: bool = False) -> str:
    if m is None or m.get("value", m.get("diff")) is None:
        return "—"
    f = f"{{:{'+' if sign else ''}.{digits}f}}"
    value = m.get("value", m.get("diff"))
    return f.format(value) + ("" if m["lo"] is None else f" [{f.format(m['lo'])}, {f.format(m['hi'])}]")


def _cells(r: dict) -> tuple[str, str, str, str]:
    fa = r["false_alarms"]
    rate = {"value": fa["rate_per_h"], "lo": fa["poisson_lo"], "hi": fa["poisson_hi"]}
    vs = None if r["vs_min"] is None else r["vs_min"]["diff"]["macro_f1"]
    return (_iv(r["metrics"]["macro_f1"]), _iv(vs, sign=True), _iv(r["metrics"]["detection_rate"], 2), _iv(rate, 2))


def suite_summary(s: dict) -> list[str]:
    """The realistic suite in one row per (profile, channels): CNODE / GRU in each cell."""
    rows: dict[tuple[str, str], dict[str, dict]] = {}
    for r in s["rows"]:
        rows.setdefault((r["profile"], r["pattern"]), {})[r["net"]] = r
    order = sorted(rows, key=lambda k: k[0] == "flightlog-mask")
    flights = max(r["flights"] for r in s["rows"])
    hours = max(r["false_alarms"]["exposure_h"] for r in s["rows"])
    out = [f"Realistic suite, {flights} {s['set']} flights ({hours:.2f} h healthy), each network under the "
           "alarm policy chosen on validation flights with every channel; cells CNODE / GRU, [95 %]:", "",
           "| profile | channels | window macro F1 | minus flightlog-min's, paired | faulty flights detected | "
           "false alarms per healthy flight-hour |", "|---|---|---|---|---|---|"]
    for prof, pattern in order:
        cells = [_cells(rows[prof, pattern][n]) if n in rows[prof, pattern] else ("—",) * 4 for n in NETS]
        out.append(f"| {prof} | {'every' if pattern == 'all' else pattern} | "
                   + " | ".join(" / ".join(c[i] for c in cells) for i in range(4)) + " |")
    goal = [f"{net.upper()} {_iv(g, sign=True)} ({'met' if g['met'] else 'NOT met'})" for net, g in s["goal"].items()]
    if goal:
        points = next(iter(s["goal"].values()))["goal_points"] * 100
        out += ["", f"flightlog-mask minus flightlog-min with every channel, window macro F1, paired (the goal: at "
                    f"most {points:g} points below): " + ", ".join(goal) + "."]
    return out


def _healthy_alarms(cases: list[dict], healthy: list[str]) -> dict[str, list[str]]:
    """Profile -> each network's alarms on each healthy flight, once per (class, motor, start) with
    the runtimes and precisions that raised it named unless all four did."""
    seen: dict[tuple, dict[tuple, set[str]]] = {}
    for c in cases:
        if c["flight"] in healthy and "record" in c:
            for a in c["record"]["alarms"]:
                seen.setdefault((c["profile"], c["net"], c["flight"]), {}).setdefault(
                    (a["class"], a["motor"], a["start_s"]), set()).add(f"{c['runtime']} {c['precision']}")
    out: dict[str, list[str]] = {}
    for (prof, net, flight), alarms in seen.items():
        text = [f"{k}{'' if m is None else ' m' + str(m)} at {t:.1f} s" + ("" if len(rp) == 4 else f" ({', '.join(sorted(rp))})")
                for (k, m, t), rp in sorted(alarms.items(), key=lambda kv: kv[0][2])]
        out.setdefault(prof, []).append(f"{net.upper()} on {flight}: " + ", ".join(text))
    return out


def shared_summary(r: dict) -> list[str]:
    """Per profile: shared logs decided and refused (ONNX Runtime fp32, CNODE), and on the healthy
    ones what it decided and every alarm in any runtime and precision (the mission's bridged pass included)."""
    per: dict[str, dict[str, bool]] = {}
    for c in r["flights"]:
        if (c["net"], c["runtime"], c["precision"]) == ("cnode", "ort", "fp32"):
            per.setdefault(c["profile"], {})[c["flight"]] = "record" in c
    alarms = _healthy_alarms(r["flights"] + r["flights_gap7"], r["healthy"])
    healthy = [f"{p} {sum(v for f, v in d.items() if f in r['healthy'])} decided, "
               + ("ALARMS " + "; ".join(alarms[p]) if p in alarms else "no alarm") for p, d in per.items()]
    n = len({c["flight"] for c in r["flights"] if c["flight"] in r["healthy"]})
    return ["Shared real quad logs decided / refused: " + ", ".join(f"{p} {sum(d.values())} / {len(d) - sum(d.values())}"
                                                              for p, d in per.items())
            + f". On the {n} healthy ones (the mission also bridged), in every runtime and precision unless named: "
            + "; ".join(healthy) + "."]


def agreement_summary(cases: list[dict]) -> list[str]:
    d = disagreements(cases)
    text = lambda k: f"{len(d[k]['differ'])} of {d[k]['compared']}"  # noqa: E731
    return [f"(Profile, log, network) whose alarms differ: C++ against ONNX Runtime {text('cpp_vs_ort_fp32')} in "
            f"fp32, {text('cpp_vs_ort_int8')} in int8; int8 against fp32 {text('int8_vs_fp32_ort')} in ONNX "
            f"Runtime, {text('int8_vs_fp32_cpp')} in C++."]


def crazypad_summary(cp: dict) -> list[str]:
    """One column per CrazyPAD group: logs, decided, alarmed per network, each E8 / E9 (ONNX Runtime fp32)."""
    fp32 = [c for c in cp["cases"] if (c["runtime"], c["precision"]) == ("ort", "fp32")]
    groups = sorted({c["group"] for c in fp32}, key=group_key)

    def count(pred) -> list[str]:
        return [" / ".join(str(len({c["flight"] for c in fp32 if c["group"] == g and c["session"] == s and pred(c)}))
                           for s in ("E8", "E9")) for g in groups]

    rows = [("logs", count(lambda c: True)), ("decided", count(lambda c: c["net"] == "cnode" and "record" in c))]
    rows += [(f"{n.upper()} alarmed", count(lambda c, n=n: c["net"] == n and "record" in c and c["record"]["alarms"]))
             for n in NETS]
    profile = fp32[0]["profile"] if fp32 else "?"
    return [f"CrazyPAD, {profile}: {cp['logs']} logs x 8 cases in {cp['wall_s']:.0f} s ({cp['workers']} "
            "workers); ONNX Runtime fp32, logs E8 / E9:", "",
            "| | " + " | ".join(groups) + " |", "|---" * (len(groups) + 1) + "|"] + \
        [f"| {name} | " + " | ".join(cells) + " |" for name, cells in rows]


def summary(r: dict) -> str:
    """The summary (module docstring) of ``run_real_flights``' result."""
    bridged = [dict(c, flight=f"{c['flight']} (gaps bridged)") for c in r["flights_gap7"]]
    cp = r["crazypad"]
    text = suite_summary(r["suite"]) + [""] if r["suite"] is not None else []
    text += [f"{p}: no export, no log decided: {why}." for p, why in r.get("export_refused", {}).items()]
    text += shared_summary(r)
    text += agreement_summary(r["flights"] + bridged + (cp["cases"] if cp else []))
    if cp:
        text += [""] + crazypad_summary(cp)
    return "\n".join(text)


def machine() -> str:
    """The CPU model and the cores this process may use (the tables' timings depend on them)."""
    import os

    model = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {len(os.sched_getaffinity(0))} cores"


def markdown(r: dict) -> str:
    """real_flights.md from ``run_real_flights``' result."""
    t = r["times"]
    text = [f"# Real flights\n\n`{r['command']}` on {machine()}: {t['total_s'] / 60:.1f} min.\n",
            "## Summary\n", summary(r) + "\n"]
    if r["suite"] is not None:
        text += [f"## The realistic suite: {r['suite']['set']} flights, sim seeds 0 and 1, train seed 0\n",
                 suite_table(r["suite"]) + "\n"]
    text += ["## The shared real quad logs\n", "Default gap rule:\n", table(r["flights"]) + "\n"]
    if r["flights_gap7"]:
        text += [f"The UAVCAN mission with logging gaps bridged up to {r['gap_factor']:g} x the median interval "
                 f"(`quadfdi ingest --gap-factor {r['gap_factor']:g}`):\n", table(r["flights_gap7"]) + "\n"]
    bridged = [dict(c, flight=f"{c['flight']} (gaps bridged)") for c in r["flights_gap7"]]
    text += ["Healthy flights (" + ", ".join(r["healthy"]) + "; the mission also bridged):\n",
             "\n".join(healthy_lines(r["flights"] + bridged, r["healthy"])) + "\n"]
    cp = r["crazypad"]
    cases = r["flights"] + bridged + (cp["cases"] if cp else [])
    text += ["## Runtimes and precisions\n", "Every shared log" + (" and every CrazyPAD log" if cp else "") + ":\n",
             "\n".join(agreement_lines(disagreements(cases))) + "\n"]
    if cp:
        groups, per_log = crazypad_tables(cp)
        profile = cp["cases"][0]["profile"] if cp["cases"] else "?"
        text += [f"## CrazyPAD ({profile})\n\n{cp['logs']} logs of {cp['root']} x 8 cases in {cp['wall_s']:.0f} s "
                 f"({cp['workers']} worker process{'es' if cp['workers'] > 1 else ''}). Decided and alarmed: ONNX Runtime fp32.\n", groups + "\n",
                 per_log + "\n"]
    return "\n".join(text)
