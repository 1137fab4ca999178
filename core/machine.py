"""The machine a measurement came from: CPU model, vector instruction sets, cores, date.

Every benchmark and every measured figure in the README records this, because the numbers move
with the CPU: on an AMD EPYC with AVX2 only, ONNX Runtime's int8 peak is half of what an Intel with
AVX-512 VNNI measures, and the GRU's test F1 came out 2 points lower (different float kernels
give different training trajectories). Detected at run time from /proc/cpuinfo; nothing's
correctness depends on it.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
from pathlib import Path

# The extensions that decide which kernels run (ONNX Runtime's, Eigen's, ours).
ISA_FLAGS = ("sse4_2", "avx", "avx2", "fma", "f16c", "avx512f", "avx512bw", "avx512vl", "avx512_vnni",
             "avx_vnni", "amx_int8")


def cpu_facts(cpuinfo: str | None = None) -> dict:
    """CPU model, the ISA extensions of ``ISA_FLAGS`` it has, logical CPUs, machine and kernel."""
    text = cpuinfo
    if text is None:
        try:
            text = Path("/proc/cpuinfo").read_text()
        except OSError:
            text = ""
    model, flags = "", set()
    for line in text.splitlines():
        key, _, value = line.partition(":")
        key = key.strip()
        if key == "model name" and not model:
            model = value.strip()
        elif key == "flags" and not flags:
            flags = set(value.split())
    return {"cpu": model or platform.processor() or "unknown",
            "isa": [f for f in ISA_FLAGS if f in flags],
            "logical_cpus": os.cpu_count(),
            "arch": platform.machine(),
            "kernel": platform.release()}


def isa_summary(facts: dict) -> str:
    """'AVX2 + FMA' or 'AVX-512 + VNNI' style short label of the vector ISA."""
    isa = set(facts.get("isa", ()))
    if "avx512f" in isa:
        label = "AVX-512" + (" + VNNI" if "avx512_vnni" in isa else " (no VNNI)")
    elif "avx2" in isa:
        label = "AVX2" + (" + FMA" if "fma" in isa else "") + (" + AVX-VNNI" if "avx_vnni" in isa else "")
    else:
        label = "no AVX2"
    return label


def machine_line(facts: dict | None = None, when: _dt.date | None = None) -> str:
    """One line naming the machine, for the head of a results table."""
    f = facts or cpu_facts()
    day = (when or _dt.date.today()).isoformat()
    return f"{f['cpu']} ({isa_summary(f)}; {f['logical_cpus']} logical CPUs), {day}"
