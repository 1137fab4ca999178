"""The Cortex-M part of parity: cross-build, QEMU runs, flash/RAM and instructions per inference.

For each core (Cortex-M4F on mps2-an386, Cortex-M7 on mps2-an500):
1. cross-build firmware_ref/mcu with the run's weights.bin and reference.bin compiled in;
2. run the parity harness under QEMU (semihosting; -icount shift=0 so that SysTick counts
   instructions) and parse its lines: every tensor against reference.bin, instructions and peak
   stack per inference; its exit code says pass or fail;
3. measure the minimal images with arm-none-eabi-size: model image minus baseline image (the same
   startup, window buffer and main without the model) = the library and its weights alone;
   the map file splits that into the weights' constant arrays and the library's code;
4. with stream inputs (parity/stream.py), build the stream image in the same folder and measure
   the on-board streaming cost of every model, held against the host's fwref_stream.
"""

from __future__ import annotations

import statistics
import subprocess
from pathlib import Path
from typing import Callable

from quadfdi.core.errors import QuadfdiError
from quadfdi.parity import stream as stream_mod
from quadfdi.runtimes.build import MCU_CPUS, build_mcu, locked, mcu_build_dir, require
from quadfdi.runtimes.mcu import (CLOCK_MHZ, QEMU_TIMEOUT_S, image_memory, map_breakdown, qemu_command,
                                  toolchain_versions)

VARIANTS = ("cnode_f32", "cnode_i8", "gru_f32", "gru_i8")
VARIANT_KEY = {"cnode_f32": "cnode_fp32", "cnode_i8": "cnode_int8", "gru_f32": "gru_fp32", "gru_i8": "gru_int8"}
TARGETS = {"cnode_int8": {"flash_bytes": 64 * 1024, "static_ram_bytes": 16 * 1024}}
EXIT_MEANING = {0: "all tensors OK", 1: "a tensor NOT OK", 2: "a model failed its check or inference",
                3: "a hard fault", 4: "an unexpected exception"}


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


def run_cpu(cpu: str, weights: Path, reference: Path, log: Callable[[str], None] = print,
            stream: stream_mod.StreamInputs | None = None) -> dict:
    """Build, run and measure one core; raises QuadfdiError only when it cannot be measured. The CNODE's
    stage weights are int16 copies in RAM (faster) when the int8 CNODE then meets its static-RAM target,
    else they stay int8 in flash: measured, the build with the copies first."""
    r = _run_build(cpu, weights, reference, log, stream, cnode_w_int16=True)
    ram, bound = r["models"]["cnode_int8"]["static_ram_bytes"], TARGETS["cnode_int8"]["static_ram_bytes"]
    if ram > bound:  # that build ran the parity harness alone: its stream replay would be thrown away
        log(f"parity: {cpu}: the int8 CNODE takes {ram} B of static RAM with its int16 weight copies "
            f"(target {bound} B): rebuilt without them")
        first = r["models"]["cnode_int8"]
        r = _run_build(cpu, weights, reference, log, stream, cnode_w_int16=False)
        r["models"]["cnode_int8"]["with_int16_copies"] = {
            k: first[k] for k in ("static_ram_bytes", "stack_peak_bytes", "instructions_per_inference")}
    r["models"]["cnode_int8"]["int16_weight_copies"] = ram <= bound
    return r


def _run_build(cpu: str, weights: Path, reference: Path, log: Callable[[str], None],
               stream: stream_mod.StreamInputs | None, cnode_w_int16: bool) -> dict:
    build_dir = mcu_build_dir(cpu)
    with locked(build_dir):
        paths = stream_mod.write_streams(build_dir, stream) if stream is not None else ()
        build_mcu(cpu, weights, reference, build_dir, log, streams=paths, cnode_w_int16=cnode_w_int16)
        images = {v: image_memory(build_dir / f"fwref_min_{v}.elf") for v in ("baseline",) + VARIANTS}
        if cnode_w_int16 and _cnode_i8_ram(images) > TARGETS["cnode_int8"]["static_ram_bytes"]:
            paths = ()  # to be built again without the copies (run_cpu)
        cmd = qemu_command(cpu, build_dir / "fwref_mcu_parity.elf")
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=QEMU_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise QuadfdiError(f"QEMU ({cpu}) did not finish within {QEMU_TIMEOUT_S} s: {' '.join(cmd)}") from None
        harness = parse_harness(res.stdout)
        maps = {v: map_breakdown(build_dir / f"fwref_min_{v}.map") for v in VARIANTS}
        streamed = stream_mod.measure(cpu, build_dir, Path(weights).parent, paths, stream, log) if paths else None
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
            "models": models, "output": res.stdout, "stream": streamed}


def _cnode_i8_ram(images: dict) -> int:
    """The int8 CNODE's static RAM: its minimal image's minus the baseline image's (as in mcu.json)."""
    return images["cnode_i8"]["static_ram_bytes"] - images["baseline"]["static_ram_bytes"]


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
            log: Callable[[str], None] = print, stream: stream_mod.StreamInputs | str | None = None) -> dict:
    """Everything above for each core; the dict that becomes mcu.json, and under ``stream`` the one
    that becomes mcu_stream.json (``{"skipped": reason}`` when ``stream`` is the reason there are no
    stream inputs, or None)."""
    for tool in ("arm-none-eabi-g++", "arm-none-eabi-size", "qemu-system-arm"):
        require(tool, "the Cortex-M build runs under QEMU")
    inputs = stream if isinstance(stream, stream_mod.StreamInputs) else None
    results = {cpu: run_cpu(cpu, weights, reference, log, inputs) for cpu in cpus}
    streamed = {cpu: r.pop("stream") for cpu, r in results.items()}
    table = (stream_mod.table(streamed, inputs) if inputs is not None
             else {"skipped": stream or "not requested"})
    problems = check_targets(results) + table.get("problems", [])
    return {"toolchain": toolchain_versions(), "targets": TARGETS,
            "what": {"flash_bytes": "model image minus baseline image (arm-none-eabi-size -A: .isr_vector, .text, "
                                    ".ARM.exidx, .init_array, .data)",
                     "static_ram_bytes": "model image minus baseline image (.data + .bss): the workspace and any "
                                         "library statics; the input window (the application's) is in both",
                     "weights_bytes": "bytes linked from the generated weight arrays (map file)",
                     "library_bytes": "bytes linked from the model library cnode.cpp/gru.cpp/status.cpp (map file)",
                     "stack_peak_bytes": "peak stack of one inference call (stack painting under QEMU)",
                     "int16_weight_copies": "int8 CNODE: lin1_z and lin2 sign-extended to int16 in RAM (faster); "
                                            "false when the static-RAM target is missed with them, so the images "
                                            "were built without (FWREF_CNODE_W_INT16=OFF); with_int16_copies: "
                                            "that build's measures",
                     "instructions_per_inference": "median over the reference windows; SysTick under -icount "
                                                   "shift=0, calibrated against a loop of known length",
                     "cycles_estimate": "ESTIMATE, not a measurement: QEMU counts instructions, not cycles; this is "
                                        "instructions_per_inference at one cycle per instruction (not modelled: "
                                        "flash wait states, VDIV.F32's 14 cycles, the M4's 2-cycle loads, the M7's "
                                        "dual issue)",
                     "latency_estimate_us": "ESTIMATE: cycles_estimate / clock_mhz_assumed (Cortex-M4 at 168 MHz, "
                                            "Cortex-M7 at 216 MHz)"},
            "cpus": results, "problems": problems, "passed": not problems, "stream": table}
