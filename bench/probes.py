"""Compiled machine probes: the vector-ISA bandwidth/FMA program (bench/cpp/l2bw.cpp), checked to be
vectorised on this host before it is trusted, and the cache sizes it is run at.

A floor is only as good as its probe: an AVX-512 build whose 64-byte vectors spill to the stack on an
AVX2-only CPU measured 15.6 GB/s whatever the buffer size, and put a "floor" above what two runtimes
took. So the probe is built for the host's widest vector width, its hot loops are read back with
objdump (full-width registers, no stack traffic), and several sizes and trials are run, best of.
"""

from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path
from typing import Callable

from quadfdi.core.errors import QuadfdiError

L2_PROBE_KIB_DEFAULT = 512
L2BW_SOURCE = Path(__file__).resolve().parent / "cpp" / "l2bw.cpp"


def time_call(fn: Callable[[], object], min_s: float, trials: int) -> float:
    """Best per-call seconds of ``fn`` over ``trials`` trials of at least ``min_s`` each."""
    fn()
    best = float("inf")
    for _ in range(trials):
        reps, t0 = 0, time.perf_counter()
        while True:
            fn()
            reps += 1
            elapsed = time.perf_counter() - t0
            if elapsed >= min_s:
                break
        best = min(best, elapsed / reps)
    return best


def cache_sizes() -> dict[str, int]:
    """Per-core data cache sizes in bytes from sysfs: {'L1d': ..., 'L2': ..., 'L3': ...} (missing: absent)."""
    out: dict[str, int] = {}
    base = Path("/sys/devices/system/cpu/cpu0/cache")
    for idx in sorted(base.glob("index*")) if base.is_dir() else []:
        try:
            level = (idx / "level").read_text().strip()
            kind = (idx / "type").read_text().strip()
            size = (idx / "size").read_text().strip()
        except OSError:
            continue
        if kind == "Instruction":
            continue
        mult = {"K": 1024, "M": 1024 ** 2, "G": 1024 ** 3}.get(size[-1], 1)
        value = int(size[:-1] if size[-1] in "KMG" else size) * mult
        out["L1d" if level == "1" else f"L{level}"] = value
    return out


