"""The parity stage: the C++ reference against ONNX Runtime and PyTorch, host and Cortex-M.

``parity_run(run, cfg)`` reads ``runs/<name>/export/`` (manifest, weights.bin, reference.bin, the
four ONNX graphs), the run's checkpoints and dataset, and writes ``runs/<name>/parity/``:
parity.json, parity.md, mcu.json, logits.npz (each atomically). It builds firmware_ref/ (CMake, Release, in
the per-user build cache: runtimes.build), runs the whole test split one window at a time through C++ fp32 and int8
(fwref_infer), ONNX Runtime fp32 and int8 (batch 1) and PyTorch, runs fwref_parity on
reference.bin, and (``mcu=True``) the Cortex-M build under QEMU. The report is written first; then
a missed target is a one-line QuadfdiError.
"""

from __future__ import annotations

import json
import shlex
import subprocess
import time
from pathlib import Path
from typing import Callable

import numpy as np

from quadfdi.formats.export_folder import Export
from quadfdi.parity import compare, mcu as mcu_mod
from quadfdi.runtimes.mcu import tools_missing
from quadfdi.runtimes import fwref, ort, pytorch
from quadfdi.runtimes.build import build_host, source_dir
from quadfdi.parity.report import markdown
from quadfdi.parity.stream import stream_inputs
from quadfdi.core.atomic import ensure_dir, write_text
from quadfdi.core.config import Config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.npzio import write_npz
from quadfdi.core.stage import stage
from quadfdi.core.rundir import RunDir
from quadfdi.formats.dataset import load_dataset, make_windows
from quadfdi.train.vehicle_ref import profiled
from quadfdi.core.jsonio import write_json
from quadfdi.core.reportmd import over_bound_clause

SCHEMA_VERSION = 1


def parity_dir(run: RunDir) -> Path:
    return run.root / "parity"


def _write_json(path: Path, data: dict) -> None:
    write_json(path, data, indent=2)


