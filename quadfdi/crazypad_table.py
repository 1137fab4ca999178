"""``quadfdi crazypad``'s table and gates: the scored network (with and without the vehicle reference)
and the four share rules per CrazyPAD protocol group and session (vehicle.crazypad.table: flights,
alarmed, right motor named among the alarmed, motors named, max and mean score, AUROC of the session's
healthy test flights against the group on each flight's score), each network cell with the classes its
alarms named, p(fault) pooled over the group's decided windows, the flights on which the policy could
raise at all (core.alarm.reach) and those with a window at or above its threshold; then the "Done when" gates (CrazyPAD
and the shared PX4 flights), each met or missed by how much, the >= 3 mm gate's note with the ranking bound
(``separable``).
"""

from __future__ import annotations

import math

from quadfdi.vehicle import crazypad
from quadfdi.vehicle.rules import RULES

NETS = ("net_ref", "net_noref")
RULE_NAMES = tuple(r.name for r in RULES)
DEEP, MID, HEALTHY = crazypad.GROUPS[1], crazypad.GROUPS[2], crazypad.GROUPS[0]
SHARE_ALARMED, SHARE_NAMED = 0.9, 0.9  # of the >= 3 mm cuts alarmed; of those, the cut motor named
AUROC_SLACK = {DEEP: 0.02, MID: 0.05}  # the network's AUROC at most this below the best rule's


def _net_extra(rows: list[dict], key: str) -> dict:
    classes: dict[str, int] = {}
    for r in rows:
        for c in sorted({a["class"] for a in r["rules"][key]["alarms"]}):
            classes[c] = classes.get(c, 0) + 1
    windows = sum(r["rules"][key]["decided_windows"] for r in rows)
    return {"classes": dict(sorted(classes.items())), "decided_windows": windows,
            "could_alarm": sum(1 for r in rows if r["rules"][key].get("alarm_possible", True)),
            "voted": sum(1 for r in rows if r["rules"][key].get("votes", 0) > 0),
            "pooled_mean_p_fault": sum(r["rules"][key]["p_fault_sum"] for r in rows) / windows if windows else None}


def table(rows: list[dict]) -> list[dict]:
    """One cell per (network mode or rule, group, session): vehicle.crazypad.table's, network cells with
    ``classes`` (flights alarming each class), ``decided_windows`` and ``pooled_mean_p_fault``."""
    cells = crazypad.table(rows, NETS + RULE_NAMES)
    for c in cells:
        if c["rule"] in NETS:
            sel = [r for r in rows if r.get("group") == c["group"] and c["session"] in ("all", r["session"])]
            c.update(_net_extra(sel, c["rule"]))
    return cells


def cell(cells: list[dict], rule: str, group: str, session: str = "all") -> dict | None:
    return next((c for c in cells if (c["rule"], c["group"], c["session"]) == (rule, group, session)), None)


def _gate(what: str, value, target: str, met: bool, missed_by: str | None) -> dict:
    return {"gate": what, "value": value, "target": target, "met": bool(met), "missed_by": None if met else missed_by}


def _auroc_gate(cells: list[dict], group: str) -> dict:
    net = cell(cells, "net_ref", group)
    rules = {r: (cell(cells, r, group) or {}).get("auroc") for r in RULE_NAMES}
    known = {r: v for r, v in rules.items() if v is not None}
    slack = AUROC_SLACK[group]
    what = f"AUROC, {group}: the network (with the reference) within {slack:g} of the best rule"
    if net is None or net["auroc"] is None or not known:
        return _gate(what, None, f">= best rule - {slack:g}", False, "(not measurable: no flights)")
    best = max(known, key=known.get)
    gap = known[best] - slack - net["auroc"]
    return _gate(what, {"network": net["auroc"], "best_rule": best, "best_rule_auroc": known[best]},
                 f">= {known[best] - slack:.3f}", gap <= 1e-12, f"{gap:.3f} AUROC")


