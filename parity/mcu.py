"""The Cortex-M part of parity: cross-build, QEMU runs, flash/RAM and instructions per inference.

For each core (Cortex-M4F on mps2-an386, Cortex-M7 on mps2-an500):
1. cross-build firmware_ref/mcu with the run's weights.bin and reference.bin compiled in;
2. run the parity harness under QEMU (semihosting; -icount shift=0 so that SysTick counts
   instructions) and parse its lines: every tensor against reference.bin, instructions and peak
   stack per inference; its exit code says pass or fail;
3. measure the minimal images with arm-none-eabi-size: model image minus baseline image (the same
   startup, window buffer and main without the model) = the library and its weights alone;
   the map file splits that into the weights' constant arrays and the library's code.
"""

from __future__ import annotations

import re
import shutil
import statistics
import subprocess
from pathlib import Path
from typing import Callable

from quadfdi.parity.build import MCU_CPUS, build_mcu, locked, mcu_build_dir, require
from quadfdi.core.errors import QuadfdiError

QEMU_TIMEOUT_S = 600
VARIANTS = ("cnode_f32", "cnode_i8", "gru_f32", "gru_i8")
VARIANT_KEY = {"cnode_f32": "cnode_fp32", "cnode_i8": "cnode_int8", "gru_f32": "gru_fp32", "gru_i8": "gru_int8"}
# Clocks of typical parts (STM32F4 Cortex-M4F at 168 MHz, STM32F7 Cortex-M7 at 216 MHz) for the
# latency estimates: QEMU counts instructions, not cycles, so an estimate is instructions / clock.
CLOCK_MHZ = {"cortex-m4": 168.0, "cortex-m7": 216.0}
TARGETS = {"cnode_int8": {"flash_bytes": 64 * 1024, "static_ram_bytes": 16 * 1024}}
FLASH_SECTIONS = (".isr_vector", ".text", ".ARM.exidx", ".init_array", ".data")  # .data's initial values live in flash
RAM_SECTIONS = (".data", ".bss")
EXIT_MEANING = {0: "all tensors OK", 1: "a tensor NOT OK", 2: "a model failed its check or inference",
                3: "a hard fault", 4: "an unexpected exception"}


def qemu_command(cpu: str, elf: Path) -> list[str]:
    """The QEMU invocation (semihosting console on stdout, exit code from SYS_EXIT_EXTENDED)."""
    return ["qemu-system-arm", "-machine", MCU_CPUS[cpu], "-nographic", "-serial", "none", "-monitor", "none",
            "-chardev", "stdio,id=sh0", "-semihosting-config", "enable=on,target=native,chardev=sh0",
            "-icount", "shift=0", "-kernel", str(elf)]


def tools_missing() -> str | None:
    """None if the cross toolchain and QEMU are installed, else what is missing."""
    missing = [t for t in ("arm-none-eabi-g++", "arm-none-eabi-size", "qemu-system-arm") if shutil.which(t) is None]
    return ", ".join(missing) + " not found (`make setup` installs them)" if missing else None


def section_sizes(binary: str | Path, tool: str = "arm-none-eabi-size") -> dict[str, int]:
    """``<tool> -A -d binary``: section name -> bytes (the one ``size -A`` parser: parity and bench)."""
    res = subprocess.run([tool, "-A", "-d", str(binary)], capture_output=True, text=True)
    if res.returncode != 0:
        raise QuadfdiError(f"{Path(tool).name} failed on {binary}: {res.stderr.strip()}")
    out = {}
    for line in res.stdout.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0].startswith(".") and parts[1].isdigit():
            out[parts[0]] = int(parts[1])
    return out


def image_memory(elf: Path) -> dict[str, int]:
    s = section_sizes(elf)
    return {"flash_bytes": sum(s.get(k, 0) for k in FLASH_SECTIONS),
            "static_ram_bytes": sum(s.get(k, 0) for k in RAM_SECTIONS),
            "text": s.get(".text", 0) + s.get(".isr_vector", 0), "data": s.get(".data", 0), "bss": s.get(".bss", 0),
            "stack_reserved": s.get(".stack", 0)}


