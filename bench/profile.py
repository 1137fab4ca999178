"""Profiles that explain a missed latency target (a profile, not a guess).

This machine's virtual CPUs expose no hardware performance counters (``perf stat`` reports
cycles and instructions as "not supported"), so the profiles are:

- C++ reference: valgrind's callgrind, collecting only inside fwref_infer's per-window call (``CALLGRIND_TOGGLE``) (the inference
  calls, not the weights loading): instructions (Ir) per window, per MAC, and by function;
  divided into the measured batch-1 p50 it gives the instructions retired per nanosecond. Plus
  what the compiler was allowed to use (the build's flags from CMakeCache.txt / flags.make) and
  how many of the float instructions in the binary's inference code are packed (SIMD) rather
  than scalar (``objdump``).
- ONNX Runtime: its own per-node profiler (``SessionOptions.enable_profiling``), summarised per
  operator type, against the whole-call time: the difference is the framework's cost between
  kernels (``bench.timing.ort.summarise_ort_profile``).

Each function returns a plain dict (or None with a reason when the tool is missing).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from quadfdi.bench.limits import run_json, worker_env

CALLGRIND_LINE = re.compile(r"^\s*([\d,]+)\s+\(\s*[\d.]+%\)\s+(.*)$")


def _short(function: str) -> str:
    """'???:fwref::infer(fwref::GruF32 const&, ...) [/path/bin]' -> 'fwref::infer(GruF32 ...)' (<= 90 chars)."""
    f = re.sub(r"\s*\[[^\]]*\]\s*$", "", function)
    f = f.split(":", 1)[1] if f.startswith(("???:", "./")) and ":" in f else f
    f = f.replace("fwref::", "").replace("Eigen::", "").replace("std::", "")
    f = re.sub(r"Matrix<float, -1, 1, 0, (\d+), 1>", r"Vec<\1>", f)
    return f if len(f) <= 90 else f[:87] + "..."


def parse_callgrind_annotate(text: str) -> tuple[int, list[dict]]:
    """(total Ir, [{function, ir}]) from ``callgrind_annotate`` output (self cost per function)."""
    total, rows = 0, []
    for line in text.splitlines():
        m = CALLGRIND_LINE.match(line)
        if not m:
            continue
        ir = int(m.group(1).replace(",", ""))
        name = m.group(2).strip()
        if name.startswith("PROGRAM TOTALS"):
            total = ir
        else:
            rows.append({"function": name, "ir": ir})
    return total, rows


# Collect inside fwref_infer's per-window call (tools/host_common.hpp BoundModel::run), not inside
# fwref::infer: GCC splits infer into a checking wrapper that tail-jumps to "infer [clone .part.0]",
# and callgrind stops collecting at that jump (it then counted 5 instructions a window).
CALLGRIND_TOGGLE = "fwref::host::BoundModel*::run*"


def callgrind_cpp(fwref: str, weights: str, windows_f32: str, n_windows: int, model: str, int8: bool) -> dict | None:
    """Instructions per window of fwref_infer's inference calls, and the top functions by self Ir."""
    valgrind, annotate = shutil.which("valgrind"), shutil.which("callgrind_annotate")
    if not valgrind or not annotate:
        return None
    with tempfile.TemporaryDirectory(prefix="quadfdi-callgrind-") as tmp:
        out = Path(tmp) / "callgrind.out"
        cmd = [valgrind, "--tool=callgrind", f"--toggle-collect={CALLGRIND_TOGGLE}", f"--callgrind-out-file={out}",
               fwref, "--weights", weights, "--model", model, "--in", windows_f32, "--out", str(Path(tmp) / "o.f32")]
        if int8:
            cmd.append("--int8")
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        if res.returncode != 0 or not out.is_file():
            return {"error": (res.stderr.strip().splitlines() or ["valgrind failed"])[-1]}
        ann = subprocess.run([annotate, "--threshold=100", str(out)], capture_output=True, text=True, timeout=120)
    total, rows = parse_callgrind_annotate(ann.stdout)
    top = [{"function": _short(r["function"]), "ir_per_window": r["ir"] / n_windows,
            "share": r["ir"] / total if total else None} for r in rows[:6] if r["ir"] > 0.005 * max(total, 1)]
    return {"tool": f"valgrind --tool=callgrind --toggle-collect={CALLGRIND_TOGGLE}", "windows": n_windows,
            "ir_per_window": total / n_windows, "top": top}


