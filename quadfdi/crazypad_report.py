"""``OUT/crazypad.md`` of ``quadfdi crazypad``: the network and policy scored and what chose them, the
reference, the gates, the summary per group, the same per session, the network's cells in full, the
shared PX4 flights and every CrazyPAD flight. ``report_section(run)``: the gates and the summary in the
run's report.md when the command wrote into ``RUN/crazypad``.
"""

from __future__ import annotations

import json
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.crazypad_choice import policy_text
from quadfdi.crazypad_decide import MODES
from quadfdi.crazypad_table import NETS, RULE_NAMES, cell
from quadfdi.vehicle.crazypad import GROUPS, SESSIONS

FOLDER = "crazypad"  # RUN/crazypad: the output folder the run's report reads
LABEL = {"net_ref": "network, reference", "net_noref": "network, no reference",
         **{r: f"`{r}`" for r in RULE_NAMES}}


def _f(x, digits: int = 2) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def _short(c: dict | None) -> str:
    """``AUROC, alarmed (right motor)`` of a cell."""
    if c is None:
        return "—"
    right = "" if c["group"] == GROUPS[0] else f" ({c['right_motor']})"
    return f"{_f(c['auroc'])}, {c['alarmed']}{right}"


def _choice_md(ch: dict) -> list[str]:
    f1 = ", ".join(f"{n} {v:.4f}" for n, v in ch["chosen_by"]["val_macro_f1"].items())
    val = ch["policy_validation"]
    pol = (f"chosen on validation flights by `quadfdi evaluate` ({ch['policy_source'][:35]}...)"
           if ch["policy_chosen_on_validation"] else
           f"from the config ({ch['policy_source']}), not a validation choice")
    if val:
        pol += (f"; on those flights {val['fa_per_h']:.2f} false alarms per healthy flight-hour, "
                f"{val['detection_rate']:.0%} of {val['faults']:g} faulty flights detected")
    return [f"Network scored: **{ch['net']}** of `{ch['export']}` (profile `{ch['profile']}`, ONNX Runtime fp32), the "
            f"higher validation macro F1 in `{ch['chosen_by']['file']}` ({ch['chosen_by']['figure']}: {f1}). "
            f"Policy {policy_text(ch['policy'])}, {pol}. No CrazyPAD flight entered either choice.", ""]


def _missed(by: str) -> str:
    return f"missed {by}" if by.startswith("(") else f"missed by {by}"


def _gates_md(gates: list[dict]) -> list[str]:
    lines = ["| gate | value | target | met |", "|---|---|---|---|"]
    for g in gates:
        v = g["value"]
        value = v if not isinstance(v, dict) else \
            f"{_f(v['network'], 3)} (best rule `{v['best_rule']}` {_f(v['best_rule_auroc'], 3)})"
        lines.append(f"| {g['gate']} | {value if value is not None else '—'} | {g['target']} | "
                     f"{'met' if g['met'] else _missed(str(g['missed_by']))} |")
    return lines + [""]


def _summary_md(cells: list[dict], sessions: tuple[str, ...]) -> list[str]:
    head = " | ".join(LABEL[k] for k in NETS + RULE_NAMES)
    lines = [f"| group | session | flights | {head} |", "|---|---|---|" + "---|" * len(NETS + RULE_NAMES)]
    for group in GROUPS:
        for s in sessions:
            first = cell(cells, NETS[0], group, s)
            if first is not None:
                row = " | ".join(_short(cell(cells, k, group, s)) for k in NETS + RULE_NAMES)
                lines.append(f"| {group} | {s} | {first['flights']} | {row} |")
    return lines + [""]


