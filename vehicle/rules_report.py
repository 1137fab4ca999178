"""``quadfdi vehicle rules``'s outputs: ``rules.json`` (everything) and ``rules.md`` (the same as tables):
the thresholds, the CrazyPAD protocol's table when the flights are CrazyPAD's, and every flight's
shares, scores, alarms and motors named."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.atomic import ensure_dir, write_text
from quadfdi.core.jsonio import write_json
from quadfdi.vehicle.crazypad import GROUPS
from quadfdi.vehicle.rules import K_FLOOR, MARGIN, RULES


def _f(x, digits: int = 3) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def _thresholds_md(limits: dict) -> list[str]:
    lines = ["## Thresholds", "",
             f"Fixed before any damaged flight was scored: the larger of {MARGIN:g} x the largest score over the "
             f"reference's own flights and the noise floor ({K_FLOOR:g} x sqrt(2) x a flight mean's standard error); "
             "a flight alarms when its score is above it.", "",
             "| rule | score | largest reference score (flight) | noise floor | threshold |", "|---|---|---|---|---|"]
    for name, lim in limits.items():
        lines.append(f"| `{name}` | {lim['what']} | {_f(lim['largest_reference_score'])} ({lim['reference_flight']}) | "
                     f"{_f(lim['noise_floor'])} | {_f(lim['threshold'])} |")
    return lines + [""]


def _summary_md(table: list[dict]) -> list[str]:
    """One row per group, all sessions: each rule's AUROC and alarms."""
    head = " | ".join(f"`{r.name}` AUROC, alarmed" for r in RULES)
    lines = ["## CrazyPAD protocol: summary (all sessions)", "",
             "AUROC: the session's healthy test flights against the group's (scikit-learn's `roc_auc_score`); "
             "alarmed: flights above the rule's threshold (for the healthy test flights: false alarms).", "",
             f"| group | flights | {head} |", "|---|---|" + "---|" * len(RULES)]
    for group in GROUPS:
        cells = {c["rule"]: c for c in table if c["group"] == group and c["session"] == "all"}
        if not cells:
            continue
        n = next(iter(cells.values()))["flights"]
        row = " | ".join(f"{_f(cells[r.name]['auroc'], 2)}, {cells[r.name]['alarmed']}" for r in RULES)
        lines.append(f"| {group} | {n} | {row} |")
    return lines + [""]


def _table_md(table: list[dict]) -> list[str]:
    lines = []
    for rule in RULES:
        lines += [f"### `{rule.name}`: {rule.what}", "",
                  "| group | session | flights | alarmed | right motor named (of alarmed) | motors named | max score | "
                  "mean score | AUROC | above every healthy test flight |", "|---|---|---|---|---|---|---|---|---|---|"]
        for c in (c for c in table if c["rule"] == rule.name):
            named = ", ".join(f"{m} x{n}" for m, n in c["named"].items()) or "—"
            right = "—" if c["group"] == "healthy test" else str(c["right_motor"])
            above = "—" if c["above_every_healthy"] is None else str(c["above_every_healthy"])
            lines.append(f"| {c['group']} | {c['session']} | {c['flights']} | {c['alarmed']} | {right} | {named} | "
                         f"{_f(c['max_score'])} | {_f(c['mean_score'])} | {_f(c['auroc'], 3)} | {above} |")
        lines.append("")
    return lines


def _flights_md(rows: list[dict], refused: list[dict]) -> list[str]:
    names = list(rows[0]["shares"]) if rows else []
    lines = ["## Flights", "", "Shares: airborne mean of each motor's command over the four's mean, the log's motor "
             "names; each rule: score, motor named, `!` when it alarms.", "",
             "| flight | role | group | session | " + " | ".join(names) + " | " +
             " | ".join(f"`{r.name}`" for r in RULES) + " |", "|---|---|---|---|" + "---|" * (len(names) + len(RULES))]
    for r in rows:
        rules = " | ".join(f"{v['score']:.3f} {v['motor']}{' !' if v['alarm'] else ''}" for v in r["rules"].values())
        head = " | ".join(str(r.get(k) or "—") for k in ("flight", "role", "group", "session"))
        lines.append(f"| {head} | " + " | ".join(f"{r['shares'][n]:.3f}" for n in names) + f" | {rules} |")
    if refused:
        lines += ["", "Not scored:", ""] + [f"- {x['flight']}: {x['reason']}" for x in refused]
    return lines + [""]


def write_outputs(out: str | Path, result: dict) -> None:
    """DIR/rules.json and DIR/rules.md (each written atomically, the folder created only now)."""
    d = ensure_dir(out)
    ref = result["reference"]
    md = ["# Vehicle reference rules", "", f"`{result['command']}`", "",
          f"Reference `{ref['file']}` (sha256 {ref['sha256'][:12]}), learned from {len(ref['flights'])} flights: "
          + ", ".join(f"`{f}`" for f in ref["flights"]) + f". {len(result['flights'])} flights scored, "
          f"{len(result['refused'])} not scored.", ""]
    md += _thresholds_md(result["thresholds"])
    if result["table"]:
        md += _summary_md(result["table"]) + ["## CrazyPAD protocol: per group and session", ""]
        md += _table_md(result["table"])
    md += _flights_md(result["flights"], result["refused"])
    write_json(d / "rules.json", result)
    write_text(d / "rules.md", "\n".join(md))
