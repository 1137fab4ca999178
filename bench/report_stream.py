"""bench's report section for the streaming runtime (bench.json ``stream``, bench/stream.py)."""

from __future__ import annotations

from quadfdi.bench.report_fmt import us
from quadfdi.core.tables import md_table


def stream_report(bench: dict) -> list[str]:
    """Latency per sample and per decision, and the stream object's memory; [] for an older bench.json."""
    s = bench.get("stream")
    if s is None:
        return []
    out = ["### Streaming runtime (fwref_stream): cost per sample", ""]
    if s.get("skipped"):
        return out + [f"Not measured: {s['skipped']}.", ""]
    out += [(f"{len(s['flights'])} test flights (round-robin over the classes: {', '.join(map(str, s['flights']))}) "
            f"replayed sample by sample through `{s['exe']}`, profile {s['profile']}, window {s['window']}, stride "
            f"{s['stride']}, one sample per {1000 * s['sample_dt_s']:.0f} ms; times are fwref_stream's own steady "
            "clock around each `push` (`--timings`), pinned like the rest of the bench. A push is a sample into the "
            "ring buffer; a decision is a push whose stride ran the model and the alarm policy. p99 on a shared "
            "machine is mostly other load; compare p50s."), ""]
    rows = [[r["model"], r["precision"], f"{r['push_n']:,}", us(r["push_p50_us"]), us(r["push_p99_us"]),
             f"{r['decision_n']:,}", us(r["decision_p50_us"]), us(r["decision_p99_us"]), us(r["decision_max_us"]),
             str(r["other_strides"])] for r in s["latency"]]
    out += md_table(["model", "precision", "pushes", "push p50 (us)", "push p99 (us)", "decisions",
                     "decision p50 (us)", "decision p99 (us)", "decision max (us)", "strides not decided"], rows)
    mrows = []
    for m in s["memory"]:
        image = m.get("image")
        img = "—" if image is None else image if isinstance(image, str) else \
            f".text {image['text_bytes']:,} B, .bss {image['bss_bytes']:,} B ({image['elf']})"
        mrows.append([m["target"], "—" if m.get("stream_bytes") is None else f"{m['stream_bytes']:,}",
                      m.get("skipped", ""), img])
    lim = s["memory"][0]["limits"] if s["memory"] else {}
    out += [("sizeof(fwref::Stream) (ring buffer, window, hover estimate, alarm state) with the model's limits ("
             + ", ".join(f"{k.removeprefix('FWREF_MAX_')} {v}" for k, v in lim.items()) + "), compiled per target:"),
            ""]
    out += md_table(["target", "stream object (B)", "skipped", "stream image"], mrows)
    host = s["memory"][0].get("fwref_stream_build_bytes") if s["memory"] else None
    if host:
        out += [(f"The host program fwref_stream itself holds {host:,} B (its build's generous limits, "
                 "fwref/config.hpp)."), ""]
    return out