def separable(rows: list[dict], key: str = "net_ref") -> dict | None:
    """The bound the network's ranking puts on any threshold: the healthy test flights' largest score
    (``healthy_max``) and how many >= 3 mm cuts score above it (``above``), i.e. what a 1-of-1 policy with
    a threshold just above every healthy test flight would alarm. A diagnostic of ranking against
    calibration, read off the test flights: never a policy (None without both groups)."""
    healthy = [r["rules"][key]["score"] for r in rows if r.get("group") == HEALTHY and key in r.get("rules", {})]
    deep = [r["rules"][key]["score"] for r in rows if r.get("group") == DEEP and key in r.get("rules", {})]
    if not healthy or not deep:
        return None
    top = max(healthy)
    return {"healthy_max": top, "above": sum(1 for v in deep if v > top), "flights": len(deep)}


def crazypad_gates(cells: list[dict], rows: list[dict] | None = None) -> list[dict]:
    """The CrazyPAD gates, all sessions, the network with the reference (``rows``: the decided logs, for
    the ranking bound in the >= 3 mm gate's note)."""
    out = []
    h = cell(cells, "net_ref", HEALTHY)
    out.append(_gate("healthy test flights alarmed", None if h is None else f"{h['alarmed']} of {h['flights']}",
                     "0", h is not None and h["alarmed"] == 0,
                     "(no healthy test flight)" if h is None else f"{h['alarmed']} flight(s)"))
    d = cell(cells, "net_ref", DEEP)
    if d is None:
        out.append(_gate(f"{DEEP} alarmed", None, f">= {SHARE_ALARMED:.0%}", False, "(no such flight)"))
        out.append(_gate(f"{DEEP}: cut motor (M3) named among the alarmed", None, f">= {SHARE_NAMED:.0%}", False,
                         "(no such flight)"))
    else:
        need = math.ceil(SHARE_ALARMED * d["flights"] - 1e-9)
        bound = separable(rows or [])
        bound_text = "" if bound is None else (
            f"; a threshold just above every healthy test flight's largest p(fault) ({bound['healthy_max']:.3f}), "
            f"1 of 1, would alarm {bound['above']}")
        out.append(_gate(f"{DEEP} alarmed", f"{d['alarmed']} of {d['flights']}", f">= {need} ({SHARE_ALARMED:.0%})",
                         d["alarmed"] >= need, f"{need - d['alarmed']} flight(s) (the policy could raise on "
                         f"{d['could_alarm']} of the {d['flights']}; {d['voted']} had a window at or above its "
                         f"threshold{bound_text})"))
        need_m = math.ceil(SHARE_NAMED * d["alarmed"] - 1e-9)
        out.append(_gate(f"{DEEP}: cut motor (M3) named among the alarmed", f"{d['right_motor']} of {d['alarmed']}",
                         f">= {need_m} ({SHARE_NAMED:.0%})", d["alarmed"] > 0 and d["right_motor"] >= need_m,
                         "(no flight alarmed: no motor named)" if d["alarmed"] == 0
                         else f"{need_m - d['right_motor']} flight(s)"))
    out += [_auroc_gate(cells, DEEP), _auroc_gate(cells, MID)]
    return out


def px4_gate(px4: dict | None) -> dict:
    """The shared healthy PX4 flights' held-out parts free of alarms, the network with the reference."""
    what = "shared healthy PX4 flights: alarms on the held-out part (reference from the first part)"
    if px4 is None:
        return _gate(what, None, "0", False, "(not run: no --logs folder)")
    done = [f for f in px4["flights"] if "net_ref" in f]
    alarmed = [f["flight"] for f in done if f["net_ref"]["alarm"]]
    if not done:
        return _gate(what, "no flight decided", "0", False, "(no flight could be split and decided)")
    refused = len(px4["flights"]) - len(done)
    return _gate(what, f"{len(alarmed)} of {len(done)} flights alarmed ({refused} refused)", "0", not alarmed,
                 f"{len(alarmed)} flight(s): {', '.join(alarmed)}")
