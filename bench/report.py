"""report.md: one markdown report of a whole run, every table and figure, from the files it holds.

``write_run_report(run_root)`` is the one call (``quadfdi bench`` and ``quadfdi run`` make it):
it reads whatever the stages left in ``runs/<name>/`` and writes ``runs/<name>/report.md`` with,
in order, a headline, then one section per stage whose outputs exist:

- sim: ``config.toml``, ``dataset.npz`` (trajectories and windows per split and class),
  ``figures/sim_traj*.png``;
- train: ``metrics.json`` (test split), ``history.json``, the training figures, and the seeds
  study's ``results.md`` when present;
- export: ``export/manifest.json`` (verification, int8 coverage, files) and ``export/coverage.md``;
- parity: ``parity/parity.md`` (the parity stage's own report, headings one level down), else a
  short summary of ``parity/parity.json``;
- bench: ``bench.json`` (latency, floors, targets with the profiles that explain a miss, limits,
  memory, Cortex-M) and ``figures/bench_*.png``;
- solvers: ``bench/solvers.json`` and ``bench/solver_matrix.json`` through
  ``bench.cli_solvers.solver_section`` (the solver engineer's markdown);
- any other figure in ``figures/``.

Every number is read from a file that a command wrote; the command is named next to each section.
``quadfdi bench report --run runs/<name>`` redraws the bench figures and rewrites report.md from
the files alone (no measuring).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

from core.atomic import write_text
from core.plotting import pyplot, save_png

RUNTIME_ORDER = {"cpp": 0, "ort": 1, "torch": 2}
RUNTIME_NAME = {"cpp": "C++", "ort": "ONNX Runtime", "torch": "PyTorch"}
TRAIN_FIGURES = ("train_curves", "confusion_", "per_class_f1", "any_fault_roc", "detection_")


# ----------------------------------------------------------------------------- formatting


def _us(x: float | None) -> str:
    if x is None:
        return "—"
    return f"{x:.2f}" if x < 10 else f"{x:.1f}" if x < 1000 else f"{x:,.0f}"


def _num(x: float | None, nd: int = 1) -> str:
    return "—" if x is None else f"{x:,.{nd}f}"


def _bytes(n: float | None) -> str:
    if n is None:
        return "—"
    n = float(n)
    if abs(n) < 1024:
        return f"{n:.0f} B"
    if abs(n) < 1024 ** 2:
        return f"{n / 1024:.1f} KiB"
    return f"{n / 1024 ** 2:.1f} MiB"


def _pct(x: float | None, nd: int = 2) -> str:
    return "—" if x is None else f"{100 * x:.{nd}f} %"


def table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|",
            *("| " + " | ".join(str(c) for c in r) + " |" for r in rows), ""]


def _read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None


def _demote(markdown: str, levels: int = 1) -> list[str]:
    """Headings one level down, so that an included report nests under this one's section."""
    out = []
    fence = False
    for line in markdown.splitlines():
        if line.startswith("```"):
            fence = not fence
        out.append(("#" * levels + line) if line.startswith("#") and not fence else line)
    return out + [""]


def _figures(run_root: Path, names: list[str], rel: str = "figures") -> list[str]:
    return [f"![{n}]({rel}/{n})" for n in names if (run_root / rel / n).is_file()] + ([""] if names else [])


def _setting(r: dict) -> str:
    spin = "" if r.get("spinning") is None else (", spin" if r["spinning"] else ", no spin")
    return f"{r['threads']} thr{spin}"


# ----------------------------------------------------------------------------- bench section


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
                     _setting(r), _us(r["p50_us"]), _us(r["p90_us"]), _us(r["p99_us"]),
                     f"{r['x_floor']:.1f}x" if r.get("x_floor") else "—", str(r["n_calls"]),
                     _num(b["throughput_wps"], 0) if b else "—", _us(b["p50_us"]) if b else "—"])
    return rows


