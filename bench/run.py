"""The bench stage: limits, latency, floors, memory, profiles, the solver study -> bench.json + report.md.

``bench_run(run, cfg)`` reads ``runs/<name>/`` (dataset.npz for the test windows, cnode.pt and
gru.pt, export/manifest.json and the files it lists, firmware_ref/build/fwref_infer, and
parity/mcu.json when present) and writes:

- ``runs/<name>/bench.json`` (docs/bench.md), atomically, after everything was measured;
- ``runs/<name>/figures/bench_*.png`` and ``runs/<name>/report.md`` (the whole run's report,
  ``bench.report.write_run_report``);
- the solver study's own files (``runs/<name>/bench/solvers.json``, ``solvers.md``, figures) through
  ``bench.cli_solvers.run_solvers``, unless ``skip_solvers``; its records become bench.json's
  ``solvers`` list (an earlier solvers.json is picked up when the study is skipped).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import shutil
import tempfile
import time
from pathlib import Path
from typing import Callable

from core.atomic import write_text
from core.config import Config
from core.errors import QuadfdiError
from core.rundir import RunDir

SCHEMA_VERSION = 1
QUICK_SOLVER_ARGS = ["--sample", "4", "--steps", "1,4,8", "--rtols", "1e-2,1e-3", "--jump", "on",
                     "--fixed-methods", "euler,rk4", "--adaptive-methods", "dopri5"]


def bench_json_path(run: RunDir) -> Path:
    return run.root / "bench.json"


def _machine(cpus: str) -> dict:
    import numpy
    import onnxruntime
    import torch

    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": model or platform.processor(), "logical_cpus": os.cpu_count(), "pinned_cpus": cpus,
            "python": platform.python_version(), "torch": torch.__version__, "onnxruntime": onnxruntime.__version__,
            "numpy": numpy.__version__, "load_average_start": list(os.getloadavg())}


def _solver_study(run: RunDir, quick: bool, skip: bool, extra: list[str] | None,
                  log: Callable[[str], None]) -> tuple[list, dict]:
    """Run the other engineer's solver study (bench.cli_solvers) unless skipped; its records."""
    meta: dict = {}
    path = run.root / "bench" / "solvers.json"
    if not skip:
        try:
            from bench.cli_solvers import add_solver_args, run_solvers
        except ImportError as exc:
            meta["skipped"] = f"solver study not available: {exc}"
        else:
            p = argparse.ArgumentParser(prog="quadfdi bench")
            add_solver_args(p)
            argv = ["--run", str(run.root)] + (QUICK_SOLVER_ARGS if quick else []) + list(extra or [])
            t0 = time.perf_counter()
            run_solvers(p.parse_args(argv))
            meta["seconds"] = time.perf_counter() - t0
            meta["argv"] = argv
    elif path.is_file():
        meta["note"] = "study skipped (--skip-solvers); records from the existing bench/solvers.json"
    else:
        meta["skipped"] = "--skip-solvers and no bench/solvers.json"
    if path.is_file():
        try:
            study = json.loads(path.read_text())
            return list(study.get("solvers", [])), {**meta, "file": "bench/solvers.json",
                                                    "command": study.get("meta", {}).get("command")}
        except (OSError, json.JSONDecodeError) as exc:
            raise QuadfdiError(f"{path} cannot be read as JSON: {exc}") from None
    return [], meta


