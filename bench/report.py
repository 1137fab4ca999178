"""bench's section of report.md and its headline lines, from ``bench.json`` and ``figures/bench_*.png``.

``report_section(run_root)`` is bench's part of the run report (the app layer, quadfdi/report.py,
assembles report.md from every stage's section): latency, floors, targets with the profiles that
explain a miss, machine limits, memory (with the Cortex-M numbers bench.json copied from
parity/mcu.json) and profiles. ``redraw_figures(run_root)`` redraws the bench figures from
bench.json alone (no measuring). A bench.json that is not bench's (schema, fields) is a one-line
QuadfdiError.
"""

from __future__ import annotations

from pathlib import Path

from quadfdi.bench.figures import draw_bench_figures
from quadfdi.bench.report_fmt import RUNTIME_NAME, RUNTIME_ORDER, nbytes, setting, us
from quadfdi.bench.report_stream import stream_report
from quadfdi.bench.report_targets import targets_section
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.reportmd import figure_links, not_run, num, optional_json
from quadfdi.core.tables import md_table

HEADING = "## Bench: latency, memory, limits"


def load_bench(run_root: Path) -> dict | None:
    """bench.json of a run (None when bench has not run); a foreign or truncated file is a one-line error."""
    path = Path(run_root) / "bench.json"
    bench = optional_json(path, "bench results")
    if bench is None:
        return None
    if not isinstance(bench, dict) or bench.get("schema_version") != 1 or "latency" not in bench:
        raise QuadfdiError(f"{path} is not a quadfdi bench.json of schema version 1 (re-run quadfdi bench)")
    return bench


def _latency_rows(bench: dict) -> list[list[str]]:
    recs = bench["latency"]
    big = {(r["runtime"], r["model"], r["precision"], r["solver"], r["threads"], r.get("spinning")): r
           for r in recs if r["batch"] != 1}
    rows = []
    for r in sorted((r for r in recs if r["batch"] == 1),
                    key=lambda r: (r["model"], RUNTIME_ORDER.get(r["runtime"], 9), r["precision"], r["solver"],
                                   r["threads"], bool(r.get("spinning")))):
        b = big.get((r["runtime"], r["model"], r["precision"], r["solver"], r["threads"], r.get("spinning")))
        rows.append([r["model"], RUNTIME_NAME.get(r["runtime"], r["runtime"]), r["precision"], r["solver"],
                     setting(r), us(r["p50_us"]), us(r["p90_us"]), us(r["p99_us"]),
                     f"{r['x_floor']:.1f}x" if r.get("x_floor") else "—", str(r["n_calls"]),
                     num(b["throughput_wps"], 0) if b else "—", us(b["p50_us"]) if b else "—"])
    return rows


def speedup_rows(recs: list[dict]) -> list[list[str]]:
    """int8 / fp32 speed-up (fp32 p50 over int8 p50) per model, runtime, setting and batch."""
    key = lambda r: (r["model"], r["runtime"], r["solver"], r["threads"], r.get("spinning"), r["batch"])  # noqa: E731
    fp32 = {key(r): r for r in recs if r["precision"] == "fp32" and r.get("p50_us")}
    rows = []
    for r in sorted((r for r in recs if r["precision"] == "int8" and r.get("p50_us") and key(r) in fp32),
                    key=lambda r: (r["model"], RUNTIME_ORDER.get(r["runtime"], 9), r["batch"], r["threads"])):
        f = fp32[key(r)]
        x = f["p50_us"] / r["p50_us"]
        rows.append([r["model"], RUNTIME_NAME.get(r["runtime"], r["runtime"]), setting(r), str(r["batch"]),
                     us(f["p50_us"]), us(r["p50_us"]), f"{x:.2f}x" + ("" if x >= 1 else " (int8 slower)")])
    return rows