def l2_probe_kib(caches: dict[str, int]) -> int:
    """A buffer size that fits L2 with room to spare but is at least 4 times L1d."""
    l1, l2 = caches.get("L1d", 32 * 1024), caches.get("L2", 1024 * 1024)
    kib = max(4 * l1, l2 // 2) // 1024
    return int(kib) if kib * 1024 < l2 else L2_PROBE_KIB_DEFAULT


def host_vector_bytes() -> int:
    """Width of the host's widest float vector registers: 64 (AVX-512F), 32 (AVX2 + FMA) or 16."""
    try:
        flags = next((ln.split(":", 1)[1].split() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                      if ln.startswith("flags")), [])
    except OSError:
        flags = []
    if "avx512f" in flags:
        return 64
    return 32 if {"avx2", "fma"} <= set(flags) else 16


VECTOR_REG = {16: "xmm", 32: "ymm", 64: "zmm"}


def build_l2bw(workdir: Path, vec_bytes: int | None = None) -> Path | None:
    """Compile bench/cpp/l2bw.cpp into ``workdir`` for vectors of ``vec_bytes`` (the host's
    widest by default); None when no g++ is available or it fails."""
    cxx = shutil.which("g++") or shutil.which("c++")
    if cxx is None:
        return None
    vec = vec_bytes or host_vector_bytes()
    exe = workdir / f"l2bw_v{vec}"
    res = subprocess.run([cxx, "-O2", "-march=native", f"-DVEC_BYTES={vec}", "-o", str(exe), str(L2BW_SOURCE)],
                         capture_output=True, text=True)
    return exe if res.returncode == 0 else None


def hot_loop(disassembly: str, symbol: str) -> list[str]:
    """The instructions of ``symbol``'s hottest loop in ``objdump -d`` text: among the backward
    branches inside the function, the loop [target, branch] with the most vector instructions."""
    lines, inside = [], False
    for ln in disassembly.splitlines():
        if ln.endswith(f"<{symbol}>:"):
            inside = True
            continue
        if inside:
            if not ln.strip():
                break
            addr, _, text = ln.partition(":")
            try:
                lines.append((int(addr.strip(), 16), text.strip()))
            except ValueError:
                continue
    best: list[str] = []
    for i, (addr, text) in enumerate(lines):
        parts = text.split()
        if not parts or not parts[0].startswith("j") or parts[0] == "jmp" or len(parts) < 2:  # loops: conditional
            continue
        try:
            target = int(parts[1], 16)
        except ValueError:
            continue
        if target <= addr:
            body = [t for a, t in lines if target <= a <= addr]
            if sum(t.startswith("v") for t in body) > sum(t.startswith("v") for t in best):
                best = body
    return best


def check_vectorised(exe: Path, vec_bytes: int) -> dict:
    """objdump the probe's two kernels: each hot loop must use ``vec_bytes`` vector registers
    (xmm/ymm/zmm) and touch no stack slot (no spill). {"checked", "ok", per kernel details}."""
    objdump = shutil.which("objdump")
    if objdump is None:
        return {"checked": False, "ok": None, "why": "objdump not found"}
    res = subprocess.run([objdump, "-d", "--no-show-raw-insn", str(exe)], capture_output=True, text=True)
    reg = VECTOR_REG[vec_bytes]
    out: dict = {"checked": True, "register": reg, "vec_bytes": vec_bytes}
    ok = True
    for symbol in ("l2bw_read_pass", "l2bw_fma_kernel"):
        loop = hot_loop(res.stdout, symbol)
        vec_ops = [t for t in loop if t.startswith("v") and f"%{reg}" in t]
        stack = [t for t in loop if "(%rsp" in t or "(%rbp" in t]
        good = bool(loop) and len(vec_ops) >= 8 and not stack
        out[symbol] = {"loop_instructions": len(loop), "vector_ops": len(vec_ops), "stack_accesses": len(stack),
                       "ok": good}
        ok = ok and good
    out["ok"] = ok
    return out


def build_checked_probe(workdir: Path) -> tuple[Path | None, dict]:
    """The widest probe variant whose hot loops pass ``check_vectorised`` (host width first, then
    narrower); (None, reason) without a compiler. An unchecked build (no objdump) is used as is."""
    tried = []
    for vec in [v for v in (64, 32, 16) if v <= host_vector_bytes()]:
        exe = build_l2bw(workdir, vec)
        if exe is None:
            return None, {"checked": False, "ok": None, "why": "no C++ compiler or the build failed"}
        check = check_vectorised(exe, vec)
        tried.append(check)
        if check["ok"] or not check["checked"]:
            return exe, {**check, "tried": tried[:-1]}
    return exe, {**tried[-1], "tried": tried[:-1]}


def fma_peak(exe: Path, cpu_prefix: list[str], trials: int, min_s: float) -> float:
    """Best GFLOP/s of the probe's FMA kernel (10 independent vector FMA chains), one core."""
    res = subprocess.run([*cpu_prefix, str(exe), "--fma", str(trials), str(min_s)], capture_output=True, text=True,
                         timeout=120)
    if res.returncode != 0:
        raise QuadfdiError(f"FMA probe {exe} failed: {res.stderr.strip() or res.returncode}")
    return max(float(f) / float(s) / 1e9 for f, s in (ln.split() for ln in res.stdout.splitlines() if ln.strip()))


def bandwidth(exe: Path, kib: int, cpu_prefix: list[str], trials: int, min_s: float) -> float:
    """Best GB/s of the l2bw probe reading a ``kib`` KiB buffer."""
    res = subprocess.run([*cpu_prefix, str(exe), str(kib), str(trials), str(min_s)], capture_output=True,
                         text=True, timeout=120)
    if res.returncode != 0:
        raise QuadfdiError(f"bandwidth probe {exe} failed: {res.stderr.strip() or res.returncode}")
    rates = [float(b) / float(s) / 1e9 for b, s in (line.split() for line in res.stdout.split("\n") if line.strip())]
    return max(rates)


def probe_sizes_kib(caches: dict[str, int]) -> dict[str, list[int]]:
    """Buffer sizes per level: L1 at 1/4 and 1/2 of L1d; L2 at 1/4 and 1/2 of L2 (at least 4x L1d)."""
    l1, l2 = caches.get("L1d", 32 * 1024), caches.get("L2", 1024 * 1024)
    l2_sizes = sorted({max(4 * l1, l2 // 4) // 1024, l2_probe_kib(caches)})
    return {"L1": [max(4, l1 // 4096), max(4, l1 // 2048)], "L2": l2_sizes}


L1_OVER_L2_MIN = 1.5  # sanity: an L1-resident read must be at least this much faster than an L2 one


def numpy_bandwidth(kib: int) -> float:
    """Fallback probe: best GB/s of numpy dot over two buffers of kib/2 each (call overhead included)."""
    import numpy as np

    n = kib * 1024 // 8
    a, b = np.ones(n, dtype=np.float32), np.ones(n, dtype=np.float32)
    s = time_call(lambda: np.dot(a, b), 0.05, 5)
    return 2 * n * 4 / s / 1e9


# ----------------------------------------------------------------------------- orchestration
