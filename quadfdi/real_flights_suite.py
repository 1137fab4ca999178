"""The realistic suite's comparison of ``quadfdi real-flights`` (quadfdi/real_flights.py, step 3).

Rows: each fixed-profile network (flightlog-min, -nocur, -esc; CNODE and GRU) with every channel, and
the masked network (flightlog-mask) with every channel and with every test window under each mask
pattern in turn (core/channels.py MASK_PATTERNS; train.study_apply.run_patterns). Each row holds the
test flights of both simulator seeds (training seed 0; one dataset for every profile): window macro
F1, faulty flights detected, false alarms per healthy flight-hour (Garwood), with flight-bootstrap
intervals, under the alarm policy ``quadfdi evaluate`` chose for that network on validation flights
with every channel -- never re-tuned to a pattern (evaluate.fixed) -- and the paired difference to
flightlog-min's network of the same kind with every channel. The goal: the masked network with every
channel within GOAL_POINTS of flightlog-min's window macro F1.
"""

from __future__ import annotations

import os
from pathlib import Path

from quadfdi.core.errors import QuadfdiError

TEST = "test"
GOAL_POINTS = 0.02
NETS = ("cnode", "gru")
REFERENCE = "flightlog-min"


def _label(profile: str, net: str, pattern: str) -> str:
    return f"{profile} {net} {pattern}"


def _same_dataset(a: Path, b: Path) -> bool:
    from quadfdi.core.records import sha256_file

    return os.path.samefile(a, b) or sha256_file(a) == sha256_file(b)


def _profile_sets(root: Path, profile: str, infos: dict) -> tuple[dict, dict, dict]:
    """(label -> Flights list, label -> policy, the run's datasets) of one profile's run folder."""
    from quadfdi.core.jsonio import read_json
    from quadfdi.core.npzio import read_npz
    from quadfdi.evaluate.load import load_run, to_flights
    from quadfdi.formats.predictions import check_prediction_set
    from quadfdi.train.study_apply import PATTERNS_SUMMARY

    fls, run_infos = load_run(root)
    for rel, info in run_infos.items():
        if rel in infos and not _same_dataset(infos[rel].path, info.path):
            raise QuadfdiError(f"{info.path} differs from {infos[rel].path}: the profiles were not trained and "
                               "scored on one simulation")
    policy = {net: read_json(root / "evaluation" / "evaluation.json", "evaluation")["models"][net]["policy"]
              for net in NETS}
    sets = {_label(profile, net, "all"): [f for f in fls if f.model == net] for net in NETS}
    policies = {_label(profile, net, "all"): policy[net] for net in NETS}
    if (root / PATTERNS_SUMMARY).is_file():
        for e in read_json(root / PATTERNS_SUMMARY, "pattern sets")["sets"]:
            arrays = read_npz(root / e["predictions"], "prediction set")
            check_prediction_set(arrays, str(root / e["predictions"]))
            label = _label(profile, e["kind"], e["pattern"])
            sets.setdefault(label, []).append(to_flights(e, arrays, run_infos[e["dataset"]]))
            policies[label] = policy[e["kind"]]
    return sets, policies, run_infos


def suite(out: Path, profiles: dict[str, str], cfg) -> dict:
    """The comparison (module docstring) as JSON: ``rows`` in table order and ``goal`` per masked net;
    ``profiles``: run folder name under ``out`` -> profile name."""
    from quadfdi.evaluate.fixed import paired_fixed, score_fixed

    sets, policies, infos = {}, {}, {}
    for folder, profile in profiles.items():
        s, p, i = _profile_sets(out / folder, profile, infos)
        sets.update(s)
        policies.update(p)
        infos = {**i, **infos}
    scored, pooled = score_fixed(sets, policies, infos, TEST, cfg)
    rows, goal = [], {}
    for label in sets:
        profile, net, pattern = label.split(" ")
        ref = _label(REFERENCE, net, "all")
        vs = paired_fixed(pooled, label, ref, cfg) if ref in pooled and ref != label else None
        rows.append({"profile": profile, "net": net, "pattern": pattern, **scored[label], "vs_min": vs})
        if vs is not None and profile == "flightlog-mask" and pattern == "all":
            d = vs["diff"]["macro_f1"]
            goal[net] = dict(d, goal_points=GOAL_POINTS, met=d["diff"] is not None and d["diff"] >= -GOAL_POINTS)
    return {"set": TEST, "rows": rows, "goal": goal}


def _iv(m: dict, digits: int = 3, sign: bool = False) -> str:
    value = m.get("value", m.get("diff"))
    if value is None:
        return "—"
    f = f"{{:{'+' if sign else ''}.{digits}f}}"
    lo_hi = "" if m["lo"] is None else f" [{f.format(m['lo'])}, {f.format(m['hi'])}]"
    return f.format(value) + lo_hi


def policy_text(p: dict) -> str:
    return f"p >= {p['threshold']:g}, {p['k']} of {p['n']}, clear {p['clear_m']}"


def _row(r: dict) -> str:
    fa = r["false_alarms"]
    rate = {"value": fa["rate_per_h"], "lo": fa["poisson_lo"], "hi": fa["poisson_hi"]}
    detected = f"{r['detected']:.0f}/{r['faults']:.0f} = {_iv(r['metrics']['detection_rate'], 2)}"
    vs = "—" if r["vs_min"] is None else _iv(r["vs_min"]["diff"]["macro_f1"], sign=True)
    channels = "every" if r["pattern"] == "all" else r["pattern"]
    policy = policy_text(r["policy"]) if r["pattern"] == "all" else "same"
    return (f"| {r['profile']} | {r['net']} | {channels} | {policy} | {_iv(r['metrics']['macro_f1'])} | {detected} | "
            f"{_iv(rate, 2)} ({fa['count']} in {fa['exposure_h']:.2f} h) | {vs} |")


def suite_table(s: dict) -> str:
    """The markdown table of ``suite`` and the goal's line."""
    head = ["| profile | net | channels | policy (validation, every channel) | test window macro F1 [95 %] | "
            "faulty flights detected [95 %] | false alarms per healthy flight-hour [95 %] | "
            "macro F1 - flightlog-min's, paired [95 %] |", "|---|---|---|---|---|---|---|---|"]
    order = {n: i for i, n in enumerate(NETS)}
    rows = sorted(s["rows"], key=lambda r: (r["profile"] == "flightlog-mask", order[r["net"]]))
    lines = head + [_row(r) for r in rows]
    for net, g in s["goal"].items():
        lines.append("")
        lines.append(f"flightlog-mask {net} with every channel against flightlog-min {net} (the goal: at most "
                     f"{g['goal_points'] * 100:g} points of window macro F1 below it): {_iv(g, sign=True)}, "
                     f"{'met' if g['met'] else 'NOT met'}.")
    return "\n".join(lines)