_MAP_LINE = re.compile(r"^\s+(?:\.\S+\s+)?0x[0-9a-f]+\s+0x([0-9a-f]+)\s+(\S+)$")


def map_breakdown(map_file: Path) -> dict[str, int]:
    """Bytes linked from the weights' generated arrays and from the model library (map file)."""
    out = {"weights_bytes": 0, "library_bytes": 0}
    linked = False
    for line in map_file.read_text(errors="replace").splitlines():
        if line.startswith("Linker script and memory map"):
            linked = True
        if not linked:
            continue
        m = _MAP_LINE.match(line)
        if m is None:
            continue
        size, obj = int(m.group(1), 16), m.group(2)
        if "fwref_weights_" in obj:
            out["weights_bytes"] += size
        elif "libfwref_mcu_models.a" in obj:
            out["library_bytes"] += size
    return out


def parse_harness(text: str) -> dict:
    """The harness's lines (mcu/parity_main.cpp) as a dict."""
    tensors, perf, calib, result = [], {}, {}, None
    for line in text.splitlines():
        parts = line.split()
        if not parts:
            continue
        kv = dict(p.split("=", 1) for p in parts if "=" in p)
        if parts[0] == "CALIB":
            calib = {"iterations": int(kv["iterations"]), "ticks": int(kv["ticks"]),
                     "instructions_per_tick": float(kv["instructions_per_tick"])}
        elif parts[0] == "TENSOR" and len(parts) >= 5:
            t = {"model": parts[1], "precision": parts[2], "tensor": parts[3], "ok": parts[-1] == "OK"}
            for k in ("maxdiff", "tol", "steps"):
                if k in kv:
                    t[k] = float(kv[k])
            tensors.append(t)
        elif parts[0] == "PERF":
            key = f"{parts[1]}_{parts[2]}"
            p = perf.setdefault(key, {"instructions": [], "stack_bytes": []})
            p["instructions"].append(int(kv["instructions"]))
            p["stack_bytes"].append(int(kv["stack_bytes"]))
        elif parts[0] == "RESULT":
            result = parts[1]
    return {"calibration": calib, "tensors": tensors, "perf": perf, "result": result}


def run_cpu(cpu: str, weights: Path, reference: Path, log: Callable[[str], None] = print) -> dict:
    """Build, run and measure one core; raises QuadfdiError only when it cannot be measured."""
    build_dir = mcu_build_dir(cpu)
    with locked(build_dir):
        build_mcu(cpu, weights, reference, build_dir, log)
        cmd = qemu_command(cpu, build_dir / "fwref_mcu_parity.elf")
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=QEMU_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise QuadfdiError(f"QEMU ({cpu}) did not finish within {QEMU_TIMEOUT_S} s: {' '.join(cmd)}") from None
        harness = parse_harness(res.stdout)
        images = {v: image_memory(build_dir / f"fwref_min_{v}.elf") for v in ("baseline",) + VARIANTS}
        maps = {v: map_breakdown(build_dir / f"fwref_min_{v}.map") for v in VARIANTS}
    if not harness["tensors"] or harness["result"] is None:
        err = (res.stderr.strip().splitlines() or ["no output"])[-1]
        raise QuadfdiError(f"QEMU ({cpu}) run gave no parity result (exit {res.returncode}: "
                           f"{EXIT_MEANING.get(res.returncode, '?')}; {err})")
    base = images["baseline"]
    models = {}
    for v in VARIANTS:
        key = VARIANT_KEY[v]
        perf = harness["perf"].get(key, {"instructions": [], "stack_bytes": []})
        ins = perf["instructions"]
        models[key] = {
            "flash_bytes": images[v]["flash_bytes"] - base["flash_bytes"],
            "static_ram_bytes": images[v]["static_ram_bytes"] - base["static_ram_bytes"],
            **maps[v],
            "stack_peak_bytes": max(perf["stack_bytes"]) if perf["stack_bytes"] else None,
            "instructions_per_inference": int(statistics.median(ins)) if ins else None,
            "instructions_min": min(ins) if ins else None, "instructions_max": max(ins) if ins else None,
            "clock_mhz_assumed": CLOCK_MHZ.get(cpu),
            "cycles_estimate": int(statistics.median(ins)) if ins else None,
            "latency_estimate_us": round(statistics.median(ins) / CLOCK_MHZ[cpu], 1) if ins and cpu in CLOCK_MHZ
            else None,
            "image": images[v],
        }
    failed = [t for t in harness["tensors"] if not t["ok"]]
    log(f"parity: {cpu} under QEMU {MCU_CPUS[cpu]}: {len(harness['tensors']) - len(failed)}/"
        f"{len(harness['tensors'])} tensors OK, exit {res.returncode}")
    return {"machine": MCU_CPUS[cpu], "qemu_command": " ".join(cmd), "exit_code": res.returncode,
            "exit_meaning": EXIT_MEANING.get(res.returncode, "?"), "passed": res.returncode == 0 and not failed,
            "calibration": harness["calibration"], "tensors": harness["tensors"], "baseline_image": base,
            "models": models, "output": res.stdout}