def _why_cpp_floor(t: dict, bench: dict) -> list[str]:
    """The profile behind a missed 'C++ within 2x of its floor' target."""
    key = f"{t['model']}_{t['precision']}"
    cpp = bench.get("profiles", {}).get("cpp", {})
    cg = cpp.get(key)
    f = next(x for x in bench["floors"] if x["model"] == t["model"] and x["precision"] == t["precision"])
    unit = "GOP/s" if t["precision"] == "int8" else "GFLOP/s"
    lines = [f"- **C++ {t['model']} {t['precision']}: {t['measured']:.1f}x its floor** (target 2x, missed by a factor "
             f"{t['measured'] / 2:.1f}). Floor {_us(f['floor_us'])} us = max(compute {_us(f['compute_us'])} us: "
             f"{f['macs_per_window']:,} MACs at {f['peak_gops']:.1f} {unit}; L2 {_us(f['memory_us'])} us: "
             f"{_bytes(f['weight_bytes_per_window'])} at {f['l2_gbps']:.0f} GB/s)."]
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
             f"For 10x, C++ would have to run one window in {_us(t['ort_p50_us'] / 10)} us; it takes "
             f"{_us(t['cpp_p50_us'])} us (see its floor row above for why)."]
    if ort and lim.get("ort_node_us") is not None:
        nodes = ort["nodes_per_call"]
        fixed = lim["ort_call_us"] + nodes * lim["ort_node_us"]
        top = ", ".join(f"{o['op']} {100 * o['kernel_share']:.0f} % ({o['nodes_per_call']:.0f} nodes)"
                        for o in ort["by_op"][:4])
        lines.append(f"  ORT's side: its graph runs {nodes:.0f} nodes per call; at the measured "
                     f"{_us(lim['ort_call_us'])} us per call plus {lim['ort_node_us']:.2f} us per node (an Identity "
                     "model and a 256-node Add chain), "
                     f"dispatch alone accounts for about {_us(fixed)} us of its {_us(t['ort_p50_us'])} us p50. Kernel "
                     f"time by operator (ORT profiler, shares): {top}.")
    return lines


def _targets_section(bench: dict) -> list[str]:
    ts = bench.get("targets", [])
    if not ts:
        return ["No latency targets could be evaluated (the C++ reference was not measured: "
                + "; ".join(bench.get("skipped", [])) + ").", ""]
    rows = [[t["target"], t["model"], t["precision"], f"{t['measured']:.2f}", f"{t['threshold']:g}",
             "**met**" if t["met"] else "**missed**", t["detail"]] for t in ts]
    out = ["### Targets", ""] + table(["target", "model", "precision", "measured", "threshold", "verdict", "detail"],
                                      rows)
    missed = [t for t in ts if not t["met"]]
    if missed:
        out += ["Why the missed ones are missed (profiles, measured in the same run):", ""]
        for t in missed:
            out += _why_cpp_floor(t, bench) if "floor" in t["target"] else _why_cpp_vs_ort(t, bench)
        if any("floor" in t["target"] for t in missed):
            out += _build_line(bench)
        out.append("")
    return out


def _floors_section(bench: dict) -> list[str]:
    lim = bench["limits"]
    rows = [[f["model"], f["precision"], f"{f['macs_per_window']:,}", _bytes(f["weight_bytes_per_window"]),
             ("fits L1" if f["traffic"]["reused_fits_l1"] else f"x{f['traffic']['reuse_count']} (> L1)"),
             _us(f["compute_us"]), _us(f["memory_us"]), _us(f["floor_us"]), f["bound"]] for f in bench["floors"]]
    return (["### Floors", "",
             f"floor = max(2 x MACs / peak, weight bytes / L2 bandwidth), batch 1, one core (bench/floors.py): peak "
             f"{lim['peak_gflops']:.1f} GFLOP/s fp32 and {lim['peak_int8_gops']:.0f} GOP/s int8, L2 "
             f"{lim['l2_gbps']:.0f} GB/s, L1d {_bytes(lim.get('caches', {}).get('L1d'))}. Weights reused across "
             "iterations (CNODE field: 4N evaluations; GRU recurrent: W steps) count once when they fit L1d, else "
             "once per iteration. MACs: the deployed graph's (export manifest).", ""]
            + table(["model", "precision", "MACs / window", "weight bytes / window", "reused weights",
                     "compute (us)", "L2 (us)", "floor (us)", "bound"], rows))


