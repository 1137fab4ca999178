"""The flight page's main figure (plotly.js JSON): panels on one linked time axis, alarms, undecided
spans and the land detector's marks.

Panels, each drawn only when the flight logs it (flight.npz ``channel_status`` "ok"): attitude
(deg; yaw hidden until clicked), body rates (deg/s), velocity (m/s, NWU), the pack's voltage per
cell and current, the motor command shares (each motor's command over the four's mean, the same
sample: a rotor working harder than the others stands out without any vehicle scale), vibration,
ESC rpm, current and temperature; last, p(class) of each fault class and p_fault at each window's
end with the policy's threshold. Every panel shares the x axis: zooming one zooms all.

With a vehicle reference (detect.reference), the motor share panel also draws each motor's reference
share at the flight's operating point (dashed, airborne samples) inside its band of +- the reference's
between-flight spread (``meta.kind`` "reference" and "reference band").

Overlays on every panel: each alarm's span (red; open-ended alarms run to the end) with a marker
trace at its start (``meta.kind`` "alarm": what tests and scripts read back), the spans where no
decision was made, shaded by reason, and the airborne segments' take-off and touchdown lines.

What is drawn is downsampled (what is decided is not): each line keeps, per bucket of samples, its
minimum and maximum (``MAX_BUCKETS`` buckets), so a spike survives and a 10-minute flight stays
small; values keep 4 significant digits.
"""

from __future__ import annotations

import numpy as np

from quadfdi.detect.html import rounded

MAX_BUCKETS = 1000
SHARE_PANEL = "motor command / mean of four"
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")
DEG = 180.0 / np.pi
UNDECIDED = {"ground": ("not airborne", "rgba(120,120,120,0.18)"),
             "hover": ("no steady hover yet (hover estimate not frozen)", "rgba(255,190,0,0.20)"),
             "gap": ("a channel the model reads has a gap", "rgba(0,120,255,0.15)")}


def downsample(t: np.ndarray, v: np.ndarray, buckets: int = MAX_BUCKETS) -> tuple[np.ndarray, np.ndarray]:
    """(t, v) reduced to each bucket's min and max in time order (NaN gaps kept as gaps)."""
    n = len(t)
    if n <= 2 * buckets:
        return t, v
    edges = np.linspace(0, n, buckets + 1).astype(int)
    keep = []
    for a, b in zip(edges[:-1], edges[1:]):
        seg = v[a:b]
        if not np.isfinite(seg).any():
            keep.append(a)  # a NaN: the gap stays a gap
            continue
        i, j = a + int(np.nanargmin(seg)), a + int(np.nanargmax(seg))
        keep += sorted({i, j})
    idx = np.array(keep)
    return t[idx], v[idx]


def _channel(flight: dict, name: str) -> np.ndarray | None:
    names = [str(n) for n in flight["channel_names"]]
    if name not in names or str(flight["channel_status"][names.index(name)]) != "ok":
        return None
    return np.asarray(flight["telemetry"][:, names.index(name)], np.float64)


