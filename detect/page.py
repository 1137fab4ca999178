"""One flight's page (``index.html``): the flight's facts, its alarms (each a link that zooms every
panel to it), the linked panels (detect.flightplot), an evidence section per alarm
(detect.evidence: which input groups carried p_fault past the threshold, the motor shares and,
with a vehicle reference, their deviations from it), the flight against the vehicle reference
(detect.reference_html), and the channels the log holds with where each came from.

The page loads the plotting library from ``script_src`` (``../plotly.min.js`` in a fleet folder)
and keeps what it drew in ``window.quadfdi`` (``figure``, ``alarms``, ``evidence``, ``reference``), so a test or a
script reads back what is on screen.
"""

from __future__ import annotations

import json

import numpy as np

from quadfdi.core.alarm import reach_note
from quadfdi.detect.flightplot import UNDECIDED, figure
from quadfdi.detect.html import esc, fmt, json_script, page
from quadfdi.detect.reference_html import evidence_table, section

SCRIPT = """
const q = window.quadfdi = {figure: JSON.parse(document.getElementById('figure-data').textContent),
  alarms: JSON.parse(document.getElementById('alarms-data').textContent),
  evidence: JSON.parse(document.getElementById('evidence-data').textContent),
  reference: JSON.parse(document.getElementById('reference-data').textContent)};
const cfg = {displaylogo: false, responsive: true};
Plotly.newPlot('flight-plot', q.figure.data, q.figure.layout, cfg);
q.evidence.forEach(function (ev) {
  const g = ev.groups.slice().reverse();
  Plotly.newPlot('evidence-plot-' + ev.alarm, [{type: 'bar', orientation: 'h', x: g.map(r => r.drop),
    y: g.map(r => r.group), text: g.map(r => r.crossed ? r.crossed + ' crossed' : ''), textposition: 'auto',
    marker: {color: g.map(r => r.crossed ? '#b00020' : '#7a8ca0')},
    hovertemplate: '%{y}: p_fault drops by %{x:.3f}<extra></extra>'}],
    {height: 60 + 22 * g.length, margin: {l: 120, r: 20, t: 10, b: 40},
     xaxis: {title: {text: 'drop of mean p_fault when the group is occluded'}}}, cfg);
});
document.querySelectorAll('a.zoom').forEach(function (a) {
  a.addEventListener('click', function (e) {
    e.preventDefault();
    Plotly.relayout('flight-plot', {'xaxis.range': [+a.dataset.from, +a.dataset.to]});
    document.getElementById('flight-plot').scrollIntoView();
  });
});
"""


def vehicle_facts(flight: dict) -> dict:
    """autopilot, frame, cells and the land detector's source, from flight.npz."""
    v = json.loads(str(flight["vehicle"]))
    return {"autopilot": str(flight["autopilot"]), "frame": v.get("frame") or "?",
            "cells": (v.get("battery") or {}).get("cells"), "airborne_source": v.get("airborne_source", "")}


def _facts(rec: dict, flight: dict, date: str | None, duration: float) -> str:
    veh = vehicle_facts(flight)
    pol = rec["policy"]
    hov = rec["hover"]
    rows = [("log", rec["flight"]), ("date", date or "\u2014"),
            ("vehicle", f"{veh['autopilot']}, {veh['frame']}, {veh['cells'] or '?'}S"),
            ("duration", f"{duration:.1f} s ({rec['airborne_s']:.1f} s airborne; {veh['airborne_source']})"),
            ("decided", f"{rec['exposure_s']:.1f} s ({rec['decided_windows']} of {rec['windows']} windows)"),
            ("model", f"{rec['net']} {rec['precision']} on {rec['runtime']}, profile {rec['profile']} ({rec['model']})"),
            ("alarm policy", f"p_fault \u2265 {pol['threshold']:g} in {pol['k']} of {pol['n']} windows, clear after "
                             f"{pol['clear_m']}{', latched' if pol.get('latch') else ''} ({rec['policy_source']})"),
            ("hover estimate", f"command {hov['cmd']:.3f}, current {fmt(hov['cur_a'], 2)} A, frozen at "
                               f"{hov['freeze_s']:.1f} s")]
    if rec.get("channels_absent"):
        rows.append(("channels absent", ", ".join(rec["channels_absent"])))
    return "<table class=\"facts\">" + "".join(f"<tr><td>{esc(k)}</td><td>{esc(v)}</td></tr>" for k, v in rows) + \
        "</table>"


def _alarm_table(rec: dict, t_last: float) -> str:
    if not rec["alarms"]:
        note = reach_note(rec.get("alarm_reach"))
        if note:
            return f"<p class=\"refused\">{esc(note[0].upper() + note[1:])}.</p>"
        return "<p class=\"ok\">No alarm.</p>"
    rows = []
    for i, a in enumerate(rec["alarms"], 1):
        end = a["end_s"] if a["end_s"] is not None else t_last
        rows.append(f"<tr id=\"alarm-{i}\"><td>{i}</td><td class=\"alarm\">{esc(a['class'])}</td>"
                    f"<td>{esc(a.get('motor') or chr(0x2014))}</td><td class=\"num\">{a['start_s']:.2f}</td>"
                    f"<td class=\"num\">{fmt(a['end_s'], 2, 'active at the end')}</td>"
                    f"<td class=\"num\">{a['peak_p_fault']:.3f}</td><td><a href=\"#flight-plot\" class=\"zoom\" "
                    f"data-from=\"{a['start_s'] - 5:.2f}\" data-to=\"{end + 5:.2f}\">zoom</a> \u00b7 "
                    f"<a href=\"#evidence-{i}\">evidence</a></td></tr>")
    return ("<table><tr><th>#</th><th>class</th><th>motor</th><th>start, s</th><th>end, s</th><th>peak p_fault</th>"
            "<th></th></tr>" + "".join(rows) + "</table>")