def _limits_section(bench: dict) -> list[str]:
    lim = bench["limits"]
    caches = lim.get("caches", {})
    out = ["### Machine limits", "",
           f"Measured in the same run, pinned to CPUs {lim.get('cpus')}; {lim.get('method')}.", ""]
    out += table(["limit", "value", "how"], [
        ["peak fp32, 1 thread", f"{lim['peak_gflops']:.1f} GFLOP/s", "numpy (OpenBLAS) / torch (MKL) sgemm, best size"],
        ["peak fp32, 2 threads", f"{lim['peak_gflops_2t']:.1f} GFLOP/s", "same"],
        ["peak int8, 1 thread", f"{lim['peak_int8_gops']:.0f} GOP/s", "ORT MatMulInteger, uint8 x int8 (MLAS)"],
        ["int8 x int8, 1 thread", f"{lim.get('s8s8_int8_gops', float('nan')):.0f} GOP/s",
         "ORT MatMulInteger, int8 activations (the exported graphs' type)"],
        ["L2 read bandwidth, 1 core", f"{lim['l2_gbps']:.0f} GB/s",
         f"{lim.get('l2_probe_kib')} KiB buffer; {lim.get('bandwidth_probe')}"],
        ["L1 read bandwidth, 1 core", f"{_num(lim.get('l1_gbps'), 0)} GB/s", "same probe, half of L1d"],
        ["ORT fixed cost per call", f"{_us(lim['ort_call_us'])} us", "Identity model, one (1, W, C) window, median"],
        ["ORT cost per node", f"{lim.get('ort_node_us', 0):.2f} us",
         "256-node Add chain on (1, 64), minus the call, / 256"],
        ["caches (per core)", ", ".join(f"{k} {_bytes(v)}" for k, v in caches.items()), "sysfs"],
    ])
    rows = [[g["label"], f"{g['m']}x{g['k']}x{g['n']}", g["library"], str(g["threads"]), str(g.get("pass", 0) + 1),
             f"{g['gflops']:.1f}"] for g in lim.get("gemm", [])]
    if rows:
        out += ["Matrix products (GFLOP/s; pass 1 before the latencies, pass 2 after; the models' own batch-1 "
                "sizes are far from the peak):", ""]
        out += table(["product", "M x K x N", "library", "threads", "pass", "GFLOP/s"], rows)
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
                     _bytes(f) + (" (weights.bin, all models)" if runtime == "cpp" and f else ""),
                     _bytes(v.get("baseline_rss_bytes")), _bytes(v.get("peak_rss_above_baseline_batch1_bytes")),
                     _bytes(v.get("peak_rss_above_baseline_batch96_bytes"))])
    if rows:
        out += ["Files and each runtime's own process (1 thread): baseline = resident set after importing the "
                "runtime and loading the windows; peak above it after the batch-1 and batch-96 loops (C++: a "
                "one-window run of fwref_infer minus `fwref_infer --help`). File: the checkpoint (PyTorch), the "
                "ONNX file, weights.bin (C++).", ""]
        out += table(["model", "runtime", "precision", "solver", "file", "baseline RSS", "peak above, batch 1",
                      "peak above, batch 96"], rows)
    static = {m["item"]: m["value"] for m in mem if m["runtime"] == "cpp" and m["model"] is None
              and m["item"] in ("static_ram_bytes", "data_bytes", "bss_bytes", "text_bytes")}
    if static:
        out += [f"C++ reference (host program fwref_infer, `size -A`): static RAM "
                f"{_bytes(static.get('static_ram_bytes'))} (.data {static.get('data_bytes')} B + .bss "
                f"{static.get('bss_bytes')} B), code {_bytes(static.get('text_bytes'))}. "
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
        out += table(["core", "model", "precision", "flash (B)", "of which weights (B)", "static RAM (B)",
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
                f"per-node cost measured without the profiler ({_us(lim['ort_call_us'])} us + "
                f"{lim.get('ort_node_us', 0):.2f} us per node).", ""]
        p50 = {(r["model"], r["precision"]): r["p50_us"] for r in bench["latency"]
               if r["runtime"] == "ort" and r["batch"] == 1 and r["threads"] == 1 and not r.get("spinning")}
        rows = []
        for key, p in prof["ort"].items():
            model, precision = key.split("_")
            ops = ", ".join(f"{o['op']} {100 * o['kernel_share']:.0f} %" for o in p["by_op"][:5])
            dispatch = lim["ort_call_us"] + p["nodes_per_call"] * lim.get("ort_node_us", 0)
            rows.append([key, f"{p['nodes_per_call']:.0f}", _us(p50.get((model, precision))), _us(dispatch),
                         _us(p["profiled_call_p50_us"]), ops])
        out += table(["graph", "nodes / call", "timed p50 (us)", "dispatch estimate (us)", "profiled call (us)",
                      "kernel time by op type"], rows)
    if prof.get("cpp"):
        out += ["### C++ reference instruction profile", "",
                "valgrind callgrind inside `fwref::infer*` only (no hardware counters on this machine: `perf stat` "
                "reports cycles and instructions as not supported).", ""]
        rows = []
        for key, c in prof["cpp"].items():
            if "ir_per_window" not in c:
                rows.append([key, "—", "—", "—", c.get("error", "")])
                continue
            top = "; ".join(f"{t['function']} {100 * t['share']:.0f} %" for t in c.get("top", [])[:3])
            rows.append([key, f"{c['ir_per_window']:,.0f}", f"{c.get('ir_per_mac', 0):.2f}",
                         _num(c.get("instructions_per_ns_at_p50"), 1), top])
        out += table(["model", "instructions / window", "per MAC", "per ns at p50", "top functions (self)"], rows)
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
    out += table(["model", "runtime", "precision", "solver", "setting", "p50 (us)", "p90 (us)", "p99 (us)", "x floor",
                  "windows", "batch-96 windows/s", "batch-96 p50 (us)"], _latency_rows(bench))
    nfe = [r for r in bench["latency"] if r.get("nfe_per_window") and r["batch"] == 1]
    if nfe:
        out += ["PyTorch CNODE evaluations per window (batch 1): "
                + ", ".join(sorted({f"{r['solver']} {r['nfe_per_window']:.0f}" for r in nfe})) + ".", ""]
    if run_root is not None:
        out += _figures(run_root, ["bench_latency.png", "bench_throughput.png"], figures)
    below = [r for r in bench["latency"] if r["batch"] == 1 and r.get("x_floor") is not None and r["x_floor"] < 1]
    if below:
        out += ["**Below the floor:** " + "; ".join(
            f"{RUNTIME_NAME.get(r['runtime'], r['runtime'])} {r['model']} {r['precision']} ({_setting(r)}) at "
            f"{r['x_floor']:.2f}x" for r in below) + ". A measured time under the floor means the limits were "
            "measured low (another user of the shared machine slowed the peak or bandwidth probe) or the floor's "
            "traffic model is too pessimistic for that runtime; treat the floor as approximate here.", ""]
    out += _floors_section(bench) + _targets_section(bench) + _limits_section(bench) + _memory_section(bench)
    out += _profiles_section(bench)
    if bench.get("solvers_meta", {}).get("skipped"):
        out += [f"Solver study: {bench['solvers_meta']['skipped']}.", ""]
    return out


# ----------------------------------------------------------------------------- figures


def _save(fig, path: Path) -> None:
    save_png(fig, path, bbox_inches="tight")


def draw_bench_figures(bench: dict, fig_dir: Path) -> list[Path]:
    """figures/bench_latency.png (batch-1 p50 with p90-p99 whiskers and each floor) and
    figures/bench_throughput.png (batch-96 windows per second)."""
    plt = pyplot()
    written = []
    recs1 = [r for r in bench["latency"] if r["batch"] == 1]
    recsn = [r for r in bench["latency"] if r["batch"] != 1]
    if not recs1:
        return written
    colors = {"cpp": "tab:green", "ort": "tab:blue", "torch": "tab:orange"}
    for name, recs, value, xlabel in (
            ("bench_latency.png", recs1, "p50_us", "batch-1 latency per window (us, log scale): p50 bar, p90-p99 line"),
            ("bench_throughput.png", recsn, "throughput_wps", "batch-96 throughput (windows per second, log scale)")):
        if not recs:
            continue
        fig, axes = plt.subplots(1, 2, figsize=(13, 0.32 * max(len(recs) // 2, 6) + 1.5), sharex=True)
        for ax, model in zip(axes, ("cnode", "gru")):
            rs = sorted((r for r in recs if r["model"] == model),
                        key=lambda r: (RUNTIME_ORDER.get(r["runtime"], 9), r["precision"], r["solver"], r["threads"],
                                       bool(r.get("spinning"))))
            ys = list(range(len(rs)))
            ax.barh(ys, [r[value] for r in rs], color=[colors.get(r["runtime"], "grey") for r in rs])
            if value == "p50_us":
                for y, r in zip(ys, rs):
                    ax.plot([r["p90_us"], r["p99_us"]], [y, y], color="black", lw=1)
                for f in bench.get("floors", []):
                    if f["model"] == model:
                        ax.axvline(f["floor_us"], ls="--" if f["precision"] == "fp32" else ":", color="red",
                                   label=f"floor {f['precision']} {f['floor_us']:.2f} us")
                ax.legend(loc="lower right", fontsize=8)
            ax.set_yticks(ys)
            ax.set_yticklabels([f"{r['runtime']} {r['precision']} {r['solver']} {_setting(r)}" for r in rs], fontsize=8)
            ax.invert_yaxis()
            ax.set_xscale("log")
            ax.set_title("CNODE" if model == "cnode" else "GRU")
            ax.set_xlabel(xlabel, fontsize=9)
            ax.grid(axis="x", alpha=0.3)
        fig.tight_layout()
        path = Path(fig_dir) / name
        _save(fig, path)
        written.append(path)
    return written


# ----------------------------------------------------------------------------- other stages


def sim_section(root: Path) -> list[str]:
    path = root / "dataset.npz"
    if not path.is_file():
        return []
    import numpy as np

    from core.contracts import CLASS_NAMES
    from sim.dataset import SPLITS, load_dataset, window_starts

    try:
        ds = load_dataset(path)
    except Exception as exc:  # noqa: BLE001  (a report never dies on one bad file)
        return ["## Simulation", "", f"Could not read {path}: {exc}", ""]
    s = ds.config.sim
    n, t, c = ds["telemetry"].shape
    per_traj = len(window_starts(t, s.window, s.stride))
    rows = []
    for split, code in SPLITS.items():
        fc = ds["fault_class"][ds["split"] == code]
        rows.append([split, str(len(fc))] + [str(int(np.sum(fc == k))) for k in range(len(CLASS_NAMES))]
                    + [str(len(fc) * per_traj)])
    out = ["## Simulation", "",
           f"Made by `quadfdi sim` (config: `config.toml`): {n} trajectories of {s.duration_s:g} s at "
           f"{1 / s.sample_dt_s:g} Hz ({t} samples, {c} channels, vehicle {s.vehicle}, seed {s.seed}); windows of "
           f"{s.window} samples every {s.stride} ({per_traj} per trajectory), labelled by the severity at their last "
           f"sample (threshold {s.severity_threshold:g}).", ""]
    out += table(["split", "trajectories"] + [f"{k}" for k in CLASS_NAMES] + ["windows"], rows)
    figs = sorted(p.name for p in (root / "figures").glob("sim_traj*.png"))
    return out + _figures(root, figs)


def train_section(root: Path) -> list[str]:
    metrics = _read_json(root / "metrics.json")
    if not metrics:
        return []
    out = ["## Training and test metrics", "",
           "Made by `quadfdi train` (`metrics.json`, test split; `history.json` for the training runs).", ""]
    cols = [("macro_f1", "macro F1", 4), ("accuracy", "accuracy", 4), ("balanced_accuracy", "balanced acc.", 4),
            ("mcc", "MCC", 4), ("roc_auc_ovr", "ROC AUC", 4), ("any_fault_f1", "any-fault F1", 4),
            ("mean_detection_delay_s", "detection delay (s)", 2), ("missed_faults", "missed faults", 0),
            ("false_alarm_rate", "false alarms", 3)]
    rows = []
    for model, m in metrics.items():
        if isinstance(m, dict) and "macro_f1" in m:
            rows.append([model] + [_num(m.get(k), nd) if isinstance(m.get(k), (int, float)) else "—"
                                   for k, _, nd in cols])
    out += table(["model"] + [name for _, name, _ in cols], rows)
    per = [(model, m["per_class"]) for model, m in metrics.items() if isinstance(m, dict) and "per_class" in m]
    if per:
        classes = list(per[0][1])
        out += ["Per-class F1:", ""]
        out += table(["model"] + classes, [[model] + [_num(pc[k].get("f1"), 3) for k in classes] for model, pc in per])
    hist = _read_json(root / "history.json") or {}
    rows = []
    for model, h in hist.items():
        if isinstance(h, dict) and h.get("loss"):
            rows.append([model, str(len(h["loss"])), str(int(h.get("best_epoch", 0)) + 1),
                         _num(sum(h.get("epoch_s", [])), 1),
                         _num(h["val_macro_f1"][-1], 4) if h.get("val_macro_f1") else "—",
                         _num(sum(h["nfe_per_forward"]) / len(h["nfe_per_forward"]), 0)
                         if h.get("nfe_per_forward") else "—"])
    if rows:
        out += table(["model", "epochs", "best epoch", "training time (s)", "last val. macro F1", "NFE / forward"],
                     rows)
    if (root / "results.md").is_file():
        out += ["### Seeds study (`quadfdi train study`)", ""] + _demote((root / "results.md").read_text(), 2)
    figs = sorted(p.name for p in (root / "figures").glob("*.png") if p.name.startswith(TRAIN_FIGURES))
    return out + _figures(root, figs)


def export_section(root: Path) -> list[str]:
    m = _read_json(root / "export" / "manifest.json")
    if not m:
        return []
    v = m.get("verification", {})
    out = ["## Export", "",
           f"Made by `quadfdi export` (`export/manifest.json`, schema {m.get('schema_version')}): classic RK4 with "
           f"N = {m.get('solver', {}).get('steps')} unrolled, opset {m.get('opset')}; verified on "
           f"{v.get('test_windows')} test windows: **{'passed' if v.get('passed') else 'FAILED'}**.", ""]
    rows = []
    for key in ("cnode_fp32_vs_pytorch", "gru_fp32_vs_pytorch"):
        if key in v:
            x = v[key]
            rows.append([key, f"{x.get('max_abs_logit_diff', float('nan')):.2e}", f"{x.get('bound', float('nan')):.1e}",
                         "pass" if x.get("passed") else "FAIL"])
    if rows:
        out += table(["check", "max abs logit diff", "bound", "result"], rows)
    rows = []
    for key in ("cnode_int8_vs_fp32", "gru_int8_vs_fp32"):
        if key in v:
            x = v[key]
            rows.append([key, _pct(x.get("argmax_agreement")), _num(x.get("macro_f1_fp32_points"), 2),
                         _num(x.get("macro_f1_int8_points"), 2), _num(x.get("macro_f1_drop_points"), 2),
                         "met" if x.get("meets_target") else "missed"])
    if rows:
        out += table(["int8 vs fp32", "argmax agreement", "macro F1 fp32", "macro F1 int8", "drop (points)",
                      "target"], rows)
    rows = [[name, f"{e['bytes']:,}", e["sha256"][:12]] for name, e in m.get("files", {}).items()]
    out += ["Files:", ""] + table(["file", "bytes", "sha256 (first 12)"], rows)
    cov = root / "export" / "coverage.md"
    if cov.is_file():
        out += _demote(cov.read_text(), 2)
    return out


def parity_section(root: Path) -> list[str]:
    md = root / "parity" / "parity.md"
    if md.is_file():
        return ["## Parity (C++ reference vs ONNX Runtime and PyTorch; Cortex-M)", ""] + _demote(md.read_text(), 2)
    p = _read_json(root / "parity" / "parity.json")
    if not p:
        return []
    verdict = "pass" if p.get("passed") else "FAIL"
    return ["## Parity", "", f"Made by `{p.get('command', 'quadfdi parity')}`: **{verdict}**"
            + ("" if p.get("passed") else ": " + "; ".join(p.get("problems", []))) + ".", ""]


def solvers_section(root: Path) -> list[str]:
    if not any((root / "bench" / f).is_file() for f in ("solvers.json", "solver_matrix.json")):
        return []
    try:
        from bench.cli_solvers import solver_section
    except ImportError:
        return []
    try:
        text = solver_section(root)
    except Exception as exc:  # noqa: BLE001
        return ["## Solvers", "", f"Could not render the solver study: {exc}", ""]
    return text.splitlines() + [""] if text.strip() else []


def headline(root: Path, bench: dict | None) -> list[str]:
    """A few numbers up front, each from the file named beside it."""
    out = []
    metrics = _read_json(root / "metrics.json") or {}
    f1 = [f"{k} {v['macro_f1']:.4f}" for k, v in metrics.items() if isinstance(v, dict) and "macro_f1" in v]
    if f1:
        out.append(f"- Test macro F1 (metrics.json): {', '.join(f1)}.")
    man = _read_json(root / "export" / "manifest.json") or {}
    drops = [f"{k.split('_')[0]} {v['macro_f1_drop_points']:+.2f}" for k, v in man.get("verification", {}).items()
             if isinstance(v, dict) and "macro_f1_drop_points" in v]
    if drops:
        out.append(f"- int8 macro F1 drop in points (export manifest): {', '.join(drops)}.")
    if bench:
        b1 = {(r["runtime"], r["model"], r["precision"]): r for r in bench["latency"]
              if r["batch"] == 1 and r["threads"] == 1 and not r.get("spinning") and r["solver"] != "dopri5"
              and not str(r["solver"]).startswith("dopri5")}
        parts = []
        for model in ("cnode", "gru"):
            for rt in ("cpp", "ort"):
                r = b1.get((rt, model, "fp32"))
                if r:
                    parts.append(f"{model} {RUNTIME_NAME[rt]} {_us(r['p50_us'])} us"
                                 + (f" ({r['x_floor']:.1f}x floor)" if r.get("x_floor") else ""))
        if parts:
            out.append(f"- Batch-1 p50 latency, fp32, 1 thread (bench.json): {'; '.join(parts)}.")
        ts = bench.get("targets", [])
        if ts:
            out.append(f"- Latency targets (bench.json): {sum(t['met'] for t in ts)} of {len(ts)} met"
                       + ("; missed: " + "; ".join(f"{t['target']} ({t['model']} {t['precision']}: {t['measured']:.2f})"
                                                  for t in ts if not t["met"]) if any(not t["met"] for t in ts) else "")
                       + ".")
        mcu = [m for m in bench.get("memory", []) if m["item"] in ("flash_bytes", "static_ram_bytes")
               and m["model"] == "cnode" and m["precision"] == "int8" and m["runtime"] not in RUNTIME_NAME]
        if mcu:
            out.append("- Cortex-M int8 CNODE (parity/mcu.json): " + ", ".join(
                f"{m['runtime']} {m['item'].replace('_bytes', '').replace('_', ' ')} {m['value']:,} B"
                for m in mcu) + ".")
    study = _read_json(root / "bench" / "solvers.json")
    if study and study.get("matched"):
        try:
            from bench.solver_report import headline as solver_headline

            out.append(f"- Solvers (bench/solvers.json): {solver_headline(study)}")
        except Exception:  # noqa: BLE001
            pass
    return (["## Headline", ""] + out + [""]) if out else []


def run_report_markdown(run_root: str | Path) -> str:
    root = Path(run_root)
    bench = _read_json(root / "bench.json")
    lines = [f"# quadfdi run report: {root.name}", "",
             f"Assembled by `bench.report.write_run_report` from the files in `{root}` (regenerate with "
             f"`quadfdi bench report --run {root}`). Sections appear for the stages that have run.", ""]
    lines += headline(root, bench)
    lines += sim_section(root)
    lines += train_section(root)
    lines += export_section(root)
    lines += parity_section(root)
    if bench:
        lines += bench_section(bench, "figures", root)
    lines += solvers_section(root)
    shown = set()
    text = "\n".join(lines)
    for p in sorted((root / "figures").glob("*.png")) if (root / "figures").is_dir() else []:
        if f"figures/{p.name}" not in text:
            shown.add(p.name)
    if shown:
        lines += ["## Other figures", ""] + _figures(root, sorted(shown))
    return "\n".join(lines).rstrip() + "\n"


def write_run_report(run_root: str | Path, log: Callable[[str], None] | None = None) -> Path:
    """Write ``runs/<name>/report.md`` (atomically) from the run folder's files; return its path."""
    root = Path(run_root)
    path = root / "report.md"
    write_text(path, run_report_markdown(root))
    if log:
        log(f"wrote {path}")
    return path
