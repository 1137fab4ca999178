"""The fleet index (``DIR/index.html``): one row per decided flight, sortable by any column (a few
lines of JavaScript), each linking to its page, with a sparkline of p_fault over the flight; then
the logs that were refused, each with its one-line reason; with vehicle references, columns of each
flight against its reference (detect.reference_html). It reads only ``summary.json``'s rows,
so it needs no plotting library: the sparklines are inline SVG."""

from __future__ import annotations

from quadfdi.detect.html import esc, fmt, page
from quadfdi.detect.reference_html import index_cells, index_columns

SORT_JS = """
document.querySelectorAll('th.sortable').forEach(function (th) {
  th.addEventListener('click', function () {
    const body = th.closest('table').tBodies[0], col = th.cellIndex, num = th.dataset.type === 'num';
    const dir = th.dataset.dir === 'asc' ? -1 : 1;
    th.dataset.dir = dir === 1 ? 'asc' : 'desc';
    const key = function (row) {
      const v = row.cells[col].dataset.v;
      if (!num) return v;
      const x = parseFloat(v);
      return isNaN(x) ? -Infinity : x;
    };
    Array.from(body.rows).sort(function (a, b) {
      const x = key(a), y = key(b);
      return (x < y ? -1 : x > y ? 1 : 0) * dir;
    }).forEach(function (r) { body.appendChild(r); });
  });
});
"""
COLUMNS = (("flight", "text"), ("vehicle", "text"), ("date", "text"), ("duration, s", "num"), ("decided, s", "num"),
           ("channels absent", "text"), ("alarms", "num"), ("worst p_fault", "num"), ("p_fault over the flight", "num"))


def sparkline(row: dict, width: int = 160, height: int = 28) -> str:
    """Inline SVG: p_fault at each decided window's end, the threshold dotted, alarms shaded."""
    pts, t0, t1 = row["spark"], row["t0"], row["t1"]
    span = max(t1 - t0, 1e-9)
    x = lambda t: (t - t0) / span * width  # noqa: E731
    y = lambda p: (1.0 - p) * (height - 2) + 1  # noqa: E731
    parts = [f'<svg width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img" '
             f'aria-label="p_fault over the flight"><rect width="{width}" height="{height}" fill="#fafafa"/>']
    for a in row["alarms"]:
        end = a["end_s"] if a["end_s"] is not None else t1
        parts.append(f'<rect x="{x(a["start_s"]):.1f}" width="{max(x(end) - x(a["start_s"]), 1.0):.1f}" y="0" '
                     f'height="{height}" fill="rgba(220,0,40,0.18)"/>')
    thr = y(row["threshold"])
    parts.append(f'<line x1="0" x2="{width}" y1="{thr:.1f}" y2="{thr:.1f}" stroke="#b00020" stroke-dasharray="2,2" '
                 'stroke-width="0.8"/>')
    segs, cur = [], []
    for t, p in pts:  # a None breaks the line: undecided windows draw nothing
        if p is None:
            segs, cur = segs + ([cur] if cur else []), []
        else:
            cur.append(f"{x(t):.1f},{y(p):.1f}")
    segs += [cur] if cur else []
    parts += [f'<polyline points="{" ".join(s)}" fill="none" stroke="#222" stroke-width="1"/>' for s in segs]
    return "".join(parts) + "</svg>"


def _alarm_class(r: dict) -> str:
    """alarm; ok; refused (amber) where the policy could raise no alarm on the flight's decided windows."""
    return "alarm" if r["alarms"] else "ok" if r.get("alarm_possible", True) else "refused"


def _row(r: dict, with_reference: bool) -> str:
    veh = r["vehicle"]
    vehicle = f"{veh['autopilot']}, {veh['frame']}, {veh['cells'] or '?'}S"
    alarms = "; ".join(f"{a['class']}{' m' + str(a['motor']) if a.get('motor') else ''} at {a['start_s']:.1f} s"
                       for a in r["alarms"]) or ("none" if r.get("alarm_possible", True) else "none possible")
    absent = ", ".join(r["channels_absent"]) or "\u2014"
    cells = [(r["name"], f'<a href="{esc(r["href"])}">{esc(r["name"])}</a>'), (vehicle, esc(vehicle)),
             (r["date"] or "", esc(r["date"] or "\u2014")), (f"{r['duration_s']:.2f}", fmt(r["duration_s"])),
             (f"{r['decided_s']:.2f}", fmt(r["decided_s"])), (absent, esc(absent)),
             (str(len(r["alarms"])), f'<span class="{_alarm_class(r)}">{esc(alarms)}</span>'),
             (f"{r['worst_p_fault']:.4f}", fmt(r["worst_p_fault"], 3)), (f"{r['worst_p_fault']:.4f}", sparkline(r))]
    cells += index_cells(r) if with_reference else []
    tds = "".join(f'<td data-v="{esc(v)}"{" class=num" if i in (3, 4, 7) or i > 9 else ""}>{h}</td>'
                  for i, (v, h) in enumerate(cells))
    return f'<tr data-name="{esc(r["name"])}">{tds}</tr>'


def index_page(summary: dict) -> str:
    rows, refused = summary["flights"], summary["refused"]
    n_alarm = sum(1 for r in rows if r["alarms"])
    extra = index_columns(rows)
    heads = "".join(f'<th class="sortable" data-type="{t}">{esc(h)}</th>' for h, t in COLUMNS + tuple(extra))
    body = "".join(_row(r, bool(extra)) for r in rows)
    table = (f'<table id="flights"><thead><tr>{heads}</tr></thead><tbody>{body}</tbody></table>' if rows
             else "<p>No flight was decided.</p>")
    ref = ""
    if refused:
        ref = ("<h2>Refused logs</h2><table id=\"refused\"><tr><th>log</th><th>reason</th></tr>"
               + "".join(f'<tr><td>{esc(r["log"])}</td><td class="refused">{esc(r["reason"])}</td></tr>'
                         for r in refused) + "</table>")
    m = summary["model"]
    body = (f"<h1>quadfdi detect: {len(rows)} flight(s) decided, {n_alarm} with alarms, {len(refused)} refused</h1>"
            f"<p>Model {esc(m['export'])}: {esc(m['net'])} {esc(m['precision'])} on {esc(m['runtime'])}, profile "
            f"{esc(m['profile'] or '?')}. Exit status {summary['exit_status']} ({esc(summary['exit_meaning'])}). "
            "Click a column's title to sort; the sparkline is p_fault at each decided window's end (dotted: the "
            "alarm threshold; red: alarms)." + (" With a vehicle reference: each motor's share, the hover collective, "
            "the sag and the vibration minus what the vehicle's own healthy flights give (\u03c3: the reference's "
            "between-flight spread), and the largest-deviation share rule's score (red: above its threshold); "
            "the model does not read them." if extra else "") + "</p>" + table + ref)
    return page("quadfdi detect \u2014 flights", body, None, SORT_JS)