def _network_md(cells: list[dict]) -> list[str]:
    lines = []
    for mode in NETS:
        lines += [f"### The network {MODES[mode]}", "", "| group | session | flights | alarmed | classes (flights) | "
                  "right motor (of alarmed) | motors named | max p(fault) | mean p(fault) | AUROC | could alarm | "
                  "with a vote |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for c in (c for c in cells if c["rule"] == mode):
            classes = ", ".join(f"{k} x{v}" for k, v in c["classes"].items()) or "—"
            named = ", ".join(f"{m} x{n}" for m, n in c["named"].items() if m) or "—"
            right = "—" if c["group"] == GROUPS[0] else str(c["right_motor"])
            lines.append(f"| {c['group']} | {c['session']} | {c['flights']} | {c['alarmed']} | {classes} | {right} | "
                         f"{named} | {_f(c['max_score'], 3)} | {_f(c['pooled_mean_p_fault'], 3)} | "
                         f"{_f(c['auroc'], 3)} | {c['could_alarm']} | {c['voted']} |")
        lines.append("")
    return lines


def _alarms(net: dict) -> str:
    return "; ".join(f"{a['class']} {a['motor'] or ''} at {a['start_s']:.1f} s".replace("  ", " ")
                     for a in net["alarms"]) or "none"


def _rule(r: dict) -> str:
    """A rule's score, motor named, ``!`` when it alarms."""
    return f"{r['score']:.3f} {r['motor']}{' !' if r['alarm'] else ''}"


def _outside(cov: dict | None) -> str:
    """The held-out part's coverage by its reference (vehicle/coverage.py): the largest share outside, and
    on what; "no share model" when the reference holds none."""
    if not cov:
        return "no share model"
    if cov["outside"] is None:
        return f"unknown: {cov['why']}"
    worst = max(cov["regressors"].values(), key=lambda p: p["outside"] or 0.0)
    return f"{cov['outside']:.0%} ({worst['what']}){' !' if cov['beyond'] else ''}"


def _px4_md(px4: dict | None) -> list[str]:
    if px4 is None:
        return ["Not run: no shared flight log folder (`--logs`).", ""]
    lines = [f"Logs `{px4['logs']}`; each flight cut where {px4['fraction']:.0%} of its airborne samples lie before "
             "the cut: the first part is the reference's only flight, the rest is decided (its own hover estimate) "
             "and scored against it.", "",
             "| flight | cut at (s) | airborne: reference / test (s) | alarms, reference | alarms, no reference | "
             "max p(fault) | decided windows | `abs_ref`, `pos_ref`: score, motor (! alarm) | outside the reference's "
             "range |", "|---|---|---|---|---|---|---|---|---|"]
    for f in px4["flights"]:
        if "refused" in f:
            lines.append(f"| {f['flight']} | refused: {f['refused']} | | | | | | | |")
            continue
        s, r = f["split"], f["rules"]
        rules = ", ".join(_rule(r[k]) for k in ("abs_ref", "pos_ref"))
        bridged = f" (gaps bridged at {s['gap_factor']:g} x)" if s.get("gap_factor") else ""
        lines.append(f"| {f['flight']}{bridged} | {s['cut_s']:.1f} | {s['reference_airborne_s']:.1f} / "
                     f"{s['test_airborne_s']:.1f} | {_alarms(f['net_ref'])} | {_alarms(f['net_noref'])} | "
                     f"{f['net_ref']['score']:.3f} | {f['net_ref']['decided_windows']} | {rules} | "
                     f"{_outside(f.get('coverage'))} |")
    if px4["absent"]:
        lines += ["", "Not in the folder: " + ", ".join(px4["absent"]) + "."]
    return lines + [""]


def _flights_md(decided: dict) -> list[str]:
    lines = ["| flight | group | session | network, reference: alarms | max p(fault) | mean p(fault) | "
             + " | ".join(f"`{r}`" for r in RULE_NAMES) + " |", "|---|---|---|---|---|---|" + "---|" * len(RULE_NAMES)]
    for r in decided["rows"]:
        n = r["rules"]["net_ref"]
        rules = " | ".join(_rule(r["rules"][k]) for k in RULE_NAMES)
        lines.append(f"| {r['flight']} | {r.get('group') or r.get('role') or '—'} | {r.get('session') or '—'} | "
                     f"{_alarms(n)} | {n['score']:.3f} | {n['mean_p_fault']:.3f} | {rules} |")
    if decided["refused"]:
        lines += ["", "Refused:", ""] + [f"- {x['flight']}: {x['refused']}" for x in decided["refused"]]
    return lines + [""]


def markdown(result: dict) -> str:
    ref, dec = result["reference"], result["decided"]
    shares = ", ".join(f"{m['log_motor']} {m['mean']:.3f}" for m in ref["motor_share"])
    lines = ["# CrazyPAD scored by a network chosen on simulation", "", f"`{result.get('command', '')}`", ""]
    lines += _choice_md(result["choice"])
    lines += [f"Reference `vehicle.json` from {', '.join(f['file'] for f in ref['flights'])}: shares {shares}; "
              f"{len(ref['warnings'])} warning(s). {len(dec['rows'])} logs of `{result['crazypad']}` decided, "
              f"{len(dec['refused'])} refused, in {dec['wall_s']:g} s ({dec['workers']} worker process(es)).", "",
              "Cells: AUROC of the session's healthy test flights against the group (scikit-learn `roc_auc_score` on "
              "each flight's score: the network's largest p(fault), a rule's share deviation), flights alarmed "
              "(right motor named among them, as the log names it). Rule thresholds as vehicle/rules.py fixes them "
              "from the reference; `*_sym` ignore it.", "", "## Gates", ""]
    lines += _gates_md(result["gates"])
    lines += ["## Per group, all sessions", ""] + _summary_md(result["table"], ("all",))
    lines += ["## Per group and session", ""] + _summary_md(result["table"], SESSIONS[1:])
    lines += ["## The network per group and session", "", "`could alarm`: flights on which the policy could raise at "
              "all (k votes among n windows need k decided windows among n: core.alarm.reach); `with a vote`: "
              "flights with a decided window at or above the policy's threshold.", ""] + _network_md(result["table"])
    lines += ["## The shared healthy PX4 flights", ""] + _px4_md(result["px4"])
    lines += ["## Every CrazyPAD flight", ""] + _flights_md(dec)
    return "\n".join(lines)


def report_section(run_root: str | Path) -> list[str]:
    """The gates and the all-session summary of ``RUN/crazypad/crazypad.json``; nothing when absent."""
    path = Path(run_root) / FOLDER / "crazypad.json"
    if not path.is_file():
        return []
    try:
        res = json.loads(path.read_text())
        lines = ["## CrazyPAD (real labelled damage)", "", f"From `{FOLDER}/crazypad.md` (`{res['command']}`).", ""]
        return lines + _choice_md(res["choice"]) + _gates_md(res["gates"]) + _summary_md(res["table"], ("all",))
    except (ValueError, KeyError, TypeError) as exc:
        raise QuadfdiError(f"{path}: not a crazypad.json ({type(exc).__name__}: {exc})") from None
