"""Builds of firmware_ref/ with CMake: the host programs, the sanitizer build, the Cortex-M images.

Each build folder is locked (fcntl) while it is configured and built, so two processes (a test
session and a `quadfdi parity`) never write one folder at once; CMake's own dependency tracking
makes a repeated build cheap. A failed build is a one-line QuadfdiError naming the log file that
holds CMake's full output.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Callable, Iterator

from quadfdi.core.errors import QuadfdiError

FW_ROOT = Path(__file__).resolve().parents[1] / "firmware_ref"
HOST_BUILD = FW_ROOT / "build"  # fwref_infer and fwref_parity end up here (a documented contract)
ASAN_BUILD = FW_ROOT / "build-asan"
MCU_CPUS = {"cortex-m4": "mps2-an386", "cortex-m7": "mps2-an500"}
JOBS = 2  # the development machine has two cores, shared


def mcu_build_dir(cpu: str) -> Path:
    return FW_ROOT / f"build-mcu-{cpu.removeprefix('cortex-')}"


def require(tool: str, why: str) -> str:
    path = shutil.which(tool)
    if path is None:
        raise QuadfdiError(f"{tool} not found on PATH ({why}); `make setup` installs it (scripts/setup.sh)")
    return path


@contextlib.contextmanager
def locked(build_dir: Path) -> Iterator[None]:
    """Exclusive lock of ``build_dir`` for the duration of the block."""
    build_dir.mkdir(parents=True, exist_ok=True)
    with open(build_dir / ".quadfdi.lock", "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _run_logged(cmd: list[str], log_file: Path, what: str) -> None:
    with open(log_file, "a") as log:
        log.write("$ " + " ".join(cmd) + "\n")
        log.flush()
        res = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=dict(os.environ, LC_ALL="C"))
    if res.returncode != 0:
        tail = [ln for ln in log_file.read_text(errors="replace").splitlines() if "error" in ln.lower()]
        hint = f": {tail[0].strip()[:200]}" if tail else ""
        raise QuadfdiError(f"{what} failed (exit {res.returncode}){hint}; full log: {log_file}")


def _configure_and_build(source: Path, build_dir: Path, options: dict[str, str], what: str,
                         targets: tuple[str, ...] = ()) -> None:
    """cmake -S source -B build_dir -D... (again only when an option changed), then cmake --build."""
    require("cmake", "it builds firmware_ref")
    log_file = build_dir / "quadfdi-build.log"
    log_file.write_text("")
    cache = build_dir / "CMakeCache.txt"
    cached = cache.read_text(errors="replace") if cache.is_file() else ""
    stale = not cached or any(f"{k}:" not in cached or f"={v}\n" not in _cache_line(cached, k) for k, v in options.items())
    if stale:
        _run_logged(["cmake", "-S", str(source), "-B", str(build_dir)] + [f"-D{k}={v}" for k, v in options.items()],
                    log_file, f"configuring {what}")
    cmd = ["cmake", "--build", str(build_dir), "-j", str(JOBS)]
    for t in targets:
        cmd += ["--target", t]
    _run_logged(cmd, log_file, f"building {what}")


def _cache_line(cache: str, key: str) -> str:
    for line in cache.splitlines():
        if line.startswith(f"{key}:"):
            return line + "\n"
    return ""


def build_host(build_dir: Path = HOST_BUILD, sanitize: bool = False, log: Callable[[str], None] = print) -> Path:
    """Build fwref_infer, fwref_parity, fwref_contracts and fwref_kernels (Release; with ``sanitize`` ASan + UBSan, assertions on)."""
    require("c++", "it compiles firmware_ref")
    options = {"CMAKE_BUILD_TYPE": "Debug" if sanitize else "Release", "FWREF_SANITIZE": "ON" if sanitize else "OFF"}
    with locked(build_dir):
        _configure_and_build(FW_ROOT, build_dir, options, f"firmware_ref ({'sanitizer' if sanitize else 'host'})")
    for name in ("fwref_infer", "fwref_parity", "fwref_contracts", "fwref_kernels"):
        if not (build_dir / name).is_file():
            raise QuadfdiError(f"the firmware_ref build did not produce {build_dir / name}")
    log(f"parity: firmware_ref built in {build_dir}{' (ASan + UBSan)' if sanitize else ''}")
    return build_dir


def build_mcu(cpu: str, weights: Path, reference: Path, build_dir: Path | None = None,
              log: Callable[[str], None] = print, streams: tuple[Path, ...] = ()) -> Path:
    """Cross-build the Cortex-M images for ``cpu`` with ``weights`` and ``reference`` compiled in;
    with ``streams`` (stream files) also the stream image fwref_mcu_stream.elf, which replays them.

    The caller holds ``locked(build_dir)`` while it also runs the images, so that another process
    cannot rebuild them with other weights in between.
    """
    if cpu not in MCU_CPUS:
        raise QuadfdiError(f"unknown Cortex-M target {cpu!r}; valid: {', '.join(MCU_CPUS)}")
    require("arm-none-eabi-g++", "it cross-compiles the Cortex-M build")
    build_dir = build_dir or mcu_build_dir(cpu)
    options = {"CMAKE_TOOLCHAIN_FILE": str(FW_ROOT / "mcu" / "toolchain-arm-none-eabi.cmake"), "FWREF_CPU": cpu,
               "FWREF_WEIGHTS": str(Path(weights).resolve()), "FWREF_REFERENCE": str(Path(reference).resolve()),
               "Python3_EXECUTABLE": sys.executable,
               # "" = no stream image: stream files of another export must not be rebuilt with these weights
               "FWREF_STREAMS": ";".join(str(Path(s).resolve()) for s in streams)}
    manifest = Path(weights).resolve().parent / "manifest.json"
    # the generator checks weights.bin and reference.bin against the export's manifest; "" = no check
    options["FWREF_MANIFEST"] = str(manifest) if manifest.is_file() else ""
    _configure_and_build(FW_ROOT / "mcu", build_dir, options, f"the {cpu} images")
    log(f"parity: {cpu} images built in {build_dir}")
    return build_dir
