"""The Cortex-M as a runtime: QEMU invocations, the images' flash and RAM (arm-none-eabi-size, map
files) and the clocks that turn QEMU's instruction counts into estimates.

QEMU (machines mps2-an386 for the Cortex-M4F, mps2-an500 for the M7) runs with semihosting and
``-icount shift=0`` so that SysTick counts instructions: QEMU counts instructions, not cycles.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.runtimes.build import MCU_CPUS

QEMU_TIMEOUT_S = 600
# Clocks of typical parts (STM32F4 Cortex-M4F at 168 MHz, STM32F7 Cortex-M7 at 216 MHz) for the
# latency estimates: QEMU counts instructions, not cycles, so an estimate is instructions / clock.
CLOCK_MHZ = {"cortex-m4": 168.0, "cortex-m7": 216.0}
FLASH_SECTIONS = (".isr_vector", ".text", ".ARM.exidx", ".init_array", ".data")  # .data's initial values live in flash
RAM_SECTIONS = (".data", ".bss")


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


def toolchain_versions() -> dict:
    out = {}
    for tool in ("arm-none-eabi-gcc", "qemu-system-arm"):
        try:
            res = subprocess.run([tool, "--version"], capture_output=True, text=True)
            out[tool] = res.stdout.splitlines()[0] if res.stdout else ""
        except OSError:
            out[tool] = None
    return out
