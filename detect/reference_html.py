"""The vehicle reference on the pages: a flight page's section (each quantity against the reference, the
four share rules), each alarm's share deviations, and the fleet index's columns (detect.reference)."""

from __future__ import annotations

from quadfdi.detect.html import esc, fmt


def _signed(x, nd: int = 3) -> str:
    return "\u2014" if x is None else f"{x:+.{nd}f}"


def _z(x) -> str:
    return "\u2014" if x is None else f"{x:+.1f}"


def _row(what: str, e: dict, nd: int = 3) -> str:
    why = f" <span class=\"muted\">({esc(e['why'])})</span>" if e.get("why") else ""
    return (f"<tr><td>{esc(what)}{why}</td><td class=\"num\">{fmt(e['value'], nd)}</td>"
            f"<td class=\"num\">{fmt(e['reference'], nd)}</td><td class=\"num\">{_signed(e['deviation'], nd)}</td>"
            f"<td class=\"num\">{fmt(e['spread'], nd)}</td><td class=\"num\">{_z(e['z'])}</td>"
            f"<td>{esc(e['unit'])}</td></tr>")


def section(record: dict | None, note: str | None) -> str:
    """The flight page's "Vehicle reference" section (or the line saying there is none)."""
    if record is None:
        return f"<h2>Vehicle reference</h2><p class=\"muted\" id=\"no-reference\">{esc(note or '')}</p>"
    rows = [_row(f"motor {m['rotor']} ({m['log_motor']}) share", m) for m in record["motor_share"]]
    rows.append(_row("hover collective", record["hover_collective"]))
    rows.append(_row("sag per ampere per cell", record["sag_v_per_a_cell"], 4))
    rows += [_row(f"{name} at this thrust", e, 2) for name, e in record["vibration"].items()]
    rows += [_row(f"ESC {key} motor {e['rotor']} ({e['log_motor']})", e) for key, es in record["esc"].items()
             for e in es]
    rules = "".join(f"<tr><td>{esc(name)}</td><td class=\"num\">{r['score']:.3f}</td><td>{esc(r['motor'])}</td>"
                    f"<td class=\"num\">{r['threshold']:.3f}</td><td class=\"{'alarm' if r['alarm'] else 'ok'}\">"
                    f"{'above' if r['alarm'] else 'below'}</td></tr>" for name, r in record["rules"].items())
    own = " This flight is one the reference was learned from." if record["reference_flight"] else ""
    return (f"<h2>Vehicle reference</h2><p id=\"reference\" data-file=\"{esc(record['file'])}\">"
            f"{esc(record['file'])} (sha256 {esc(record['sha256'][:12])}, {esc(record['chosen_by'])}), learned from "
            f"{len(record['learned_from'])} healthy flight(s): what this vehicle's own flights say, beside the model "
            f"(which does not read it).{own} Shares: means over {esc(record['motor_share'][0]['basis'])} (the "
            "model at this flight's forward speed and yaw rate); z: the deviation in the reference's between-flight "
            "spreads.</p>"
            "<table id=\"reference-quantities\"><tr><th>quantity</th><th>this flight</th><th>reference</th>"
            "<th>deviation</th><th>between-flight spread</th><th>z</th><th>unit</th></tr>" + "".join(rows)
            + "</table>" + coverage_paragraph(record.get("coverage"))
            + "<table id=\"reference-rules\"><tr><th>share rule</th><th>score</th><th>motor</th>"
              "<th>threshold</th><th></th></tr>" + rules + "</table>")


