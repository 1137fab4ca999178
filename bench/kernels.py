"""Instructions per kernel of the C++ reference: callgrind on fwref_infer, 8 windows minus 4 windows.

    quadfdi bench kernels --run runs/<name> [--fwref PATH] [--json FILE]

For each model (CNODE, GRU) and precision (fp32, int8), fwref_infer runs under
``valgrind --tool=callgrind --toggle-collect`` on fwref_infer's per-window call (only the inference
calls are counted, not loading weights.bin; ``bench.profile.CALLGRIND_TOGGLE``) once on the first
8 test windows and once on the first 4; the difference divided by 4 is the cost of one window in steady state (the first window's one-off work, e.g. lazy
buffers, cancels out). Self instructions (Ir) are grouped per function ("kernel": an int8 gemv, the
inference function with what the compiler inlined into it, Eigen's products, ...). Per MAC divides by
the multiply-accumulates the C++ executes (``executed_macs``: the CNODE's control path is two weights
per row, not the dense (S, W) product the manifest counts). Instruction counts do not depend on the
machine's load; they depend on the build (``fwref_kernels --info`` names the int8 kernel that ran).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from quadfdi.bench.profile import CALLGRIND_TOGGLE, parse_callgrind_annotate
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.tables import md_table

WINDOWS_LONG, WINDOWS_SHORT = 8, 4
# What to do when valgrind cannot decode the build's instructions: on an AVX-512 CPU the host build's
# -march=native emits AVX-512, which valgrind does not implement (it hides AVX-512 from cpuid, so the
# run-time kernel choice falls back to AVX2 by itself; only the compiled-in ISA is the problem).
VALGRIND_ISA_HINT = ("valgrind cannot decode an instruction of this build (AVX-512 from -march=native on an "
                     "AVX-512 CPU?); count an AVX2 build instead: cmake -S firmware_ref -B B -DFWREF_NATIVE=OFF "
                     "'-DCMAKE_CXX_FLAGS=-march=x86-64-v3 -fno-trapping-math' && cmake --build B, then --fwref B/fwref_infer")
PAIRS = (("cnode", "fp32"), ("cnode", "int8"), ("gru", "fp32"), ("gru", "int8"))


def executed_macs(model: dict, steps: int) -> dict[str, int]:
    """Multiply-accumulates per window that the C++ reference executes, in total and in the int8
    gemv products (``gemv``: every weight product; the CNODE's interpolation is 2 weights a row)."""
    C, K = int(model["n_channels"]), int(model["n_classes"])
    if model["kind"] == "cnode":
        L, H, S = int(model["latent"]), int(model["hidden"]), 2 * steps + 1
        gemv = L * C + S * H * C + 4 * steps * 2 * L * H + K * L
        return {"total": gemv + 2 * S * C, "gemv": gemv}
    H, W = int(model["hidden"]), int(model["window"])
    gemv = W * 3 * H * (C + H) + K * H
    return {"total": gemv, "gemv": gemv}


def kernel_name(function: str) -> str:
    """A callgrind function name without its file, argument lists and template arguments:
    '???:fwref::(anonymous namespace)::gemv_i8_avx2(signed char const*, ...) [/x/fwref_infer]'
    -> 'gemv_i8_avx2'; lambdas keep the name of the function they live in, plus '{lambda}'; a GCC
    clone keeps its suffix: 'fwref::infer(fwref::CnodeF32 const&, ...) [clone .part.0] [/x]' ->
    'infer [clone .part.0]' (a part of infer that GCC split off, counted apart from infer itself)."""
    clones = re.findall(r"\[clone ([^\]]*)\]", function)
    f = re.sub(r"\s*\[clone [^\]]*\]", "", function)
    f = re.sub(r"\s*\[[^\]]*\]\s*$", "", f)
    f = f.split(":", 1)[1] if f.startswith(("???:", "./")) and ":" in f else f
    f = f.replace("(anonymous namespace)", "anon")
    lam = "{lambda" in f
    depth, out = 0, []
    for ch in f:  # drop every (...) and <...> group
        if ch in "(<":
            depth += 1
        elif ch in ")>":
            depth = max(0, depth - 1)
        elif depth == 0:
            out.append(ch)
    name = "".join(out).split("::{lambda")[0].strip().split(" ")[-1]  # no return type ("void gru_cell")
    parts = [p for p in name.split("::") if p]
    keep = 2 if len(parts) >= 2 and parts[-2][:1].isupper() else 1  # a class's method keeps its class
    name = "::".join(parts[-keep:])
    return (name or f[:60]) + (" {lambda}" if lam else "") + "".join(f" [clone {c}]" for c in clones)


def _callgrind(fwref: str, weights: str, model: str, int8: bool, windows: Path, tmp: Path) -> tuple[int, dict]:
    out = tmp / f"cg_{model}_{int8}_{windows.stem}.out"
    cmd = ["valgrind", "--tool=callgrind", f"--toggle-collect={CALLGRIND_TOGGLE}", f"--callgrind-out-file={out}",
           fwref, "--weights", weights, "--model", model, "--in", str(windows), "--out", str(tmp / "o.f32")]
    res = subprocess.run(cmd + (["--int8"] if int8 else []), capture_output=True, text=True, timeout=900)
    if res.returncode != 0 or not out.is_file():
        what = f"callgrind of {fwref} --model {model}{' --int8' if int8 else ''} failed: "
        if "unhandled instruction" in res.stderr:  # e.g. AVX-512, which valgrind 3.19 (this machine) cannot decode
            raise QuadfdiError(what + VALGRIND_ISA_HINT)
        raise QuadfdiError(what + (res.stderr.strip().splitlines() or ["no output"])[-1])
    ann = subprocess.run(["callgrind_annotate", "--threshold=100", str(out)], capture_output=True, text=True,
                         timeout=300, check=True)
    total, rows = parse_callgrind_annotate(ann.stdout)
    per: dict[str, int] = {}
    for r in rows:
        k = kernel_name(r["function"])
        per[k] = per.get(k, 0) + r["ir"]
    return total, per


def kernel_counts(fwref: str, weights: str, windows: np.ndarray, manifest: dict) -> list[dict]:
    """One record per (model, precision): ``{model, precision, ir_per_window, macs, ir_per_mac,
    kernels: [{kernel, ir_per_window, ir_per_mac}]}``; ``windows`` (n >= 8, W, C) raw float32.
    A kernel's per-MAC figure is against the gemv MACs for gemv kernels, else against all MACs."""
    for tool in ("valgrind", "callgrind_annotate"):
        if shutil.which(tool) is None:
            raise QuadfdiError(f"quadfdi bench kernels needs {tool} (apt-get install valgrind)")
    if len(windows) < WINDOWS_LONG:
        raise QuadfdiError(f"quadfdi bench kernels needs {WINDOWS_LONG} test windows, the run has {len(windows)}")
    steps = int(manifest["solver"]["steps"])
    out = []
    with tempfile.TemporaryDirectory(prefix="quadfdi-kernels-") as tmp:
        tmpd = Path(tmp)
        files = {}
        for n in (WINDOWS_LONG, WINDOWS_SHORT):
            files[n] = tmpd / f"w{n}.f32"
            np.ascontiguousarray(windows[:n], dtype="<f4").tofile(files[n])
        for model, precision in PAIRS:
            runs = {n: _callgrind(fwref, weights, model, precision == "int8", files[n], tmpd) for n in files}
            (t8, k8), (t4, k4) = runs[WINDOWS_LONG], runs[WINDOWS_SHORT]
            span = WINDOWS_LONG - WINDOWS_SHORT
            macs = executed_macs(manifest["models"][model], steps)
            kernels = []
            for k in sorted(k8, key=lambda k: -(k8[k] - k4.get(k, 0))):
                ir = (k8[k] - k4.get(k, 0)) / span
                if ir <= 0:
                    continue
                denom = macs["gemv"] if k.startswith(("gemv_i8", "gemv_w16")) else macs["total"]
                kernels.append({"kernel": k, "ir_per_window": ir, "ir_per_mac": ir / denom})
            ir = (t8 - t4) / span
            out.append({"model": model, "precision": precision, "ir_per_window": ir, "macs": macs,
                        "ir_per_mac": ir / macs["total"], "kernels": kernels})
    return out


def kernels_table(records: list[dict]) -> list[str]:
    """Markdown: one row per model, precision and kernel (share >= 0.5 % of the window), then totals."""
    rows = []
    for r in records:
        for k in r["kernels"]:
            if k["ir_per_window"] >= 0.005 * r["ir_per_window"]:
                rows.append([r["model"], r["precision"], f"`{k['kernel']}`", f"{k['ir_per_window']:,.0f}",
                             f"{k['ir_per_mac']:.2f}"])
        rows.append([r["model"], r["precision"], f"**total** ({r['macs']['total']:,} MACs)",
                     f"**{r['ir_per_window']:,.0f}**", f"**{r['ir_per_mac']:.2f}**"])
    return md_table(["model", "precision", "kernel", "instructions / window", "per MAC"], rows)
