"""The streaming CNODE's step on the Cortex-M (firmware_ref/mcu/scnode): build the images with an export's
scnode_fw.bin and scnode_fw_i8.bin compiled in, run them under QEMU, and read what they print and what
QEMU's block trace says each step costs in Cortex-M4 cycles (runtimes/mcu_cycles.py's table).

- ``build_scnode(cpu, files)``: the CMake project firmware_ref/mcu/scnode in ``<fwref cache>/build-scnode-<m4|m7>``
  (the generator runs with this interpreter: ``-m quadfdi.runtimes.mcu_scnode_src``);
- ``run_steps(cpu, elf)``: fwref_mcu_scnode.elf's ``STEP`` lines, per precision the logits of every sample
  (float32, from their printed bits) and the instructions of every step (SysTick under ``-icount``);
- ``trace_steps(cpu, elf)``: fwref_mcu_scnode_trace.elf (its first ``TRACE_STEPS`` samples) under QEMU's block
  trace, cut at every entry of ``board::ticks()``: the image reads the counter just before and just after
  each step, so each step is one segment; per precision the trace's instructions and estimated cycles per
  step, and the worst step's cycles by instruction class.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.runtimes import mcu_cycles
from quadfdi.runtimes.build import MCU_CPUS, configure_and_build, fwref_home, locked, require, source_dir
from quadfdi.runtimes.mcu import QEMU_TIMEOUT_S, qemu_command
from quadfdi.runtimes.mcu_stream import TICKS, TRACE_FLAGS, FollowLog, symbol_address
from quadfdi.runtimes.mcu_trace import Trace

ELF, TRACE_ELF = "fwref_mcu_scnode.elf", "fwref_mcu_scnode_trace.elf"
TRACE_STEPS = 64
PRECISIONS = ("fp32", "int8")


@dataclass
class StepRun:
    """What one run printed: per precision the logits (T, K) and the -icount instructions (T,) of every step."""

    text: str
    ratio: float = 0.0  # instructions per SysTick tick
    calib_ticks: int = 0
    logits: dict[str, np.ndarray] = field(default_factory=dict)
    instructions: dict[str, np.ndarray] = field(default_factory=dict)


def build_scnode(cpu: str, files: list[Path], build_dir: Path | None = None) -> Path:
    """Cross-build both images for ``cpu`` with ``files`` compiled in; returns the build folder."""
    if cpu not in MCU_CPUS:
        raise QuadfdiError(f"unknown Cortex-M target {cpu!r}; valid: {', '.join(MCU_CPUS)}")
    require("arm-none-eabi-g++", "it cross-compiles the Cortex-M build")
    src = source_dir()
    build_dir = build_dir or fwref_home() / f"build-scnode-{cpu.removeprefix('cortex-')}"
    build_dir.mkdir(parents=True, exist_ok=True)
    options = {"CMAKE_TOOLCHAIN_FILE": str(src / "mcu" / "toolchain-arm-none-eabi.cmake"), "FWREF_CPU": cpu,
               "FWREF_SCNODE": ";".join(str(Path(f).resolve()) for f in files),
               "FWREF_SCNODE_TRACE_STEPS": str(TRACE_STEPS), "Python3_EXECUTABLE": sys.executable}
    with locked(build_dir):
        configure_and_build(src / "mcu" / "scnode", build_dir, options, f"the {cpu} streaming CNODE images")
    return build_dir


def parse_output(text: str) -> StepRun:
    run = StepRun(text)
    if "RESULT DONE" not in text:
        last = [ln for ln in text.splitlines() if ln.startswith("RESULT")] or ["no RESULT line"]
        raise QuadfdiError(f"the streaming CNODE image did not finish: {last[-1]}")
    rows: dict[str, list[list[str]]] = {p: [] for p in PRECISIONS}
    for line in text.splitlines():
        parts = line.split()
        if parts and parts[0] == "SCNODE":
            kv = dict(p.split("=", 1) for p in parts[1:])
            run.ratio, run.calib_ticks = int(kv["instructions_per_tick_x1000"]) / 1000.0, int(kv["calib_ticks"])
        elif parts and parts[0] == "STEP":
            rows[parts[1]].append(parts[3:])
    for prec, r in rows.items():
        if r:
            arr = np.array(r, np.uint64)
            run.instructions[prec] = arr[:, 0].astype(np.int64)
            run.logits[prec] = arr[:, 1:].astype(np.uint32).view(np.float32)
    return run


def run_steps(cpu: str, elf: Path) -> StepRun:
    """Run ``elf`` under QEMU (-icount) and parse what it printed."""
    try:
        res = subprocess.run(qemu_command(cpu, elf), capture_output=True, text=True, timeout=QEMU_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise QuadfdiError(f"QEMU ({cpu}) did not finish {elf.name} within {QEMU_TIMEOUT_S} s") from None
    if res.returncode != 0:
        raise QuadfdiError(f"QEMU ({cpu}) ran {elf.name} to exit code {res.returncode}: "
                           f"{(res.stdout.strip().splitlines() or ['no output'])[-1]}")
    return parse_output(res.stdout)


def trace_steps(cpu: str, elf: Path) -> tuple[StepRun, dict[str, dict]]:
    """Run the traced image; per precision (in the image's order) the trace's ``instructions``, ``cycles``
    and ``taken`` per step, and ``worst``: the costliest step's cycles by instruction class."""
    with tempfile.TemporaryDirectory(prefix="quadfdi-scnode-trace-") as tmp:
        stripped, out, log = Path(tmp) / "scnode.elf", Path(tmp) / "semihosting.txt", Path(tmp) / "trace.log"
        subprocess.run([require("arm-none-eabi-objcopy", "it strips the traced image"), "--strip-all", str(elf),
                        str(stripped)], check=True, capture_output=True)
        cmd = [a.replace("stdio,id=sh0", f"file,id=sh0,path={out}") for a in qemu_command(cpu, stripped)]
        proc = subprocess.Popen(cmd + ["-d", TRACE_FLAGS, "-D", str(log)], stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)
        try:
            tr = Trace.read(FollowLog(log, proc))
        finally:
            if proc.poll() is None:
                proc.kill()
            err = proc.communicate()[1]
        if proc.returncode != 0:
            raise QuadfdiError(f"QEMU ({cpu}, traced) exited {proc.returncode}: {(err.strip().splitlines() or ['?'])[-1]}")
        run = parse_output(out.read_text(errors="replace"))
    seg = tr.segments(symbol_address(elf, TICKS))
    counts = [len(run.instructions[p]) for p in PRECISIONS if p in run.instructions]
    n_steps = sum(counts)
    n = len(seg["start"])
    if n - 1 < 2 * n_steps:
        raise QuadfdiError(f"the {cpu} trace has {n - 1} ticks() calls for {n_steps} steps")
    ends = np.append(seg["start"], len(tr.codes))
    idx = n - 2 * n_steps + 2 * np.arange(n_steps)  # the segment from each step's first ticks() to its second
    out_fig, at = {}, 0
    for prec, c in zip([p for p in PRECISIONS if p in run.instructions], counts):
        sel = idx[at:at + c]
        at += c
        cyc = seg["cycles"][sel]
        w = int(sel[np.argmax(cyc)])
        classes = tr.class_cycles(int(ends[w]), int(ends[w + 1]))
        classes["branch_refills"] = int(seg["taken"][w]) * mcu_cycles.REFILL
        out_fig[prec] = {"instructions": seg["instructions"][sel], "cycles": cyc, "taken": seg["taken"][sel],
                         "worst": {"instructions": int(seg["instructions"][w]), "cycles": int(seg["cycles"][w]),
                                   "taken_branches": int(seg["taken"][w]), "class_cycles": classes}}
    return run, out_fig