def _speedup_section(bench: dict) -> list[str]:
    rows = speedup_rows(bench["latency"])
    if not rows:
        return []
    return (["### int8 against fp32", "", "Speed-up = fp32 p50 / int8 p50, same runtime, setting and batch.", ""]
            + md_table(["model", "runtime", "setting", "batch", "fp32 p50 (us)", "int8 p50 (us)", "int8 speed-up"],
                       rows))


def _pairs_section(bench: dict) -> list[str]:
    """bench.json ``cpp_pairs`` and ``ort_pairs``: the ratios the int8 / fp32 targets are judged on."""
    rows = [[model, name, str(p["batch"]), str(p["rounds"]), us(p["fp32_p50_us"]), us(p["int8_p50_us"]),
             f"{p['int8_over_fp32_median']:.3f}", f"{p['int8_over_fp32_p10']:.2f}-{p['int8_over_fp32_p90']:.2f}"]
            for key, name in (("cpp_pairs", "C++"), ("ort_pairs", "ONNX Runtime"))
            for model, pairs in (bench.get(key) or {}).items() if isinstance(pairs, list) for p in pairs]
    if not rows:
        return []
    text = ("fp32 and int8 in one process, taking turns round by round (C++: fwref_pair, bench/cpp_pairs.py; ONNX "
            "Runtime: 1 thread, spinning off, bench/ort_pairs.py): a process's speed mode or a burst of load hits "
            "both precisions alike, so the int8 / fp32 targets below use the median of the rounds' ratios, "
            "not the ratio of the separate processes' p50s above.")
    return (["### int8 against fp32 in one process", "", text, ""]
            + md_table(["model", "runtime", "batch", "rounds", "fp32 p50 (us)", "int8 p50 (us)",
                        "int8 / fp32 time (median)", "p10-p90 of rounds"], rows))


def _graphs_section(bench: dict) -> list[str]:
    g = bench.get("graphs") or {}
    if not g:
        return []
    rows = [[k, str(v["nodes"]), str(v["ort_nodes"]) + (f" + {v['ort_body_nodes']} in a Scan body (run per step)"
                                                        if v.get("ort_body_nodes") else ""),
             ", ".join(f"{op} {n}" for op, n in sorted(v["ort_ops"].items(), key=lambda kv: -kv[1])[:6])]
            for k, v in g.items()]
    return (["### ONNX graphs", "", "Nodes as exported and after ONNX Runtime's optimizer (ORT_ENABLE_ALL, CPU; "
             "`SessionOptions.optimized_model_filepath`, counted): each costs ~0.4 us of dispatch per call.", ""]
            + md_table(["graph", "nodes", "nodes after ORT optimizer", "largest op counts"], rows))


def _floors_section(bench: dict) -> list[str]:
    lim = bench["limits"]
    rows = [[f["model"], f["precision"], f"{f['macs_per_window']:,}", nbytes(f["weight_bytes_per_window"]),
             ("fits L1" if f["traffic"]["reused_fits_l1"] else f"x{f['traffic']['reuse_count']} (> L1)"),
             us(f["compute_us"]), us(f["memory_us"]), us(f["floor_us"]), f["bound"]] for f in bench["floors"]]
    return (["### Floors", "",
             f"floor = max(2 x MACs / peak, weight bytes / L2 bandwidth), batch 1, one core (bench/floors.py): peak "
             f"{lim['peak_gflops']:.1f} GFLOP/s fp32 and {lim['peak_int8_gops']:.0f} GOP/s int8, L2 "
             f"{lim['l2_gbps']:.0f} GB/s, L1d {nbytes(lim.get('caches', {}).get('L1d'))}. Weights reused across "
             "iterations (CNODE field: 4N evaluations; GRU recurrent: W steps) count once when they fit L1d, else "
             "once per iteration. MACs: the deployed graph's (export manifest).", ""]
            + md_table(["model", "precision", "MACs / window", "weight bytes / window", "reused weights",
                     "compute (us)", "L2 (us)", "floor (us)", "bound"], rows))