def _shares(cols: list[np.ndarray | None], floor: float) -> list[np.ndarray] | None:
    if any(c is None for c in cols):
        return None
    mean = np.mean(cols, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return [np.where(mean > floor, c / mean, np.nan) for c in cols]


def signal_panels(flight: dict) -> list[tuple[str, list[tuple[str, np.ndarray, bool]]]]:
    """(panel title, [(line name, (T,) values, visible)]) of the logged channels."""
    ch = lambda n: _channel(flight, n)  # noqa: E731
    cells = None
    try:
        import json

        cells = (json.loads(str(flight["vehicle"])).get("battery") or {}).get("cells")
    except ValueError:
        pass
    panels = []

    def add(title, lines):
        lines = [(n, v, vis) for n, v, vis in lines if v is not None]
        if lines:
            panels.append((title, lines))

    ang = lambda n: None if ch(n) is None else ch(n) * DEG  # noqa: E731
    add("attitude, deg", [("roll", ang("roll"), True), ("pitch", ang("pitch"), True), ("yaw", ang("yaw"), False)])
    add("body rates, deg/s", [(n, ang(n), True) for n in ("p", "q", "r")])
    add("velocity (NWU), m/s", [(n, ch(n), True) for n in ("vx", "vy", "vz")])
    vb = ch("V_b")
    add("pack voltage per cell, V" if cells else "pack voltage, V",
        [("V_b / cell" if cells else "V_b", None if vb is None else vb / (cells or 1), True)])
    add("current, A", [("I_b", ch("I_b"), True)])
    shares = _shares([ch(f"thr{m}") for m in range(1, 5)], 0.05)
    add(SHARE_PANEL, [(f"motor {m + 1}", s, True) for m, s in enumerate(shares or [])])
    add("vibration, m/s^2", [(n, ch(n), True) for n in ("vib_px4", "vib_ap")])
    add("ESC rpm", [(f"rpm{m}", ch(f"rpm{m}"), True) for m in range(1, 5)])
    add("ESC current, A", [(f"esc_cur{m}", ch(f"esc_cur{m}"), True) for m in range(1, 5)])
    add("ESC temperature, degC", [(f"esc_temp{m}", ch(f"esc_temp{m}"), True) for m in range(1, 5)])
    return panels


def undecided_spans(result: dict, flight: dict) -> list[tuple[float, float, str]]:
    """(start, end, reason key) of the time that no decision covers, merged per reason. Window i
    speaks for (t_end[i-1], t_end[i]]; the first for the flight's start up to its end."""
    arr, fi, window = result["arrays"], result["inputs"], result["window"]
    t_end, dec = np.asarray(arr["t_end"], np.float64), np.asarray(arr["decided"], bool)
    air = np.asarray(flight["airborne"], bool)
    freeze_t = float(fi.time[fi.hover.freeze])
    spans: list[list] = []
    for i in np.flatnonzero(~dec):
        s = int(fi.starts[i])
        if t_end[i] < freeze_t:
            why = "hover"
        elif not air[s:s + window].all():
            why = "ground"
        else:
            why = "gap"
        a = float(fi.time[0]) if i == 0 else float(t_end[i - 1])
        if spans and spans[-1][2] == why and abs(spans[-1][1] - a) < 1e-6:
            spans[-1][1] = float(t_end[i])
        else:
            spans.append([a, float(t_end[i]), why])
    return [tuple(s) for s in spans]


def _line(name, t, v, axis, color, visible=True, legend="legend") -> dict:
    ts, vs = downsample(t, v)
    # On the uniform grid, x0 and dx say what an x array would at a fraction of the bytes
    steps = np.diff(ts)
    x = ({"x0": float(ts[0]), "dx": float(steps[0])} if len(ts) == len(t) and len(ts) > 1
         and np.allclose(steps, steps[0], atol=1e-6) else {"x": rounded(ts, 6)})
    return {"type": "scatter", "mode": "lines", "name": name, **x, "y": rounded(vs),
            "xaxis": "x", "yaxis": axis, "line": {"width": 1, "color": color}, "legend": legend,
            "visible": True if visible else "legendonly", "hovertemplate": "%{y:.4g}"}


def probability_traces(result: dict, axis: str, legend: str) -> list[dict]:
    rec, arr = result["record"], result["arrays"]
    names = [str(c) for c in arr["class_names"]]
    t = np.asarray(arr["t_end"], np.float64)
    proba = np.asarray(arr["proba"], np.float64)
    out = []
    for k, name in enumerate(names):
        if name == "Healthy":
            continue
        out.append(_line(f"p({name})", t, proba[:, k], axis, COLORS[len(out) % len(COLORS)], legend=legend))
    p_fault = 1.0 - proba[:, names.index("Healthy")]
    fault = _line("p_fault", t, p_fault, axis, "#000000", legend=legend)
    fault["line"]["width"] = 1.6
    thr = float(rec["policy"]["threshold"])
    out += [fault, {"type": "scatter", "mode": "lines", "name": f"threshold {thr:g}", "x": [float(t[0]), float(t[-1])],
                    "y": [thr, thr], "xaxis": "x", "yaxis": axis, "legend": legend,
                    "line": {"width": 1, "dash": "dot", "color": "#b00020"}, "hoverinfo": "skip"}]
    return out


def _overlays(result: dict, flight: dict, axis: str, legend: str) -> tuple[list[dict], list[dict], list[dict]]:
    """(marker traces, shapes, annotations): alarms, undecided spans, take-off and touchdown."""
    rec = result["record"]
    t_last = float(result["inputs"].time[-1])
    thr = float(rec["policy"]["threshold"])
    traces, shapes, notes = [], [], []
    for i, a in enumerate(rec["alarms"], 1):
        end = a["end_s"] if a["end_s"] is not None else t_last
        label = f"alarm {i}: {a['class']}" + (f" motor {a['motor']}" if a.get("motor") else "")
        shapes.append({"type": "rect", "xref": "x", "yref": "paper", "x0": a["start_s"], "x1": end, "y0": 0, "y1": 1,
                       "fillcolor": "rgba(220,0,40,0.13)", "line": {"width": 0}, "layer": "below"})
        traces.append({"type": "scatter", "mode": "markers+text", "name": label, "x": [a["start_s"]], "y": [thr],
                       "xaxis": "x", "yaxis": axis, "legend": legend, "text": [f"\u25b2 {i}"], "textposition": "top center",
                       "marker": {"symbol": "triangle-up", "size": 11, "color": "#b00020"},
                       "meta": {"kind": "alarm", "index": i, "start_s": a["start_s"], "end_s": a["end_s"],
                                "class": a["class"], "motor": a.get("motor")},
                       "hovertemplate": f"{label}<br>start %{{x:.2f}} s<extra></extra>"})
    shown = set()
    for a, b, why in undecided_spans(result, flight):
        text, color = UNDECIDED[why]
        shapes.append({"type": "rect", "xref": "x", "yref": "paper", "x0": a, "x1": b, "y0": 0, "y1": 1,
                       "fillcolor": color, "line": {"width": 0}, "layer": "below", "name": f"undecided: {text}",
                       "showlegend": why not in shown, "legend": legend, "legendgroup": why})
        shown.add(why)
    marks = [(float(x), what) for a, b in np.asarray(flight["airborne_segments"], np.float64).reshape(-1, 2)
             for x, what in ((a, "take-off"), (b, "touchdown"))]
    for k, (x, what) in enumerate(marks):  # labels alternate in height: a touchdown and the next take-off
        shapes.append({"type": "line", "xref": "x", "yref": "paper", "x0": x, "x1": x, "y0": 0, "y1": 1,
                       "line": {"width": 1, "dash": "dash", "color": "#2a7a2a"}})
        notes.append({"xref": "x", "yref": "paper", "x": x, "y": 1.0, "yanchor": "bottom", "text": what,
                      "yshift": 12 * (k % 2), "showarrow": False, "font": {"size": 10, "color": "#2a7a2a"}})
    return traces, shapes, notes


def _rgba(color: str, alpha: float) -> str:
    return f"rgba({int(color[1:3], 16)},{int(color[3:5], 16)},{int(color[5:7], 16)},{alpha})"


def reference_traces(series: dict, time: np.ndarray, axis: str, legend: str) -> list[dict]:
    """Each motor's reference share (dashed) and its band (a filled polygon per airborne run, at most
    ``MAX_BUCKETS`` points a motor: the reference moves slowly, a stride keeps its shape); one legend
    entry for them all (a click hides or shows every one)."""
    from quadfdi.vehicle.stats import runs

    air = np.asarray(series["airborne"], bool)
    out = []
    for k in range(4):
        ref, spread, color = series["reference"][:, k], series["spread"][k], COLORS[k % len(COLORS)]
        meta = {"motor": k + 1, "log_motor": series["log_motor"][k], "spread": spread}
        group = {"legend": legend, "legendgroup": "reference", "showlegend": not out,
                 "name": "vehicle reference \u00b1 between-flight spread"}
        if spread:
            ok = air & np.isfinite(ref)
            step = max(1, int(ok.sum()) // MAX_BUCKETS + 1)
            xs, ys = [], []
            for a, b in runs(ok):
                idx = np.unique(np.r_[np.arange(a, b, step), b - 1])
                t, lo, hi = time[idx], ref[idx] - spread, ref[idx] + spread
                xs += rounded(t, 6) + rounded(t[::-1], 6) + [None]
                ys += rounded(hi) + rounded(lo[::-1]) + [None]
            out.append({"type": "scatter", "mode": "lines", "x": xs, "y": ys, "xaxis": "x", "yaxis": axis,
                        "fill": "toself", "fillcolor": _rgba(color, 0.15), "line": {"width": 0}, "hoverinfo": "skip",
                        "meta": dict(meta, kind="reference band"), **group})
        line = _line(f"reference motor {k + 1} ({series['log_motor'][k]})", time, np.where(air, ref, np.nan), axis,
                     color, legend=legend)
        line["line"]["dash"], line["meta"] = "dash", dict(meta, kind="reference")
        out.append(dict(line, legendgroup="reference", showlegend=not out))
    return out


def figure(result: dict, flight: dict) -> dict:
    """{"data", "layout"} of the flight's linked panels (plotly.js)."""
    time = np.asarray(flight["time"], np.float64)
    panels = signal_panels(flight)
    n = len(panels) + 1
    gap, weights = 0.025, [1.0] * len(panels) + [1.4]
    unit = (1.0 - gap * (n - 1)) / sum(weights)
    data, layout = [], {"height": 150 * n + 120, "margin": {"l": 70, "r": 190, "t": 40, "b": 45},
                        "hovermode": "x unified", "showlegend": True, "dragmode": "zoom"}
    top = 1.0
    for p in range(n):
        h = unit * weights[p]
        axis, key, legend = ("y" if p == 0 else f"y{p + 1}"), ("yaxis" if p == 0 else f"yaxis{p + 1}"), \
            ("legend" if p == 0 else f"legend{p + 1}")
        title = panels[p][0] if p < len(panels) else "p(class), p_fault"
        layout[key] = {"domain": [max(top - h, 0.0), top], "title": {"text": title, "font": {"size": 10}},
                       "anchor": "x", "zeroline": False}
        layout[legend] = {"y": top, "yanchor": "top", "x": 1.01, "font": {"size": 10}}
        if p < len(panels):
            data += [_line(name, time, v, axis, COLORS[j % len(COLORS)], vis, legend)
                     for j, (name, v, vis) in enumerate(panels[p][1])]
            if panels[p][0] == SHARE_PANEL and result.get("vehicle_series") is not None:
                data += reference_traces(result["vehicle_series"], time, axis, legend)
        else:
            layout[key]["range"] = [-0.03, 1.08]
            data += probability_traces(result, axis, legend)
            marks, shapes, notes = _overlays(result, flight, axis, legend)
            data += marks
            layout["shapes"], layout["annotations"] = shapes, notes
        top -= h + gap
    layout["xaxis"] = {"anchor": "y" if n == 1 else f"y{n}", "title": {"text": "time from log start, s"},
                       "showspikes": True, "spikemode": "across", "spikethickness": 1}
    return {"data": data, "layout": layout}
