"""report.html: the run report (report.md, quadfdi.report) as one page, with interactive figures.

The page is report.md's own text turned into HTML (a converter for the markdown the stages write:
headings, pipe tables, bullet lists, paragraphs, images, links, inline code and bold), so the two
never disagree; the stages' PNG figures stay files under ``figures/``, linked relatively. Where the
run holds the numbers, a figure drawn with plotly.js (``plotly.min.js`` written beside the page,
detect.html) follows its section: the training history per epoch (``history.json``) and the
batch-1 latencies of every runtime (``bench.json``).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.detect.html import PLOTLY_JS, esc, json_script, page

_INLINE = ((re.compile(r"!\[([^\]]*)\]\(([^)\s]+)\)"), r'<img alt="\1" src="\2" loading="lazy">'),
           (re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)"), r'<a href="\2">\1</a>'),
           (re.compile(r"\*\*([^*]+)\*\*"), r"<strong>\1</strong>"))
SCRIPT = """
JSON.parse(document.getElementById('figures-data').textContent).forEach(function (f) {
  Plotly.newPlot(f.id, f.data, f.layout, {displaylogo: false, responsive: true});
});
"""


def inline(text: str) -> str:
    """Escape, then code spans (kept literal), images, links and bold."""
    parts = re.split(r"(`[^`]*`)", text)
    out = []
    for part in parts:
        if part.startswith("`") and part.endswith("`") and len(part) > 1:
            out.append(f"<code>{esc(part[1:-1])}</code>")
            continue
        s = esc(part).replace("&quot;", '"').replace("&#x27;", "'")
        for pattern, repl in _INLINE:
            s = pattern.sub(repl, s)
        out.append(s)
    return "".join(out)


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def markdown_html(text: str) -> str:
    """HTML of the markdown subset report.md is written in."""
    lines, out, i = text.splitlines(), [], 0
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            i += 1
        elif m := re.match(r"(#{1,6})\s+(.*)", line):
            level = len(m.group(1))
            out.append(f"<h{level}>{inline(m.group(2))}</h{level}>")
            i += 1
        elif line.lstrip().startswith("|"):
            rows = []
            while i < len(lines) and lines[i].lstrip().startswith("|"):
                rows.append(_cells(lines[i]))
                i += 1
            head, body = rows[0], [r for r in rows[1:] if not all(re.fullmatch(r":?-+:?", c) for c in r)]
            out.append("<table><tr>" + "".join(f"<th>{inline(c)}</th>" for c in head) + "</tr>"
                       + "".join("<tr>" + "".join(f"<td>{inline(c)}</td>" for c in r) + "</tr>" for r in body)
                       + "</table>")
        elif re.match(r"\s*[-*]\s+", line):
            items = []
            while i < len(lines) and lines[i].strip():
                if re.match(r"\s*[-*]\s+", lines[i]):
                    items.append(re.sub(r"^\s*[-*]\s+", "", lines[i]))
                else:
                    items[-1] += " " + lines[i].strip()  # a continued item
                i += 1
            out.append("<ul>" + "".join(f"<li>{inline(t)}</li>" for t in items) + "</ul>")
        elif line.startswith("```"):
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            out.append("<pre>" + esc("\n".join(lines[i + 1:j])) + "</pre>")
            i = j + 1
        else:
            para = []
            while i < len(lines) and lines[i].strip() and not re.match(r"(#{1,6}\s|\s*\||\s*[-*]\s|```)", lines[i]):
                para.append(lines[i].strip())
                i += 1
            out.append(f"<p>{inline(' '.join(para))}</p>")
    return "\n".join(out)


def _json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text()) if path.is_file() else None
    except (OSError, ValueError) as exc:
        raise QuadfdiError(f"{path} is not readable JSON: {exc}") from None


def history_figure(root: Path) -> dict | None:
    hist = _json(root / "history.json")
    if not isinstance(hist, dict) or not hist:
        return None
    data = []
    for k, (model, h) in enumerate(sorted(hist.items())):
        if not isinstance(h, dict) or "loss" not in h:
            continue
        epochs = list(range(1, len(h["loss"]) + 1))
        data.append({"type": "scatter", "mode": "lines+markers", "name": f"{model} loss", "x": epochs, "y": h["loss"],
                     "yaxis": "y"})
        if h.get("val_macro_f1"):
            data.append({"type": "scatter", "mode": "lines+markers", "name": f"{model} val. macro F1", "x": epochs,
                         "y": h["val_macro_f1"], "yaxis": "y2", "line": {"dash": "dot"}})
    layout = {"height": 380, "margin": {"t": 30}, "xaxis": {"title": {"text": "epoch"}, "dtick": 1},
              "yaxis": {"title": {"text": "training loss"}, "domain": [0.55, 1]},
              "yaxis2": {"title": {"text": "validation macro F1"}, "domain": [0, 0.45], "range": [0, 1]}}
    return {"id": "fig-history", "after": "Training", "data": data, "layout": layout} if data else None


def latency_figure(root: Path) -> dict | None:
    bench = _json(root / "bench.json")
    if not isinstance(bench, dict) or not bench.get("latency"):
        return None
    recs = [r for r in bench["latency"] if r.get("batch") == 1 and r.get("p50_us")]
    label = lambda r: f"{r['runtime']} {r['precision']} {r['solver']} t{r['threads']}"  # noqa: E731
    data = []
    for model in sorted({r["model"] for r in recs}):
        rs = sorted((r for r in recs if r["model"] == model), key=lambda r: r["p50_us"])
        data.append({"type": "bar", "orientation": "h", "name": model, "y": [label(r) for r in rs],
                     "x": [r["p50_us"] for r in rs],
                     "error_x": {"type": "data", "symmetric": False, "array": [r["p99_us"] - r["p50_us"] for r in rs],
                                 "arrayminus": [0] * len(rs)},
                     "hovertemplate": "%{y}: p50 %{x:.1f} us<extra>" + model + "</extra>"})
    layout = {"height": 160 + 18 * len(recs), "margin": {"l": 220, "t": 30}, "barmode": "group",
              "xaxis": {"title": {"text": "latency per window at batch 1, us (bar p50, whisker p99)"}, "type": "log"}}
    return {"id": "fig-latency", "after": "Bench", "data": data, "layout": layout} if data else None


def _place(body: str, fig: dict) -> str:
    """``body`` with the figure's div at the end of the section whose h2 starts with ``fig['after']``."""
    div = f'<div id="{fig["id"]}" class="figure"></div>'
    m = re.search(r"<h2>" + re.escape(fig["after"]), body)
    if not m:
        return body + div
    nxt = body.find("<h2>", m.end())
    return body + div if nxt < 0 else body[:nxt] + div + "\n" + body[nxt:]


def report_html(root: Path, markdown: str) -> str:
    """The whole page of the run report whose markdown is ``markdown``."""
    body = markdown_html(markdown)
    figs = [f for f in (history_figure(root), latency_figure(root)) if f]
    for f in figs:
        body = _place(body, f)
    body += json_script("figures-data", [{k: f[k] for k in ("id", "data", "layout")} for f in figs])
    return page(f"quadfdi run report: {root.name}", body, PLOTLY_JS, SCRIPT)