def build_flags(fwref: str) -> dict:
    """The C++ build's type and compile flags (CMakeCache.txt and the model library's flags.make)."""
    build = Path(fwref).resolve().parent
    out: dict = {"build_dir": str(build)}
    cache = build / "CMakeCache.txt"
    if cache.is_file():
        for line in cache.read_text(errors="replace").splitlines():
            for key in ("CMAKE_BUILD_TYPE", "CMAKE_CXX_FLAGS", "CMAKE_CXX_FLAGS_RELEASE", "CMAKE_CXX_COMPILER"):
                if line.startswith(key + ":"):
                    out[key] = line.split("=", 1)[1]
    flags = next(iter(sorted(build.glob("CMakeFiles/fwref_models.dir/flags.make"))), None)
    if flags is not None:
        for line in flags.read_text(errors="replace").splitlines():
            if line.startswith("CXX_FLAGS"):
                out["CXX_FLAGS"] = line.split("=", 1)[1].strip()
    text = " ".join(str(v) for k, v in out.items() if "FLAGS" in k)
    isa = sorted(set(re.findall(r"-march=\S+|-mtune=\S+|-m(?:avx\S*|fma|sse\S*|f16c|bmi\S*)\b", text)))
    out["march"] = (", ".join(isa) if isa
                    else "no -march or -m<isa> flag (the compiler's default target: x86-64 baseline, SSE2)")
    return out


def simd_share(fwref: str) -> dict | None:
    """Packed vs scalar single-precision float instructions in the binary's fwref/Eigen functions."""
    objdump = shutil.which("objdump")
    if not objdump:
        return None
    res = subprocess.run([objdump, "-d", "-C", "--no-show-raw-insn", fwref], capture_output=True, text=True,
                         timeout=120)
    if res.returncode != 0:
        return None
    packed = scalar = 0
    widths = {"xmm": 0, "ymm": 0, "zmm": 0}
    inside = False
    for line in res.stdout.splitlines():
        if line.endswith(">:"):
            inside = "fwref::" in line or "Eigen::" in line
            continue
        if not inside or "\t" not in line:
            continue
        ins = line.split("\t", 1)[1].strip()
        mnemonic = ins.split(" ", 1)[0]
        if re.match(r"^v?(add|sub|mul|div|fmadd\w*|fnmadd\w*|fmsub\w*|max|min)ps$", mnemonic):
            packed += 1
            for w in widths:
                if w in ins:
                    widths[w] += 1
                    break
        elif re.match(r"^v?(add|sub|mul|div|fmadd\w*|fnmadd\w*|fmsub\w*|max|min)ss$", mnemonic):
            scalar += 1
    total = packed + scalar
    return {"packed": packed, "scalar": scalar, "packed_share": packed / total if total else None,
            "packed_by_width": widths, "note": "static count over the inference code (fwref::, Eigen:: functions)"}


def ort_profile(artifact: str, windows_npy: str, model: str, precision: str, solver: str, cpus_prefix: list[str],
                n: int, out_json: Path) -> dict:
    """Per-op-type ONNX Runtime profile of batch-1 calls, one thread, in a fresh pinned process."""
    import json

    cmd = [*cpus_prefix, sys.executable, "-m", "quadfdi.bench.latency_worker", "--runtime", "ort", "--model", model,
           "--precision", precision, "--solver", solver, "--threads", "1", "--spinning", "off",
           "--windows", windows_npy, "--artifact", artifact, "--n", str(n), "--profile", str(out_json)]
    run_json(cmd, worker_env(1), f"ORT profile of {model} {precision}", 600)
    return json.loads(out_json.read_text())
