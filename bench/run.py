"""The bench stage: the deployed runtimes timed -> bench.json and the bench figures.

``bench_run(run, cfg)`` reads ``runs/<name>/`` (dataset.npz for the test windows, cnode.pt and
gru.pt, export/manifest.json and the files it lists, fwref_infer (the per-user build cache's), and
parity/mcu.json when present), measures with the settings of ``cfg.bench`` (the ``[bench]``
config section; ``quick`` replaces the counts with tiny ones) and writes:

- ``runs/<name>/bench.json`` (docs/bench.md), atomically, after everything was measured;
- ``runs/<name>/figures/bench_*.png`` (``bench.figures.draw_bench_figures``).

It measures limits, latency, floors, memory and profiles; it solves no ODE and trains nothing.
The solver study is its own stage (package ``solverstudy``): bench.json's ``solvers`` list copies
the study's records when ``runs/<name>/solvers/solvers.json`` exists, and ``solvers_meta`` says so
either way. report.md is the app layer's (``quadfdi report``, ``quadfdi run``).
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import tempfile
import time
from pathlib import Path
from typing import Callable

from quadfdi.bench.config import BenchConfig
from quadfdi.core.config import Config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.rundir import RunDir
from quadfdi.formats.export_folder import Export

SCHEMA_VERSION = 1
SOLVERS_JSON = Path("solvers") / "solvers.json"  # written by solverstudy.run.study_run


def bench_json_path(run: RunDir) -> Path:
    return run.root / "bench.json"


def _machine(cpus: str) -> dict:
    """The machine this bench measured (core.machine: CPU model and vector ISA read at run time)."""
    import datetime

    import numpy
    import onnxruntime
    import torch

    from quadfdi.core.machine import cpu_facts

    return {**cpu_facts(), "pinned_cpus": cpus, "date": datetime.date.today().isoformat(),
            "python": platform.python_version(), "torch": torch.__version__, "onnxruntime": onnxruntime.__version__,
            "numpy": numpy.__version__, "load_average_start": list(os.getloadavg())}


def _profiles(export: Export, test_x, fwref: str | None, fw_flags: dict | None, cpus: str,
              quick: bool, latency: list[dict], bc: BenchConfig, log: Callable[[str], None]) -> dict:
    """ORT per-op profiles and C++ callgrind counts (bench.profile), keyed 'model_precision'."""
    import numpy as np

    from quadfdi.bench.latency import sample_windows
    from quadfdi.bench.limits import cpu_prefix
    from quadfdi.bench.profile import callgrind_cpp, ort_profile, simd_share

    t0 = time.perf_counter()
    out: dict = {"ort": {}, "cpp": {}}
    steps = export.steps
    with tempfile.TemporaryDirectory(prefix="quadfdi-prof-") as tmp:
        tmpd = Path(tmp)
        x = sample_windows(test_x, 20 if quick else bc.profile_windows, seed=1)
        np.save(tmpd / "w.npy", x)
        n_cg = min(len(x), 2 if quick else bc.callgrind_windows)
        np.ascontiguousarray(x[:n_cg], dtype="<f4").tofile(tmpd / "w.f32")
        for model in ("cnode", "gru"):
            for precision in ("fp32",) if quick else ("fp32", "int8"):
                key = f"{model}_{precision}"
                art = str(export.artifact(model, precision))
                solver = f"rk4-{steps}" if model == "cnode" else "gru"
                out["ort"][key] = ort_profile(art, str(tmpd / "w.npy"), model, precision, solver, cpu_prefix(cpus),
                                              len(x), tmpd / f"{key}.json")
                if fwref:
                    cg = callgrind_cpp(fwref, str(export.weights_path), str(tmpd / "w.f32"), n_cg, model,
                                       precision == "int8")
                    if cg is not None:
                        out["cpp"][key] = cg
    if fwref:
        out["cpp_build"] = fw_flags
        out["cpp_simd"] = simd_share(fwref)
        # instructions retired per nanosecond at the measured batch-1 p50 (no hardware counters here)
        for key, cg in out["cpp"].items():
            model, precision = key.split("_")
            r = next((r for r in latency if r["runtime"] == "cpp" and r["model"] == model
                      and r["precision"] == precision and r["batch"] == 1), None)
            if r and "ir_per_window" in cg:
                cg["instructions_per_ns_at_p50"] = cg["ir_per_window"] / (r["p50_us"] * 1e3)
                cg["ir_per_mac"] = cg["ir_per_window"] / export.manifest["models"][model]["macs_per_window"]
    out["seconds"] = time.perf_counter() - t0
    log(f"bench profiles: ORT per-op and C++ callgrind in {out['seconds']:.0f} s")
    return out


def solver_records(run_root: Path) -> tuple[list, dict]:
    """The solver study's records for bench.json's ``solvers`` list, and a note on where they came from.

    No ``solvers/solvers.json`` means the study did not run in this folder: an empty list and a note
    saying so. An existing file is read by the study's own reader (a bad file is its one-line error).
    """
    path = run_root / SOLVERS_JSON
    if not path.is_file():
        return [], {"note": f"no solver study in this run ({SOLVERS_JSON} absent; the solvers stage of "
                            "`quadfdi run` writes it)"}
    from quadfdi.formats.solver_files import load_records

    return list(load_records(run_root)), {"file": str(SOLVERS_JSON)}


def test_windows(run: RunDir, export: Export):
    """The run's test windows, checked against the export and the checkpoints."""
    from quadfdi.formats.dataset import load_dataset, make_windows

    for kind in ("cnode", "gru"):
        if not run.checkpoint(kind).is_file():
            raise QuadfdiError(f"{run.checkpoint(kind)} is missing: run `quadfdi train --run {run.root}` first")
    from quadfdi.train.vehicle_ref import profiled

    test = make_windows(profiled(load_dataset(run.dataset), export.profile()), "test")  # the export's inputs
    if len(test) == 0:
        raise QuadfdiError(f"{run.dataset} has no test windows to time")
    want = (export.window, len(export.channel_names))
    if test.x.shape[1:] != want:
        raise QuadfdiError(f"{run.dataset}: windows are {test.x.shape[1:]}, the export expects {want}: "
                           f"re-run `quadfdi export`")
    return test