def _limits_section(bench: dict) -> list[str]:
    lim = bench["limits"]
    caches = lim.get("caches", {})
    out = ["### Machine limits", "",
           f"Measured in the same run, pinned to CPUs {lim.get('cpus')}; {lim.get('method')}.", ""]
    out += md_table(["limit", "value", "how"], [
        ["peak fp32, 1 thread", f"{lim['peak_gflops']:.1f} GFLOP/s",
         "best of numpy (OpenBLAS) / torch (MKL) sgemm (best size)"
         + (f" {lim['gemm_peak_gflops']:.1f} and the probe's FMA loop {lim['fma_peak_gflops']:.1f}"
            if lim.get("fma_peak_gflops") else "")],
        *([["peak fp32, 2 threads", f"{lim['peak_gflops_2t']:.1f} GFLOP/s", "same"]]
          if lim.get("peak_gflops_2t") is not None else []),  # measured only when bench.threads has 2
        ["peak int8, 1 thread", f"{lim['peak_int8_gops']:.0f} GOP/s",
         "ORT MatMulInteger, uint8 x int8 (MLAS): the exported graphs' products (7-bit weights)"],
        ["int8 x int8, 1 thread", f"{lim.get('s8s8_int8_gops', float('nan')):.0f} GOP/s",
         "ORT MatMulInteger, int8 activations (only the CNODE's P @ x_norm product uses it)"],
        ["L2 read bandwidth, 1 core", f"{lim['l2_gbps']:.0f} GB/s",
         f"{lim.get('l2_probe_kib')} KiB buffer; {lim.get('bandwidth_probe')}"],
        *([["L1 read bandwidth, 1 core",
            f"{lim['l1_gbps']:.0f} GB/s (L1 / L2 {lim['l1_gbps'] / lim['l2_gbps']:.1f}x, sane >= 1.5x)",
            "best of sizes " + ", ".join(f"{k}: {v:.0f}" for k, v in (lim.get("bandwidth_by_size") or {}).items())
            + ("" if lim.get("bandwidth_sane", True) else "; IMPLAUSIBLE: L1 < 1.5x L2")]]
          if lim.get("l1_gbps") else []),
        ["ORT fixed cost per call", f"{us(lim['ort_call_us'])} us", "Identity model, one (1, W, C) window, median"],
        ["ORT cost per node", f"{lim.get('ort_node_us', 0):.2f} us",
         "256-node Add chain on (1, 64), minus the call, / 256"],
        ["caches (per core)", ", ".join(f"{k} {nbytes(v)}" for k, v in caches.items()), "sysfs"],
    ])
    rows = [[g["label"], f"{g['m']}x{g['k']}x{g['n']}", g["library"], str(g["threads"]), str(g.get("pass", 0) + 1),
             f"{g['gflops']:.1f}"] for g in lim.get("gemm", [])]
    if rows:
        out += ["Matrix products (GFLOP/s; pass 1 before the latencies, pass 2 after; the models' own batch-1 "
                "sizes are far from the peak):", ""]
        out += md_table(["product", "M x K x N", "library", "threads", "pass", "GFLOP/s"], rows)
    return out