def coverage_paragraph(cov: dict | None) -> str:
    """How much of the flight flies outside the reference flights' forward speed and yaw rate ranges."""
    if not cov:
        return ("<p id=\"reference-coverage\" class=\"muted\">The reference holds no share model (too few steady "
                "samples): shares are compared with its airborne mean.</p>")
    if cov["outside"] is None:
        return f"<p id=\"reference-coverage\" class=\"muted\">Coverage by the reference: {esc(cov['why'])}.</p>"
    parts = [f"{p['what']} {p['range_5_95'][0]:.2f} to {p['range_5_95'][1]:.2f} {esc(p['unit'])}: "
             f"{fmt_share(p['outside'])} of this flight outside ({p['seconds_outside']:.1f} s)"
             for p in cov["regressors"].values()]
    cls = "alarm" if cov["beyond"] else "muted"
    more = (f" More than {cov['limit']:.0%}: this flight flies unlike the reference flights, and its shares are "
            "compared with the share model held at the edge of what they flew; learn the reference from flights "
            "that fly like this one." if cov["beyond"] else "")
    return (f"<p id=\"reference-coverage\" class=\"{cls}\" data-outside=\"{cov['outside']}\">What the reference "
            f"flights flew (5-95 %): {esc('; '.join(parts))}.{esc(more)}</p>")


def fmt_share(x) -> str:
    return "\u2014" if x is None else f"{x:.0%}"


def evidence_table(ev: dict) -> str:
    """An alarm's motor share deviations from the reference over its span (empty without a reference)."""
    dev = ev.get("reference_shares")
    if not dev:
        return ""
    rows = "".join(f"<tr><td>{d['motor']} ({esc(d['log_motor'])})</td><td class=\"num\">{d['share']:.3f}</td>"
                   f"<td class=\"num\">{d['reference']:.3f}</td><td class=\"num\">{d['deviation']:+.3f}</td>"
                   f"<td class=\"num\">{_z(d['z'])}</td></tr>" for d in dev)
    return ("<p>Motor shares against the vehicle reference over the alarm (medians of the airborne samples; the "
            "reference at each sample's operating point):</p><table class=\"reference-deviation\"><tr><th>motor"
            "</th><th>share</th><th>reference</th><th>deviation</th><th>z</th></tr>" + rows + "</table>")


def index_columns(rows: list[dict]) -> list[tuple[str, str]]:
    """The fleet index's reference columns (title, sort type): none when no flight has a reference."""
    if not any(r.get("vehicle_reference") for r in rows):
        return []
    return ([("reference", "text")] + [(f"\u0394 share m{k}", "num") for k in range(1, 5)]
            + [("\u0394 hover", "num"), ("\u0394 sag, V/A/cell", "num"), ("\u0394 vibration", "num"),
               ("abs_ref score", "num"), ("outside reference", "num")])


def index_cells(row: dict) -> list[tuple[str, str]]:
    """(sort value, html) of one flight's reference columns (dashes without a reference)."""
    ref = row.get("vehicle_reference")
    if ref is None:
        return [("", f"<span class=\"muted\" title=\"{esc(row.get('reference_note'))}\">none</span>")] + \
            [("", "\u2014")] * 9

    def num(x, nd=3, extra=""):
        return ("" if x is None else f"{x:.6g}", f"<span style=\"white-space:nowrap\">{_signed(x, nd)}{extra}</span>")

    cells = [(ref["file"], esc(ref["file"]))]
    for s in ref["shares"]:
        z = "" if s["z"] is None else f" {s['z']:+.1f}\u03c3"
        cells.append(num(s["deviation"], 3, f" <small class=\"muted\">{esc(s['log_motor'])}{z}</small>"))
    r = ref["rules"]["abs_ref"]
    flag = f" <small class=\"{'alarm' if r['alarm'] else 'muted'}\">{esc(r['motor'])}</small>"
    cells += [num(ref["hover"]), num(ref["sag"], 4), num(ref["vibration"], 2),
              (f"{r['score']:.6g}", f"<span style=\"white-space:nowrap\">{r['score']:.3f}{flag}</span>"),
              _outside_cell(ref.get("outside"), ref.get("beyond", False))]
    return cells


def _outside_cell(outside, beyond: bool) -> tuple[str, str]:
    """The share of the flight past the reference's flown ranges (vehicle/coverage.py); flagged when beyond its
    LIMIT."""
    if outside is None:
        return "", "\u2014"
    cls = "alarm" if beyond else "muted"
    return f"{outside:.6g}", f"<span class=\"{cls}\">{outside:.0%}</span>"