def _private_fwref(fwref_path: str | None, tmp: Path) -> tuple[str | None, dict | None]:
    """Copy fwref_infer into ``tmp`` (a rebuild of its build folder while timing cannot change
    the copy); (copy path, its build flags and sha256), or (None, None)."""
    if not fwref_path:
        return None, None
    from quadfdi.bench.profile import build_flags

    fw_copy = str(tmp / "fwref_infer")
    shutil.copy2(fwref_path, fw_copy)
    fw_flags = build_flags(fwref_path)  # the flags of the binary just copied
    fw_flags["sha256"] = hashlib.sha256(Path(fw_copy).read_bytes()).hexdigest()
    return fw_copy, fw_flags


def _measure(run: RunDir, cfg: Config, export: Export, test_x, fw_copy: str | None, fw_flags: dict | None,
             cpus: str, quick: bool, log: Callable[[str], None]) -> dict:
    """Limits (before and after), latency, floors, profiles and memory, each timed."""
    from quadfdi.bench.floors import attach_distance, below_floor, floors, violation_text
    from quadfdi.bench.cpp_pairs import measure_cpp_pairs
    from quadfdi.bench.latency import Counts, measure_latency, sample_windows
    from quadfdi.bench.limits import measure_limits, merge_limits
    from quadfdi.bench.memory import memory_records
    from quadfdi.bench.stream import stream_section

    timing: dict[str, float] = {}
    manifest = export.manifest
    window, channels = export.window, len(export.channel_names)
    t0 = time.perf_counter()
    # the thread counts the latencies are timed at (1 always: the batch-1 floors use it); a 2-thread
    # pass for a bench that times 1 thread only cost the tiny pipeline of the tests ~10 s for nothing
    limits = measure_limits(cpus, quick, window, channels, log=log, threads=tuple(sorted({1, *cfg.bench.threads})))
    timing["limits"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    lat = measure_latency(run.root, manifest, test_x, cfg.train.rtol, cfg.bench, cpus=cpus, quick=quick,
                          fwref=fw_copy, log=log)
    timing["latency"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    after = measure_limits(cpus, quick, window, channels, log=log, threads=(1,))
    limits = merge_limits([limits, after])
    timing["limits"] += time.perf_counter() - t0
    floor_list = floors(manifest["models"], export.steps, limits)
    attach_distance(lat["latency"], floor_list)
    if below_floor(lat["latency"]):  # re-measure once: a probe slowed by another user reads the machine low
        log(f"bench: below the floor, re-measuring the limits: {violation_text(below_floor(lat['latency']))}")
        t0 = time.perf_counter()
        limits = merge_limits([limits, measure_limits(cpus, quick, window, channels, log=log, threads=(1,))])
        timing["limits"] += time.perf_counter() - t0
        floor_list = floors(manifest["models"], export.steps, limits)
        attach_distance(lat["latency"], floor_list)
    t0 = time.perf_counter()
    # the C++ int8 / fp32 ratios: both precisions in one process (bench/cpp_pairs.py says why)
    n = Counts.of(cfg.bench, quick).n
    cpp_pairs = {"skipped": "the C++ reference is not measured (--skip-cpp or no build)"} if not fw_flags else \
        measure_cpp_pairs(Path(fw_flags["build_dir"]), export.weights_path, sample_windows(test_x, n), n,
                          cpus, cfg.bench.worker_timeout_s, log)
    timing["cpp_pairs"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    profiles = _profiles(export, test_x, fw_copy, fw_flags, cpus, quick, lat["latency"], cfg.bench, log)
    timing["profiles"] = time.perf_counter() - t0
    memory = memory_records(run.root, manifest, lat["runtime_memory"], fw_copy)
    t0 = time.perf_counter()
    stream = {"skipped": "the C++ reference is not measured (--skip-cpp or no build)"} if not fw_flags else \
        stream_section(run.root, export, str(Path(fw_flags["build_dir"]) / "fwref_infer"), cpus,
                       1 if quick else cfg.bench.stream_flights, log,
                       ("cortex-m4",) if quick else ("cortex-m4", "cortex-m7"))
    timing["stream"] = time.perf_counter() - t0
    return {"limits": limits, "lat": lat, "floors": floor_list, "profiles": profiles, "memory": memory,
            "stream": stream, "cpp_pairs": cpp_pairs, "timing": timing}


def _command(run: RunDir, quick: bool, skip_cpp: bool) -> str:
    return f"quadfdi bench --run {run.root}" + (" --quick" if quick else "") + (" --skip-cpp" if skip_cpp else "")


def graph_nodes(export: Export) -> dict:
    """Per exported ONNX graph: nodes as written and after ONNX Runtime's optimizer (with op counts);
    ``ort_body_nodes``: the nodes in a Scan's body after the optimizer (run once per step)."""
    import onnx

    from quadfdi.runtimes.ort import optimized_nodes

    out = {}
    for key, name in export.manifest["artifacts"].items():
        path = export.root / name
        ort_ops = optimized_nodes(path)
        out[key] = {"file": name, "nodes": len(onnx.load(str(path)).graph.node), "ort_nodes": ort_ops.pop("total"),
                    "ort_body_nodes": ort_ops.pop("body"), "ort_ops": ort_ops}
    return out


def _bench_dict(run: RunDir, export: Export, m: dict, machine: dict, fwref: tuple[str | None, str],
                command: str, quick: bool) -> dict:
    """bench.json's content (docs/bench.md) from the measurements ``m`` of ``_measure``."""
    from quadfdi.bench.floors import below_floor, targets, violation_text
    from quadfdi.bench.int8_targets import int8_targets
    from quadfdi.bench.memory import mcu_records

    solvers, solver_meta = solver_records(run.root)
    fwref_path, fwref_note = fwref
    steps = export.steps
    lat = m["lat"]
    return {
        "schema_version": SCHEMA_VERSION,
        "producer": "quadfdi bench",
        "command": command,
        "quick": quick,
        "machine": machine,
        "limits": m["limits"],
        "models": {k: {**v, "export_steps": steps} for k, v in export.manifest["models"].items()},
        "latency": lat["latency"],
        "floors": m["floors"],
        "targets": targets(lat["latency"], m["floors"]) + int8_targets(lat["latency"], m["floors"], lat["ort_pairs"],
                                                                       m["cpp_pairs"]),
        "ort_pairs": lat["ort_pairs"],
        "cpp_pairs": m["cpp_pairs"],
        "floor_violations": violation_text(below_floor(lat["latency"])),
        "graphs": graph_nodes(export),
        "memory": m["memory"],
        "mcu": mcu_records(run.root)[1],
        "stream": m["stream"],
        "solvers": solvers,
        "solvers_meta": solver_meta,
        "profiles": m["profiles"],
        "windows": lat["windows"],
        "counts": lat["counts"],
        "workers": lat["workers"],
        "fwref": {"path": fwref_path, "how": fwref_note,
                  "sha256": (m["profiles"].get("cpp_build") or {}).get("sha256") if fwref_path else None},
        "skipped": [] if fwref_path else [fwref_note],
        "timing_s": m["timing"],
    }


def bench_run(run: RunDir, cfg: Config, log: Callable[[str], None] = print, *, quick: bool = False,
              skip_cpp: bool = False, cpus: str | None = None, fwref: str | None = None,
              command: str | None = None) -> dict:
    """The whole bench stage (module doc); returns the bench.json dict. ``cpus`` defaults to
    ``cfg.bench.cpus``; ``quick``, ``skip_cpp`` and ``fwref`` are how to run, not what to measure."""
    from quadfdi.bench.latency import check_cpus

    cpus = check_cpus(cpus or cfg.bench.cpus)  # before the heavy imports: a typo fails at once

    from quadfdi.core.records import load_record
    from quadfdi.core.stage import stage

    with stage(run.root, "bench", {"bench": cfg.to_dict()["bench"]}, targets=("bench.json",)) as st:
        for entry in (load_record(run.root, "export") or {"outputs": [{"path": "export/manifest.json"}]})["outputs"]:
            st.consume(entry["path"])
        st.consume("dataset.npz")
        bench = _bench_into(run, cfg, RunDir(st.out), log, quick, skip_cpp, cpus, fwref, command)
    # Published first: bench.json says which floors failed, and the report shows FLOOR INVALID.
    if bench["floor_violations"] and cfg.bench.fail_below_floor:
        raise QuadfdiError("bench: measured below the floor after re-measuring the limits, so the floors are not lower "
                           f"bounds on this machine ({bench['floor_violations']}); peak "
                           f"{bench['limits']['peak_gflops']:.1f} GFLOP/s, L2 {bench['limits']['l2_gbps']:.1f} GB/s, "
                           f"bandwidth probe sane: {bench['limits'].get('bandwidth_sane')}; bench.json written")
    return bench


def _bench_into(run: RunDir, cfg: Config, dest: RunDir, log: Callable[[str], None], quick: bool, skip_cpp: bool,
                cpus: str, fwref: str | None, command: str | None) -> dict:
    from quadfdi.bench.latency import find_fwref
    from quadfdi.bench.figures import draw_bench_figures
    from quadfdi.core.jsonio import to_jsonable, write_json
    t_start = time.perf_counter()
    export = Export.open(run.export)
    test = test_windows(run, export)
    machine = _machine(cpus)
    fwref_found = (None, "C++ reference not measured: --skip-cpp") if skip_cpp else find_fwref(fwref, log)
    if not fwref_found[0]:
        log(f"bench: {fwref_found[1]}")
    with tempfile.TemporaryDirectory(prefix="quadfdi-fwref-copy-") as tmp:
        fw_copy, fw_flags = _private_fwref(fwref_found[0], Path(tmp))
        m = _measure(run, cfg, export, test.x, fw_copy, fw_flags, cpus, quick, log)
    machine["load_average_end"] = list(os.getloadavg())
    timing = m["timing"]
    timing["total"] = time.perf_counter() - t_start
    bench = to_jsonable(_bench_dict(run, export, m, machine, fwref_found, command or _command(run, quick, skip_cpp),
                                    quick))
    write_json(bench_json_path(dest), bench, indent=1)
    figs = draw_bench_figures(bench, dest.figures)
    log(f"bench: wrote {bench_json_path(run)} and {len(figs)} figures in {timing['total']:.0f} s "
        f"(limits {timing['limits']:.0f} s, latency {timing['latency']:.0f} s, profiles {timing['profiles']:.0f} s); "
        f"`quadfdi report --run {run.root}` rewrites report.md"
        + ("; a quick run (few windows, 1 thread only): not figures to quote" if quick else ""))
    return bench