def _memory_section(bench: dict) -> list[str]:
    mem = bench.get("memory", [])
    out = ["### Memory", ""]
    params = {m["model"]: m["value"] for m in mem if m["item"] == "parameters"}
    if params:
        out += ["Parameters: " + ", ".join(f"{k} {v:,}" for k, v in params.items()) + ".", ""]
    files = {(m["model"], m["runtime"], m["precision"]): m["value"] for m in mem if m["item"] == "file_bytes"}
    rss = {}
    for m in mem:
        if m["item"] in ("baseline_rss_bytes", "peak_rss_above_baseline_batch1_bytes",
                         "peak_rss_above_baseline_batch96_bytes"):
            rss.setdefault((m["model"], m["runtime"], m["precision"], m.get("solver")), {})[m["item"]] = m["value"]
    rows = []
    for (model, runtime, precision, solver), v in sorted(
            rss.items(), key=lambda kv: (kv[0][0], RUNTIME_ORDER.get(kv[0][1], 9), kv[0][2], kv[0][3] or "")):
        f = files.get((model, runtime, precision), files.get((None, runtime, None)))
        rows.append([model, RUNTIME_NAME.get(runtime, runtime), precision, solver or "—",
                     nbytes(f) + (" (weights.bin, all models)" if runtime == "cpp" and f else ""),
                     nbytes(v.get("baseline_rss_bytes")), nbytes(v.get("peak_rss_above_baseline_batch1_bytes")),
                     nbytes(v.get("peak_rss_above_baseline_batch96_bytes"))])
    if rows:
        out += ["Files and each runtime's own process (1 thread): baseline = resident set after importing the "
                "runtime and loading the windows; peak above it after the batch-1 and batch-96 loops (C++: a "
                "one-window run of fwref_infer minus `fwref_infer --help`). File: the checkpoint (PyTorch), the "
                "ONNX file, weights.bin (C++).", ""]
        out += md_table(["model", "runtime", "precision", "solver", "file", "baseline RSS", "peak above, batch 1",
                      "peak above, batch 96"], rows)
    static = {m["item"]: m["value"] for m in mem if m["runtime"] == "cpp" and m["model"] is None
              and m["item"] in ("static_ram_bytes", "data_bytes", "bss_bytes", "text_bytes")}
    if static:
        out += [f"C++ reference (host program fwref_infer, `size -A`): static RAM "
                f"{nbytes(static.get('static_ram_bytes'))} (.data {static.get('data_bytes')} B + .bss "
                f"{static.get('bss_bytes')} B), code {nbytes(static.get('text_bytes'))}. "
                "On the host the weights and the workspace live on the heap (in the peak RSS above); the "
                "Cortex-M images below place them statically.", ""]
    mcu = [m for m in mem if m["runtime"] not in RUNTIME_NAME and m["runtime"] is not None]
    if mcu:
        cores = sorted({m["runtime"] for m in mcu})
        rows = []
        for core in cores:
            for key in sorted({(m["model"], m["precision"]) for m in mcu if m["runtime"] == core}):
                v = {m["item"]: m["value"] for m in mcu if m["runtime"] == core and (m["model"], m["precision"]) == key}
                ins = None
                cpu = (bench.get("mcu") or {}).get("cpus", {}).get(core, {})
                ins = cpu.get("models", {}).get(f"{key[0]}_{key[1]}", {}).get("instructions_per_inference")
                rows.append([core, key[0], key[1], f"{v.get('flash_bytes', 0):,}", f"{v.get('weights_bytes', 0):,}",
                             f"{v.get('static_ram_bytes', 0):,}", f"{v.get('stack_peak_bytes') or 0:,}",
                             f"{ins:,}" if ins else "—"])
        out += ["Cortex-M (from `quadfdi parity`'s parity/mcu.json: model image minus baseline image):", ""]
        out += md_table(["core", "model", "precision", "flash (B)", "of which weights (B)", "static RAM (B)",
                      "stack peak (B)", "instructions / inference"], rows)
    else:
        out += ["Cortex-M: no parity/mcu.json in this run (run `quadfdi parity --run <run>`).", ""]
    return out