def fwref_parity(build_dir: Path, weights: Path, reference: Path) -> dict:
    cmd = [str(build_dir / "fwref_parity"), "--weights", str(weights), "--reference", str(reference)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    lines = res.stdout.splitlines() + [ln for ln in res.stderr.splitlines() if ln.strip()]
    return {"command": " ".join(shlex.quote(c) for c in cmd), "exit_code": res.returncode,
            "passed": res.returncode == 0, "output": lines}


def host_parity(run: RunDir, export: Export, build_dir: Path, log: Callable[[str], None],
                out_dir: Path) -> tuple[dict, dict]:
    """Logits of every runtime on the test split and the pair metrics; (models, timing). The logits
    are also written to parity/logits.npz (keys <model>_<runtime>, plus the labels ``y``)."""
    weights_path, weights = export.weights_path, export.weights()
    ds = profiled(load_dataset(run.dataset), export.profile())  # the models' input channels
    test = make_windows(ds, "test")
    if len(test) == 0:
        raise QuadfdiError(f"{run.dataset} has no test windows to check parity on")
    x = test.x
    torch_models = pytorch.load_models({k: run.checkpoint(k) for k in ("cnode", "gru")}, export.steps)
    timing, logits = {}, {}
    motor: dict[str, dict] = {}  # a net with a motor head: its motor logits per runtime, from the same runs
    for model in ("cnode", "gru"):
        has = weights.has(f"{model}_motor", "fp32")
        names = ["logits"] + (["motor_logits"] if has else [])
        t0 = time.perf_counter()
        (cf, mf), (ci, mi) = (fwref.cpp_outputs(weights_path, model, i8, x, has, build_dir) for i8 in (False, True))
        logits[model] = {"cpp_fp32": cf, "cpp_int8": ci}
        timing[f"{model}_cpp"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        of, oi = (ort.outputs(export.artifact(model, p), x, names, batch=1) for p in ("fp32", "int8"))
        logits[model]["ort_fp32"], logits[model]["ort_int8"] = of[0], oi[0]
        timing[f"{model}_ort"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        logits[model]["torch"] = pytorch.torch_logits(torch_models[model], x)
        if has:
            motor[model] = {"cpp_fp32": mf, "cpp_int8": mi, "ort_fp32": of[1], "ort_int8": oi[1],
                            "torch": pytorch.torch_motor_logits(torch_models[model], x)}
        timing[f"{model}_torch"] = time.perf_counter() - t0
        log(f"parity: {model}: {len(x)} windows through C++ ({timing[f'{model}_cpp']:.1f} s), ONNX Runtime "
            f"({timing[f'{model}_ort']:.1f} s) and PyTorch ({timing[f'{model}_torch']:.1f} s)")

    write_npz(out_dir / "logits.npz",
              {"y": test.y, **{f"{m}_{k}": v for m, lg in logits.items() for k, v in lg.items()},
               **{f"{m}_motor_{k}": v for m, lg in motor.items() for k, v in lg.items()}})
    models = {}
    for model, lg in logits.items():
        if model in motor:
            models[f"{model}_motor"] = motor_pairs(motor[model])
            judge_fp32(models[f"{model}_motor"]["cpp_fp32_vs_ort_fp32"], motor[model], torch_models[model], x, "motor")
        pairs = {
            "cpp_fp32_vs_ort_fp32": compare.pair_metrics(lg["cpp_fp32"], lg["ort_fp32"]),
            "cpp_fp32_vs_torch": compare.pair_metrics(lg["cpp_fp32"], lg["torch"]),
            "ort_fp32_vs_torch": compare.pair_metrics(lg["ort_fp32"], lg["torch"]),
            "cpp_int8_vs_ort_int8": compare.pair_metrics(lg["cpp_int8"], lg["ort_int8"]),
            "cpp_int8_vs_cpp_fp32": compare.pair_metrics(lg["cpp_int8"], lg["cpp_fp32"]),
            "ort_int8_vs_ort_fp32": compare.pair_metrics(lg["ort_int8"], lg["ort_fp32"]),
        }
        pairs["cpp_fp32_vs_ort_fp32"]["target"] = compare.fp32_target(pairs["cpp_fp32_vs_ort_fp32"])
        judge_fp32(pairs["cpp_fp32_vs_ort_fp32"], lg, torch_models[model], x)
        pairs["cpp_int8_vs_ort_int8"]["target"] = compare.int8_target(
            lg["cpp_int8"], lg["ort_int8"], compare.logit_steps(weights, model), pairs["cpp_int8_vs_ort_int8"])
        models[model] = pairs
    return models, timing


def judge_fp32(pair: dict, lg: dict, model, x, head: str = "logits") -> None:
    """A missed fp32 target of C++ against ONNX Runtime judged again on the windows past it (over the
    bound or another argmax) against float32 rounding (core/contracts.py, ``pytorch.rounding_judgement``):
    a window where the model amplifies rounding parts two correct float32 programs."""
    target = pair["target"]
    if target["passed"]:
        return
    cpp, ref = lg["cpp_fp32"].astype(np.float64), lg["ort_fp32"].astype(np.float64)
    outside = (np.abs(cpp - ref).max(1) > target["bound"]) | (cpp.argmax(1) != ref.argmax(1))
    target.update(pytorch.rounding_judgement(lg["cpp_fp32"], outside, model, x, head))


def motor_pairs(lg: dict) -> dict:
    """The motor head's pairs: C++ fp32 against ORT fp32 within the class logits' fp32 bound; C++ int8
    against ORT int8 bit-identical (the same integers and the class head's rescale order)."""
    pairs = {"cpp_fp32_vs_ort_fp32": compare.pair_metrics(lg["cpp_fp32"], lg["ort_fp32"]),
             "cpp_fp32_vs_torch": compare.pair_metrics(lg["cpp_fp32"], lg["torch"]),
             "cpp_int8_vs_ort_int8": compare.pair_metrics(lg["cpp_int8"], lg["ort_int8"]),
             "cpp_int8_vs_cpp_fp32": compare.pair_metrics(lg["cpp_int8"], lg["cpp_fp32"])}
    pairs["cpp_fp32_vs_ort_fp32"]["target"] = compare.fp32_target(pairs["cpp_fp32_vs_ort_fp32"])
    m = pairs["cpp_int8_vs_ort_int8"]
    m["target"] = {"bitwise": True, "rule": "every window bit-identical",
                   "passed": bool(m["bitwise_identical_windows"] == m["windows"])}
    return pairs


def parity_run(run: RunDir, cfg: Config, log: Callable[[str], None] = print, *, mcu: bool = True,
               host: bool = True, build_dir: Path | None = None, command: str | None = None) -> dict:
    """The stage (see the module docstring); returns the parity.json dict.

    ``host``: C++ / ONNX Runtime / PyTorch on the test split and fwref_parity on reference.bin.
    ``mcu``: the Cortex-M part (cross-build, QEMU); skipped with a note in the report when the cross
    toolchain or QEMU is missing and ``host`` is true, an error when only the Cortex-M part was asked for.
    """
    sections = cfg.to_dict()  # the run's export fixed everything else parity needs (N, scales, files)
    with stage(run.root, "parity", {"sim": sections["sim"]}, targets=("parity/parity.json", "parity/parity.md")) as st:
        _consume_inputs(run, st)
        out_dir = ensure_dir(st.out / "parity")
        if not host:
            st.carry_previous()
            report, problem = _mcu_only(parity_dir(run), out_dir, run.export / "weights.bin",
                                        run.export / "reference.bin", log, lambda: stream_inputs(run.root, build_dir))
        else:
            report = _parity_host(run, out_dir, log, mcu, build_dir, command)
            problem = ("parity target missed: " + "; ".join(report["problems"])
                       + f" (report: {parity_dir(run) / 'parity.md'})") if report["problems"] else None
    if problem:  # the report is published first: it is the evidence of what was missed
        raise QuadfdiError(problem)
    return report


def _consume_inputs(run: RunDir, st) -> None:
    """Every file of the published export (manifest, graphs, weights.bin, reference.bin), the
    dataset and the checkpoints, each checked against its stage record (also for --mcu, so that
    its record has the inputs of the host report it carries forward)."""
    from quadfdi.core.records import load_record

    st.consume("export/manifest.json")
    for entry in (load_record(run.root, "export") or {}).get("outputs", []):
        st.consume(entry["path"])
    for rel in ("dataset.npz", "cnode.pt", "gru.pt"):
        st.consume(rel, ("sim",))


def _parity_host(run: RunDir, out_dir: Path, log: Callable[[str], None], mcu: bool, build_dir: Path | None,
                 command: str | None) -> dict:
    t_start = time.perf_counter()
    export = Export.open(run.export)
    weights, reference = export.weights_path, run.export / "reference.bin"
    command = command or "quadfdi parity --run " + shlex.quote(str(run.root))

    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    build_dir = build_host(build_dir, log=log)  # default: the per-user build cache (runtimes.build)
    timing["build"] = time.perf_counter() - t0
    fp = fwref_parity(build_dir, weights, reference)
    log(f"parity: fwref_parity on reference.bin: {'OK' if fp['passed'] else 'NOT OK'} (exit {fp['exit_code']})")
    models, t_host = host_parity(run, export, build_dir, log, out_dir)
    timing.update(t_host)
    mcu_report = _mcu_part(mcu, weights, reference, out_dir, timing, log, lambda: stream_inputs(run.root, build_dir))
    timing["total"] = time.perf_counter() - t_start

    problems = []
    if not fp["passed"]:
        problems.append(f"fwref_parity on reference.bin exited {fp['exit_code']}")
    for model, pairs in models.items():
        for key in ("cpp_fp32_vs_ort_fp32", "cpp_int8_vs_ort_int8"):
            if key not in pairs:
                continue
            t, m = pairs[key]["target"], pairs[key]
            if not t["passed"]:
                detail = (f"{t['max_diff_steps']:.3g} logit steps" if "max_diff_steps" in t
                          else f"{m['windows'] - m['bitwise_identical_windows']} windows not bit-identical"
                          if "bitwise" in t
                          else f"max |diff| {m['max_abs_diff']:.3g} (bound {t['bound']:.3g})"
                          + over_bound_clause(t))
                problems.append(f"{model} {key}: {detail}, argmax {100 * m['argmax_agreement']:.2f} %")
    problems += mcu_report.get("problems", [])
    report = {
        "schema_version": SCHEMA_VERSION, "producer": "quadfdi parity", "command": command, "run": str(run.root),
        "test_windows": int(models["cnode"]["cpp_fp32_vs_ort_fp32"]["windows"]),
        "export_steps": export.steps,
        "firmware": {"build_dir": str(build_dir), "infer": str(build_dir / "fwref_infer"),
                     "build": f"cmake -S {source_dir()} -B {build_dir} -DCMAKE_BUILD_TYPE=Release && "
                              f"cmake --build {build_dir} -j2"},
        "tolerances": {"fp32_rel_tol": compare.FP32_REL_TOL, "int8_argmax_min": compare.INT8_ARGMAX_MIN,
                       "int8_tol_steps": compare.INT8_TOL_STEPS},
        "fwref_parity": fp, "models": models, "mcu": _mcu_summary(mcu_report),
        "problems": problems, "passed": not problems, "timing_s": timing,
    }
    _write_json(out_dir / "parity.json", report)
    write_text(out_dir / "parity.md", markdown({**report, "mcu": mcu_report}))
    log(f"parity: wrote parity.json, parity.md" + (", mcu.json" if "cpus" in mcu_report else "")
        + f" in {timing['total']:.1f} s")
    return report


def _mcu_part(mcu: bool, weights: Path, reference: Path, out_dir: Path, timing: dict,
              log: Callable[[str], None], stream: Callable[[], object]) -> dict:
    if not mcu:
        return {"skipped": "not requested (--no-mcu)"}
    missing = tools_missing()
    if missing:
        log(f"parity: Cortex-M part skipped: {missing}")
        return {"skipped": missing}
    t0 = time.perf_counter()
    report = mcu_mod.mcu_run(weights, reference, log=log, stream=stream())
    timing["mcu"] = report["timing_s"] = time.perf_counter() - t0
    _write_mcu(out_dir, report)
    return report


def _write_mcu(out_dir: Path, report: dict) -> None:
    """mcu.json, and the streaming cost table (parity/stream.py) as mcu_stream.json."""
    _write_json(out_dir / "mcu.json", {k: v for k, v in report.items() if k != "stream"})
    _write_json(out_dir / "mcu_stream.json", report["stream"])


def _mcu_only(old_dir: Path, out_dir: Path, weights: Path, reference: Path,
              log: Callable[[str], None], stream: Callable[[], object]) -> tuple[dict, str | None]:
    """``quadfdi parity --mcu``: mcu.json, and parity.json/parity.md updated when a host report exists
    (read from the published ``old_dir``, written to the staging ``out_dir``); (report, problem)."""
    missing = tools_missing()
    if missing:
        raise QuadfdiError(f"cannot run the Cortex-M part: {missing}")
    t0 = time.perf_counter()
    mcu_report = mcu_mod.mcu_run(weights, reference, log=log, stream=stream())
    mcu_report["timing_s"] = time.perf_counter() - t0
    _write_mcu(out_dir, mcu_report)
    report_path = old_dir / "parity.json"
    if report_path.is_file():
        report = json.loads(report_path.read_text())
        if report.get("schema_version") == SCHEMA_VERSION:
            report["mcu"] = _mcu_summary(mcu_report)
            report["problems"] = [p for p in report.get("problems", []) if not p.startswith("cortex-")]
            report["problems"] += mcu_report["problems"]
            report["passed"] = not report["problems"]
            _write_json(out_dir / "parity.json", report)
            write_text(out_dir / "parity.md", markdown({**report, "mcu": mcu_report}))
    log(f"parity: wrote {old_dir / 'mcu.json'} in {mcu_report['timing_s']:.1f} s")
    problem = "Cortex-M target missed: " + "; ".join(mcu_report["problems"]) if mcu_report["problems"] else None
    return {"mcu": mcu_report}, problem


def _mcu_summary(mcu_report: dict) -> dict:
    """The Cortex-M numbers for parity.json (mcu.json holds everything, with the harness output)."""
    if "cpus" not in mcu_report:
        return mcu_report
    stream = mcu_report.get("stream", {})
    return {"passed": mcu_report["passed"], "problems": mcu_report["problems"], "file": "mcu.json",
            "stream": {"skipped": stream["skipped"]} if "skipped" in stream else
            {"file": "mcu_stream.json", "passed": stream.get("passed"), "problems": stream.get("problems", [])},
            "cpus": {cpu: {"machine": r["machine"], "passed": r["passed"],
                           "models": {k: {f: v[f] for f in ("flash_bytes", "weights_bytes", "static_ram_bytes",
                                                            "stack_peak_bytes", "instructions_per_inference")}
                                      for k, v in r["models"].items()}}
                     for cpu, r in mcu_report["cpus"].items()}}