def _profiles(run: RunDir, manifest: dict, test_x, fwref: str | None, fw_flags: dict | None, cpus: str,
              quick: bool, latency: list[dict], log: Callable[[str], None]) -> dict:
    """ORT per-op profiles and C++ callgrind counts (bench.profile), keyed 'model_precision'."""
    import numpy as np

    from bench.latency import sample_windows
    from bench.limits import cpu_prefix
    from bench.profile import callgrind_cpp, ort_profile, simd_share

    t0 = time.perf_counter()
    out: dict = {"ort": {}, "cpp": {}}
    steps = int(manifest["solver"]["steps"])
    with tempfile.TemporaryDirectory(prefix="quadfdi-prof-") as tmp:
        tmpd = Path(tmp)
        x = sample_windows(test_x, 20 if quick else 100, seed=1)
        np.save(tmpd / "w.npy", x)
        n_cg = 2 if quick else 5
        np.ascontiguousarray(x[:n_cg], dtype="<f4").tofile(tmpd / "w.f32")
        for model in ("cnode", "gru"):
            for precision in ("fp32",) if quick else ("fp32", "int8"):
                key = f"{model}_{precision}"
                art = str(run.export / manifest["artifacts"][key])
                solver = f"rk4-{steps}" if model == "cnode" else "gru"
                out["ort"][key] = ort_profile(art, str(tmpd / "w.npy"), model, precision, solver, cpu_prefix(cpus),
                                              len(x), tmpd / f"{key}.json")
                if fwref:
                    cg = callgrind_cpp(fwref, str(run.export / "weights.bin"), str(tmpd / "w.f32"), n_cg, model,
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
                cg["ir_per_mac"] = cg["ir_per_window"] / manifest["models"][model]["macs_per_window"]
    out["seconds"] = time.perf_counter() - t0
    log(f"bench profiles: ORT per-op and C++ callgrind in {out['seconds']:.0f} s")
    return out


def bench_run(run: RunDir, cfg: Config, log: Callable[[str], None] = print, *, quick: bool = False,
              skip_solvers: bool = False, skip_cpp: bool = False, cpus: str = "0,1", fwref: str | None = None,
              solver_args: list[str] | None = None, command: str | None = None) -> dict:
    """The whole bench stage (module doc); returns the bench.json dict."""
    from bench.latency import check_cpus

    cpus = check_cpus(cpus)  # before the heavy imports: a typo fails at once
    from bench.floors import attach_distance, floors, targets
    from bench.latency import find_fwref, measure_latency
    from bench.limits import measure_limits, merge_limits
    from bench.memory import mcu_records, memory_records
    from bench.report import draw_bench_figures, write_run_report
    from export.manifest import check_files, load_manifest
    from sim.dataset import load_dataset, make_windows
    from core.jsonio import to_jsonable, write_json

    t_start = time.perf_counter()
    timing: dict[str, float] = {}
    manifest = load_manifest(run.export / "manifest.json")
    check_files(manifest, run.export)
    for kind in ("cnode", "gru"):
        if not run.checkpoint(kind).is_file():
            raise QuadfdiError(f"{run.checkpoint(kind)} is missing: run `quadfdi train --run {run.root}` first")
    ds = load_dataset(run.dataset)
    test = make_windows(ds, "test")
    if len(test) == 0:
        raise QuadfdiError(f"{run.dataset} has no test windows to time")
    if test.x.shape[1:] != (manifest["window"], manifest["n_channels"]):
        raise QuadfdiError(f"{run.dataset}: windows are {test.x.shape[1:]}, the export expects "
                           f"({manifest['window']}, {manifest['n_channels']}): re-run `quadfdi export`")
    machine = _machine(cpus)
    fwref_path, fwref_note = (None, "C++ reference not measured: --skip-cpp") if skip_cpp else find_fwref(fwref, log)
    skipped = [] if fwref_path else [fwref_note]
    if not fwref_path:
        log(f"bench: {fwref_note}")

    with tempfile.TemporaryDirectory(prefix="quadfdi-fwref-copy-") as tmp:
        # Time a private copy: a rebuild of firmware_ref/build during the benchmark cannot change it.
        fw_copy, fw_flags = None, None
        if fwref_path:
            from bench.profile import build_flags

            fw_copy = str(Path(tmp) / "fwref_infer")
            shutil.copy2(fwref_path, fw_copy)
            fw_flags = build_flags(fwref_path)  # the flags of the binary just copied
            fw_flags["sha256"] = hashlib.sha256(Path(fw_copy).read_bytes()).hexdigest()
        t0 = time.perf_counter()
        limits = measure_limits(cpus, quick, manifest["window"], manifest["n_channels"], log=log)
        timing["limits"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        lat = measure_latency(run.root, manifest, test.x, cfg.train.rtol, cpus=cpus, quick=quick, fwref=fw_copy,
                              log=log)
        timing["latency"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        after = measure_limits(cpus, quick, manifest["window"], manifest["n_channels"], log=log, threads=(1,))
        limits = merge_limits([limits, after])
        timing["limits"] += time.perf_counter() - t0
        steps = int(manifest["solver"]["steps"])
        floor_list = floors(manifest["models"], steps, limits)
        attach_distance(lat["latency"], floor_list)
        t0 = time.perf_counter()
        profiles = _profiles(run, manifest, test.x, fw_copy, fw_flags, cpus, quick, lat["latency"], log)
        timing["profiles"] = time.perf_counter() - t0
        memory = memory_records(run.root, manifest, lat["runtime_memory"], fw_copy)
    t0 = time.perf_counter()
    solvers, solver_meta = _solver_study(run, quick, skip_solvers, solver_args, log)
    timing["solvers"] = time.perf_counter() - t0
    machine["load_average_end"] = list(os.getloadavg())
    timing["total"] = time.perf_counter() - t_start
    bench = {
        "schema_version": SCHEMA_VERSION,
        "producer": "quadfdi bench",
        "command": command or f"quadfdi bench --run {run.root}" + (" --quick" if quick else "")
        + (" --skip-solvers" if skip_solvers else "") + (" --skip-cpp" if skip_cpp else ""),
        "quick": quick,
        "machine": machine,
        "limits": limits,
        "models": {k: {**v, "export_steps": steps} for k, v in manifest["models"].items()},
        "latency": lat["latency"],
        "floors": floor_list,
        "targets": targets(lat["latency"], floor_list),
        "memory": memory,
        "mcu": mcu_records(run.root)[1],
        "solvers": solvers,
        "solvers_meta": solver_meta,
        "profiles": profiles,
        "windows": lat["windows"],
        "counts": lat["counts"],
        "workers": lat["workers"],
        "fwref": {"path": fwref_path, "how": fwref_note,
                  "sha256": (profiles.get("cpp_build") or {}).get("sha256") if fwref_path else None},
        "skipped": skipped,
        "timing_s": timing,
    }
    bench = to_jsonable(bench)
    write_json(bench_json_path(run), bench, indent=1)
    figs = draw_bench_figures(bench, run.figures)
    report = write_run_report(run.root)
    log(f"bench: wrote {bench_json_path(run)}, {len(figs)} figures and {report} in {timing['total']:.0f} s "
        f"(limits {timing['limits']:.0f} s, latency {timing['latency']:.0f} s, profiles {timing['profiles']:.0f} s, "
        f"solvers {timing['solvers']:.0f} s)")
    return bench