def toolchain_versions() -> dict:
    out = {}
    for tool in ("arm-none-eabi-gcc", "qemu-system-arm"):
        try:
            res = subprocess.run([tool, "--version"], capture_output=True, text=True)
            out[tool] = res.stdout.splitlines()[0] if res.stdout else ""
        except OSError:
            out[tool] = None
    return out


def check_targets(cpus: dict) -> list[str]:
    """Failures of the memory targets and of the QEMU parity runs, one line each."""
    problems = []
    for cpu, r in cpus.items():
        if not r["passed"]:
            bad = [f"{t['model']} {t['precision']} {t['tensor']}" for t in r["tensors"] if not t["ok"]]
            problems.append(f"{cpu}: QEMU parity failed ({r['exit_meaning']}{': ' + ', '.join(bad) if bad else ''})")
        for key, lim in TARGETS.items():
            for what, bound in lim.items():
                v = r["models"][key][what]
                if v > bound:
                    problems.append(f"{cpu}: {key} {what} {v} > target {bound}")
    return problems


def mcu_run(weights: Path, reference: Path, cpus: tuple[str, ...] = tuple(MCU_CPUS),
            log: Callable[[str], None] = print) -> dict:
    """Everything above for each core; the dict that becomes mcu.json."""
    for tool in ("arm-none-eabi-g++", "arm-none-eabi-size", "qemu-system-arm"):
        require(tool, "the Cortex-M build runs under QEMU")
    results = {cpu: run_cpu(cpu, weights, reference, log) for cpu in cpus}
    problems = check_targets(results)
    return {"toolchain": toolchain_versions(), "targets": TARGETS,
            "what": {"flash_bytes": "model image minus baseline image (arm-none-eabi-size -A: .isr_vector, .text, "
                                    ".ARM.exidx, .init_array, .data)",
                     "static_ram_bytes": "model image minus baseline image (.data + .bss): the workspace and any "
                                         "library statics; the input window (the application's) is in both",
                     "weights_bytes": "bytes linked from the generated weight arrays (map file)",
                     "library_bytes": "bytes linked from the model library cnode.cpp/gru.cpp/status.cpp (map file)",
                     "stack_peak_bytes": "peak stack of one inference call (stack painting under QEMU)",
                     "instructions_per_inference": "median over the reference windows; SysTick under -icount "
                                                   "shift=0, calibrated against a loop of known length",
                     "cycles_estimate": "ESTIMATE, not a measurement: QEMU counts instructions, not cycles; this is "
                                        "instructions_per_inference at one cycle per instruction (not modelled: "
                                        "flash wait states, VDIV.F32's 14 cycles, the M4's 2-cycle loads, the M7's "
                                        "dual issue)",
                     "latency_estimate_us": "ESTIMATE: cycles_estimate / clock_mhz_assumed (Cortex-M4 at 168 MHz, "
                                            "Cortex-M7 at 216 MHz)"},
            "cpus": results, "problems": problems, "passed": not problems}
