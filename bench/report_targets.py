"""bench's latency targets in report.md, and why each missed one is missed (from the run's profiles)."""

from __future__ import annotations

from quadfdi.bench.report_fmt import nbytes, us
from quadfdi.core.tables import md_table


def _why_cpp_floor(t: dict, bench: dict) -> list[str]:
    """The profile behind a missed 'C++ within 2x of its floor' target."""
    key = f"{t['model']}_{t['precision']}"
    cpp = bench.get("profiles", {}).get("cpp", {})
    cg = cpp.get(key)
    f = next(x for x in bench["floors"] if x["model"] == t["model"] and x["precision"] == t["precision"])
    unit = "GOP/s" if t["precision"] == "int8" else "GFLOP/s"
    lines = [f"- **C++ {t['model']} {t['precision']}: {t['measured']:.1f}x its floor** (target {t['threshold']:g}x, missed "
             f"by a factor {t['measured'] / t['threshold']:.1f}). Floor {us(f['floor_us'])} us = max(compute {us(f['compute_us'])} us: "
             f"{f['macs_per_window']:,} MACs at {f['peak_gops']:.1f} {unit}; L2 {us(f['memory_us'])} us: "
             f"{nbytes(f['weight_bytes_per_window'])} at {f['l2_gbps']:.0f} GB/s)."]
    if cg and "ir_per_window" in cg:
        ipns = cg.get("instructions_per_ns_at_p50")
        rates = [c.get("instructions_per_ns_at_p50") for c in cpp.values() if c.get("instructions_per_ns_at_p50")]
        best = max(rates) if rates else None
        need = f["floor_us"] * 1e3 * ipns / f["macs_per_window"] if ipns else None
        top = "; ".join(f"{x['function']} {100 * x['share']:.0f} %" for x in cg.get("top", [])[:3])
        text = (f"  Profile (callgrind, inference calls only): {cg['ir_per_window']:,.0f} instructions per window, "
                f"{cg.get('ir_per_mac', 0):.2f} per MAC")
        if ipns:
            text += f", retired at {ipns:.1f} per ns at the measured p50"
            if best and ipns < 0.5 * best:
                text += (f" — less than half the {best:.1f} per ns that the fastest-retiring C++ model "
                         "reaches on the same machine in the same run: this model is stalled (waiting on dependent "
                         "results or memory), not limited by how many instructions it executes")
            else:
                text += (f". At that rate the floor allows {need:.2f} instructions per MAC: it is limited by its "
                         f"instruction count, and needs several MACs per instruction (packed SIMD) instead of "
                         f"{cg.get('ir_per_mac', 0):.2f} instructions per MAC")
        lines.append(text + "." + (f" Self cost: {top}." if top else ""))
    return lines


def _build_line(bench: dict) -> list[str]:
    prof = bench.get("profiles", {})
    build, simd = prof.get("cpp_build"), prof.get("cpp_simd")
    parts = []
    if build:
        parts.append(f"build type {build.get('CMAKE_BUILD_TYPE', '?')}, compile flags `{build.get('CXX_FLAGS', '?')}`, "
                     f"target ISA: {build['march']}")
    if simd and simd.get("packed_share") is not None:
        w = simd["packed_by_width"]
        parts.append(f"{100 * simd['packed_share']:.0f} % of the float add/mul/FMA instructions in the inference "
                     f"code are packed ({w['xmm']} on 4-lane xmm, {w['ymm']} on 8-lane ymm, {w['zmm']} on 16-lane zmm "
                     f"registers; {simd['scalar']} scalar; objdump, static count)")
    return ["- The C++ build (all four models): " + "; ".join(parts) + "."] if parts else []


def _why_cpp_vs_ort(t: dict, bench: dict) -> list[str]:
    lim = bench["limits"]
    key = f"cnode_{t['precision']}"
    ort = bench.get("profiles", {}).get("ort", {}).get(key)
    label = t["target"].split("than ")[-1].split(" at batch")[0]
    lines = [f"- **C++ CNODE {t['precision']} vs {label}: {t['measured']:.2f}x** (target 10x; {t['detail']}). "
             f"For 10x, C++ would have to run one window in {us(t['ort_p50_us'] / 10)} us; it takes "
             f"{us(t['cpp_p50_us'])} us (see its floor row above for why)."]
    if ort and lim.get("ort_node_us") is not None:
        nodes = ort["nodes_per_call"]
        fixed = lim["ort_call_us"] + nodes * lim["ort_node_us"]
        top = ", ".join(f"{o['op']} {100 * o['kernel_share']:.0f} % ({o['nodes_per_call']:.0f} nodes)"
                        for o in ort["by_op"][:4])
        lines.append(f"  ORT's side: its graph runs {nodes:.0f} nodes per call; at the measured "
                     f"{us(lim['ort_call_us'])} us per call plus {lim['ort_node_us']:.2f} us per node (an Identity "
                     "model and a 256-node Add chain), "
                     f"dispatch alone accounts for about {us(fixed)} us of its {us(t['ort_p50_us'])} us p50. Kernel "
                     f"time by operator (ORT profiler, shares): {top}.")
    return lines


def _why_ratio(t: dict) -> list[str]:
    """A missed ratio between two runtimes or precisions of the same run (bench.int8_targets)."""
    return [f"- **{t['target']}, {t['model']}: {t['measured']:.2f}** (threshold {t['threshold']:g}; {t['detail']})."]


def _why(t: dict, bench: dict) -> list[str]:
    if "floor" in t["target"]:
        return _why_cpp_floor(t, bench)
    return _why_cpp_vs_ort(t, bench) if "ort_p50_us" in t else _why_ratio(t)


def targets_section(bench: dict) -> list[str]:
    ts = bench.get("targets", [])
    if not ts:
        return ["No latency targets could be evaluated (the C++ reference was not measured: "
                + "; ".join(bench.get("skipped", [])) + ").", ""]
    rows = [[t["target"], t["model"], t["precision"], f"{t['measured']:.2f}", f"{t['threshold']:g}",
             "**met**" if t["met"] else "**missed**", t["detail"]] for t in ts]
    out = ["### Targets", ""] + md_table(["target", "model", "precision", "measured", "threshold", "verdict", "detail"],
                                      rows)
    missed = [t for t in ts if not t["met"]]
    if missed:
        out += ["Why the missed ones are missed (profiles, measured in the same run):", ""]
        for t in missed:
            out += _why(t, bench)
        if any("floor" in t["target"] for t in missed):
            out += _build_line(bench)
        out.append("")
    return out
