"""The streaming runtime's memory (bench.json ``stream.memory``).

``sizeof(fwref::Stream)`` (ring buffer, window, hover estimate and alarm state) with the model's own
limits (W, C, K, the stream's raw channels R, the policy's n): the size of one static object
compiled from fwref/stream.hpp for the host (``c++``) and for each Cortex-M core
(``arm-none-eabi-g++`` with the firmware's flags, mcu/toolchain-arm-none-eabi.cmake), read with
``nm -S``. Also the host program's own ``stream_bytes`` (its generous build limits, ``fwref_stream
--info``) and the sections of the stream image that ``quadfdi parity`` (its Cortex-M part) last
built for each core (``arm-none-eabi-size`` of ``runtimes.mcu_stream.stream_elf(cpu)``).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

from quadfdi.formats.export_folder import Export

MCU_FLAGS = {"cortex-m4": ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"],
             "cortex-m7": ["-mcpu=cortex-m7", "-mthumb", "-mfpu=fpv5-d16", "-mfloat-abi=hard"]}  # mcu/toolchain
PROBE = "quadfdi_stream_probe"
PROBE_CPP = f'#include "fwref/stream.hpp"\nfwref::Stream {PROBE};\n'


def limit_macros(record: dict, export: Export) -> dict[str, int]:
    """The FWREF_MAX_* values that size fwref::Stream for this model (what the Cortex-M generators
    runtimes/mcu_weights_src and mcu_stream_src set)."""
    from quadfdi.formats.onboard import max_alarm_n

    return {"FWREF_MAX_WINDOW": int(record["window"]), "FWREF_MAX_CHANNELS": len(export.channel_names),
            "FWREF_MAX_CLASSES": len(export.class_names), "FWREF_MAX_RAW_CHANNELS": len(record["raw_channels"]),
            "FWREF_MAX_ALARM_N": max_alarm_n(record)}  # the largest n of the record's per-network policies


def eigen_include() -> list[str]:
    """The compiler flags that find Eigen's headers (fwref/stream.hpp includes the streaming GRU's step,
    which uses Eigen): pkg-config's, else Debian's /usr/include/eigen3 (libeigen3-dev)."""
    try:
        out = subprocess.run(["pkg-config", "--cflags", "eigen3"], capture_output=True, text=True, check=True).stdout
        return out.split()
    except (OSError, subprocess.CalledProcessError):
        return ["-I", "/usr/include/eigen3"]


def sizeof_stream(compiler: str, nm: str, flags: list[str], macros: dict[str, int], tmp: Path) -> int:
    """sizeof(fwref::Stream) under ``compiler`` and ``flags``: the symbol size of one static object."""
    from quadfdi.core.resources import firmware_sources

    src, obj = tmp / "probe.cpp", tmp / "probe.o"
    src.write_text(PROBE_CPP)
    cmd = [compiler, "-std=c++17", "-O2", "-I", str(firmware_sources() / "include"), *eigen_include(), *flags,
           *(f"-D{k}={v}" for k, v in macros.items()), "-c", str(src), "-o", str(obj)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    out = subprocess.run([nm, "-S", "--defined-only", str(obj)], check=True, capture_output=True, text=True).stdout
    return next(int(p[1], 16) for p in (ln.split() for ln in out.splitlines()) if len(p) == 4 and p[3] == PROBE)


def _image(cpu: str) -> dict | None:
    """The stream image parity's Cortex-M part last built for ``cpu``, or None."""
    from quadfdi.runtimes.mcu import section_sizes
    from quadfdi.runtimes.mcu_stream import stream_elf

    elf = stream_elf(cpu)
    if not elf.is_file() or shutil.which("arm-none-eabi-size") is None:
        return None
    s = section_sizes(elf)
    return {"elf": str(elf), "text_bytes": s.get(".text", 0), "data_bytes": s.get(".data", 0),
            "bss_bytes": s.get(".bss", 0),
            "note": "as quadfdi parity last built it (the weights and stream files of its run)"}


def stream_memory(record: dict, export: Export, exe: Path | None,
                  cores: tuple[str, ...] = tuple(MCU_FLAGS)) -> list[dict]:
    """One record per target: host (c++) and each Cortex-M core of ``cores`` (skipped with a reason
    if no compiler); ``record`` is ``export``'s on-board record."""
    macros = limit_macros(record, export)
    rows = []
    targets = [("host", "c++", "nm", [])] + [(cpu, "arm-none-eabi-g++", "arm-none-eabi-nm", f)
                                              for cpu, f in MCU_FLAGS.items() if cpu in cores]
    with tempfile.TemporaryDirectory(prefix="quadfdi-stream-sizeof-") as d:
        for target, cc, nm, flags in targets:
            row: dict = {"target": target, "limits": macros}
            if shutil.which(cc) is None or shutil.which(nm) is None:
                row["skipped"] = f"{cc} or {nm} not found"
            else:
                row["stream_bytes"] = sizeof_stream(cc, nm, flags, macros, Path(d))
                row["source"] = f"{cc} -O2 {' '.join(flags)} of fwref/stream.hpp: nm -S of one fwref::Stream"
            if target != "host":
                row["image"] = _image(target) or "no stream image built (`quadfdi parity --run RUN` builds one)"
            rows.append(row)
    if exe is not None:
        info = subprocess.run([str(exe), "--weights", str(export.weights_path), "--info"], capture_output=True, text=True,
                              check=False)
        line = next((ln for ln in info.stdout.splitlines() if ln.startswith("stream_bytes=")), None)
        rows[0]["fwref_stream_build_bytes"] = int(line.split("=")[1]) if line else None
    return rows