def _evidence_html(ev: dict) -> str:
    head = (f"<h3>Alarm {ev['alarm']}: {esc(ev['class'])}{' motor ' + str(ev['motor']) if ev['motor'] else ''}, "
            f"from {ev['start_s']:.2f} s</h3><p>Mean p_fault {ev['p_fault']:.3f} over {ev['windows']} of the alarm's "
            f"windows ({ev['voting_windows']} at or above the threshold {ev['threshold']:g}). Each input group "
            f"replaced by its {esc(ev['reference'])}, re-run on {esc(ev['runtime'])}:</p>")
    rows = "".join(f"<tr><td>{esc(r['group'])}</td><td>{esc(', '.join(r['channels']))}</td>"
                   f"<td class=\"num\">{r['p_fault']:.3f}</td><td class=\"num\">{r['drop']:+.3f}</td>"
                   f"<td class=\"num\">{r['crossed']}</td></tr>" for r in ev["groups"])
    table = ("<table><tr><th>occluded group</th><th>channels</th><th>mean p_fault</th><th>drop</th>"
             "<th>windows below the threshold</th></tr>" + rows + "</table>")
    shares = ""
    if ev.get("motor_shares"):
        srows = "".join(f"<tr><td>{s['motor']}</td><td class=\"num\">{s['during']:.3f}</td>"
                        f"<td class=\"num\">{fmt(s['outside'], 3)}</td><td class=\"num\">"
                        f"{'' if s['change'] is None else format(s['change'], '+.3f')}</td></tr>"
                        for s in ev["motor_shares"])
        shares = ("<p>Motor command shares (each motor over the four's mean; medians while airborne):</p><table>"
                  "<tr><th>motor</th><th>during the alarm</th><th>outside every alarm</th><th>change</th></tr>"
                  + srows + "</table>")
    return (f"<div class=\"evidence\" id=\"evidence-{ev['alarm']}\" data-start-s=\"{ev['start_s']}\">{head}"
            f"<div id=\"evidence-plot-{ev['alarm']}\"></div>{table}{shares}{evidence_table(ev)}</div>")


def _channels_table(flight: dict) -> str:
    names, status = [str(n) for n in flight["channel_names"]], [str(s) for s in flight["channel_status"]]
    src, rate = [str(s) for s in flight["channel_sources"]], np.asarray(flight["channel_rates_hz"], np.float64)
    rows = "".join(f"<tr><td>{esc(n)}</td><td class=\"{'ok' if s == 'ok' else 'muted'}\">{esc(s)}</td>"
                   f"<td>{esc(c)}</td><td class=\"num\">{fmt(r, 1, '') if r > 0 else ''}</td></tr>"
                   for n, s, c, r in zip(names, status, src, rate))
    return ("<details><summary>Channels of the log (flight.npz)</summary><table><tr><th>channel</th><th>status</th>"
            "<th>source</th><th>logged rate, Hz</th></tr>" + rows + "</table></details>")


def flight_page(result: dict, flight: dict, evidence: list[dict], date: str | None, script_src: str,
                index_href: str | None = None) -> str:
    """The whole page of one detected flight."""
    rec = result["record"]
    time = np.asarray(flight["time"], np.float64)
    duration = float(time[-1] - time[0]) if len(time) else 0.0
    fig = figure(result, flight)
    spans = "".join(f"<span style=\"background:{c};padding:0 0.6em;margin-right:0.4em\">&nbsp;</span>{esc(t)} "
                    for t, c in UNDECIDED.values())
    back = f"<p><a href=\"{esc(index_href)}\">\u2190 all flights</a></p>" if index_href else ""
    notes = json.loads(str(flight["notes"])) if "notes" in flight else []
    body = (f"{back}<h1>{esc(rec['flight'])}: {len(rec['alarms'])} alarm(s)</h1>{_facts(rec, flight, date, duration)}"
            f"<h2>Alarms</h2>{_alarm_table(rec, float(time[-1]))}<h2>Flight</h2>"
            f"<p class=\"muted\">Drag to zoom (every panel follows), double-click to reset. Red: alarms; shaded: no "
            f"decision ({spans}); dashed green: the land detector's take-off and touchdown.</p>"
            "<div id=\"flight-plot\"></div>"
            + (f"<h2>Evidence</h2>{''.join(_evidence_html(ev) for ev in evidence)}" if evidence else "")
            + section(rec.get("vehicle_reference"), result.get("reference_note"))
            + f"<h2>Log</h2>{_channels_table(flight)}"
            + ("<details><summary>Ingest notes</summary><ul>" + "".join(f"<li>{esc(n)}</li>" for n in notes)
               + "</ul></details>" if notes else "")
            + json_script("figure-data", fig) + json_script("alarms-data", rec["alarms"])
            + json_script("evidence-data", evidence) + json_script("reference-data", rec.get("vehicle_reference")))
    return page(f"{rec['flight']} \u2014 quadfdi detect", body, script_src, SCRIPT)