def _profiles_section(bench: dict) -> list[str]:
    prof = bench.get("profiles", {})
    out = []
    if prof.get("ort"):
        lim = bench["limits"]
        out += ["### ONNX Runtime per-operator profile (batch 1, 1 thread)", "",
                "`SessionOptions.enable_profiling`: share of kernel time by operator type. The profiler costs "
                "several microseconds per node itself (profiled calls are the column below, far slower than the "
                "timed p50), so only the shares are used; the dispatch estimate is the call cost plus nodes x the "
                f"per-node cost measured without the profiler ({us(lim['ort_call_us'])} us + "
                f"{lim.get('ort_node_us', 0):.2f} us per node).", ""]
        p50 = {(r["model"], r["precision"]): r["p50_us"] for r in bench["latency"]
               if r["runtime"] == "ort" and r["batch"] == 1 and r["threads"] == 1 and not r.get("spinning")}
        rows = []
        for key, p in prof["ort"].items():
            model, precision = key.split("_")
            ops = ", ".join(f"{o['op']} {100 * o['kernel_share']:.0f} %" for o in p["by_op"][:5])
            dispatch = lim["ort_call_us"] + p["nodes_per_call"] * lim.get("ort_node_us", 0)
            rows.append([key, f"{p['nodes_per_call']:.0f}", us(p50.get((model, precision))), us(dispatch),
                         us(p["profiled_call_p50_us"]), ops])
        out += md_table(["graph", "nodes / call", "timed p50 (us)", "dispatch estimate (us)", "profiled call (us)",
                      "kernel time by op type"], rows)
    if prof.get("cpp"):
        out += ["### C++ reference instruction profile", "",
                "valgrind callgrind inside fwref_infer's per-window call only (no hardware counters on this machine: `perf stat` "
                "reports cycles and instructions as not supported).", ""]
        rows = []
        for key, c in prof["cpp"].items():
            if "ir_per_window" not in c:
                rows.append([key, "—", "—", "—", c.get("error", "")])
                continue
            top = "; ".join(f"{t['function']} {100 * t['share']:.0f} %" for t in c.get("top", [])[:3])
            rows.append([key, f"{c['ir_per_window']:,.0f}", f"{c.get('ir_per_mac', 0):.2f}",
                         num(c.get("instructions_per_ns_at_p50"), 1), top])
        out += md_table(["model", "instructions / window", "per MAC", "per ns at p50", "top functions (self)"], rows)
    return out


def bench_section(bench: dict, figures: str = "figures", run_root: Path | None = None) -> list[str]:
    """The bench part of report.md from a bench.json dict."""
    m = bench.get("machine", {})
    la0, la1 = m.get("load_average_start"), m.get("load_average_end")
    out = ["## Bench: latency, memory, limits", "",
           f"Made by `{bench['command']}`" + (" (quick: few windows, 1 thread only)" if bench.get("quick") else "")
           + f" in {bench['timing_s']['total']:.0f} s. CPU: {m.get('cpu', '?')}, {m.get('logical_cpus')} logical CPUs, "
           f"every runtime in its own process pinned to CPUs {m.get('pinned_cpus')} (taskset); torch "
           f"{m.get('torch')}, onnxruntime {m.get('onnxruntime')}."]
    if la0 and la1:
        out[-1] += (f" Load average (1 min) {la0[0]:.1f} at the start, {la1[0]:.1f} at the end"
                    + (" — the machine was shared: absolute times are inflated, compare within this run."
                       if max(la0[0], la1[0]) > (m.get("logical_cpus") or 2) * 0.5 else "."))
    w = bench.get("windows", {})
    c = bench.get("counts", {})
    out += ["", f"Batch 1: each of up to {c.get('n')} test windows timed once after {c.get('warmup')} warm-up calls "
            f"(at most {c.get('budget_s')} s per loop; the windows column says how many); batch {c.get('batch')}: "
            f"up to {c.get('batches')} batches. Test windows: {w.get('available')} available, a seeded sample of "
            f"{w.get('sampled')}{' (cycled)' if w.get('cycled') else ''}. Throughput = batch x 10^6 / p50. "
            "x floor = batch-1 p50 over the model's floor (below). C++ runs windows one at a time (its batch-96 "
            "figure is 96 consecutive single-window calls).", ""]
    if bench.get("skipped"):
        out += ["Not measured: " + "; ".join(bench["skipped"]) + ".", ""]
    out += md_table(["model", "runtime", "precision", "solver", "setting", "p50 (us)", "p90 (us)", "p99 (us)", "x floor",
                  "windows", "batch-96 windows/s", "batch-96 p50 (us)"], _latency_rows(bench))
    nfe = [r for r in bench["latency"] if r.get("nfe_per_window") and r["batch"] == 1]
    if nfe:
        out += ["PyTorch CNODE evaluations per window (batch 1): "
                + ", ".join(sorted({f"{r['solver']} {r['nfe_per_window']:.0f}" for r in nfe})) + ".", ""]
    if run_root is not None:
        out += figure_links(run_root, ["bench_latency.png", "bench_throughput.png"], figures)
    below = [r for r in bench["latency"] if r["batch"] == 1 and r.get("x_floor") is not None and r["x_floor"] < 1]
    if bench.get("floor_violations"):
        out += ["**FLOORS INVALID (the bench failed):** still below the floor after re-measuring the limits: "
                + bench["floor_violations"] + ". No floor target counts as met.", ""]
    elif below:
        out += ["**Below the floor:** " + "; ".join(
            f"{RUNTIME_NAME.get(r['runtime'], r['runtime'])} {r['model']} {r['precision']} ({setting(r)}) at "
            f"{r['x_floor']:.2f}x" for r in below) + ". A measured time under the floor means the limits were "
            "measured low (another user of the shared machine slowed the peak or bandwidth probe) or the floor's "
            "traffic model is too pessimistic for that runtime; treat the floor as approximate here.", ""]
    out += _speedup_section(bench) + _pairs_section(bench) + _graphs_section(bench)
    out += _floors_section(bench) + targets_section(bench) + _limits_section(bench) + _memory_section(bench)
    out += stream_report(bench) + _profiles_section(bench)
    note = bench.get("solvers_meta", {}).get("note") or bench.get("solvers_meta", {}).get("skipped")
    if note:
        out += [f"Solver study: {note}.", ""]
    return out


def headline(run_root: Path) -> list[str]:
    """The report's headline bullets from bench.json: batch-1 latency, targets, Cortex-M ([] when bench has not run)."""
    bench = load_bench(run_root)
    if not bench:
        return []
    out = []
    b1 = {(r["runtime"], r["model"], r["precision"]): r for r in bench["latency"]
          if r["batch"] == 1 and r["threads"] == 1 and not r.get("spinning") and not str(r["solver"]).startswith("dopri5")}
    parts = [f"{model} {RUNTIME_NAME[rt]} {us(r['p50_us'])} us" + (f" ({r['x_floor']:.1f}x floor)" if r.get("x_floor") else "")
             for model in ("cnode", "gru") for rt in ("cpp", "ort") if (r := b1.get((rt, model, "fp32")))]
    if parts:
        out.append(f"- Batch-1 p50 latency, fp32, 1 thread (bench.json): {'; '.join(parts)}.")
    ts = bench.get("targets", [])
    if ts:
        missed = [t for t in ts if not t["met"]]
        out.append(f"- Latency targets (bench.json): {len(ts) - len(missed)} of {len(ts)} met"
                   + ("; missed: " + "; ".join(f"{t['target']} ({t['model']} {t['precision']}: {t['measured']:.2f})"
                                              for t in missed) if missed else "") + ".")
    mcu = [m for m in bench.get("memory", []) if m["item"] in ("flash_bytes", "static_ram_bytes")
           and m["model"] == "cnode" and m["precision"] == "int8" and m["runtime"] not in RUNTIME_NAME]
    if mcu:
        out.append("- Cortex-M int8 CNODE (parity/mcu.json): " + ", ".join(
            f"{m['runtime']} {m['item'].replace('_bytes', '').replace('_', ' ')} {m['value']:,} B" for m in mcu) + ".")
    return out


def report_section(run_root: Path) -> list[str]:
    """bench's section of report.md (module doc)."""
    root = Path(run_root)
    bench = load_bench(root)
    if bench is None:
        return not_run(HEADING, f"no bench.json in this run (`quadfdi bench --run {root}` writes it)")
    return bench_section(bench, "figures", root)


def redraw_figures(run_root: Path, out_root: Path | None = None) -> list[Path]:
    """Redraw figures/bench_*.png from bench.json ([] when bench has not run) into ``out_root``
    (default: the run folder; the report stage gives its staging folder)."""
    bench = load_bench(run_root)
    return draw_bench_figures(bench, Path(out_root or run_root) / "figures") if bench else []
