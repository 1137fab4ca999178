"""Builds of firmware_ref with CMake: the host programs, the sanitizer build, the Cortex-M images, in a
per-user cache folder named by the hash of the C++ sources.

Layout: ``<cache>/fwref-<hash16>/`` (``<cache>``: core.resources.cache_root, i.e. ``$QUADFDI_CACHE``,
else ``$XDG_CACHE_HOME/quadfdi``, else ``~/.cache/quadfdi``) holds ``src/``, a copy of the sources the
hash names (core.resources.FWREF_PATTERNS: the files the wheel ships), and the build folders made from
it: ``build/`` (Release: fwref_infer, fwref_parity, ...), ``build-asan/`` (ASan + UBSan) and
``build-mcu-m4/``, ``build-mcu-m7/`` (the Cortex-M images). One scheme for a checkout and an installed
wheel: nothing is built into site-packages or the checkout; a change to any C++ source gives a new
folder and a clean build of exactly those sources (CMake cannot move a build tree, so a folder keyed
by content cannot be updated in place); checkouts and venvs holding the same sources share one
build. When a new folder is made, the others not used for ``PRUNE_DAYS`` days are removed.

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
import time
from pathlib import Path
from typing import Callable, Iterator

from quadfdi.core.cliargs import one_line_main
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.resources import cache_root, firmware_digest, firmware_files

MCU_CPUS = {"cortex-m4": "mps2-an386", "cortex-m7": "mps2-an500"}
JOBS = 2  # the development machine has two cores, shared
HOST_PROGRAMS = ("fwref_infer", "fwref_parity", "fwref_contracts", "fwref_kernels")  # what build_host checks
PRUNE_DAYS = 7
LOCK, LAST_USED = ".quadfdi.lock", ".last-used"


def fwref_home() -> Path:
    """``<cache>/fwref-<hash16>`` of the installed C++ sources, with their copy in ``src/`` (made on
    first use) and its last use recorded; a new one prunes the stale others (``prune``)."""
    files = firmware_files()
    home = cache_root() / f"fwref-{firmware_digest(files)[:16]}"
    try:
        with locked(home):
            made = not (home / "src").is_dir()
            if made:
                _write_sources(home, files)
            (home / LAST_USED).touch()
    except OSError as exc:
        raise QuadfdiError(f"cannot use the build cache {home}: {exc.strerror or exc} "
                           "(QUADFDI_CACHE names another folder)") from None
    if made:
        prune(home.parent, keep=home)
    return home


def _write_sources(home: Path, files: dict[str, bytes]) -> None:
    """``home/src`` from ``files``: written beside it, then renamed, so that it exists only whole (the
    bytes were read once: the copy is exactly what the folder's hash names)."""
    tmp = home / "src.partial"
    shutil.rmtree(tmp, ignore_errors=True)
    for rel, data in files.items():
        (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp / rel).write_bytes(data)
    tmp.rename(home / "src")


def prune(root: Path, keep: Path, days: float = PRUNE_DAYS) -> list[Path]:
    """Remove the ``fwref-*`` folders of ``root`` other than ``keep`` whose last use is ``days`` days old
    or more, unless another process holds one locked; the removed folders. (A use records itself under
    the lock, so the age is read again once the lock is held.)"""
    def stale(home: Path) -> bool:
        stamp = home / LAST_USED
        return time.time() - (stamp if stamp.is_file() else home).stat().st_mtime >= days * 86400

    removed = []
    for home in sorted(root.glob("fwref-*")):
        if home == keep or not home.is_dir() or not stale(home):
            continue
        with open(home / LOCK, "a") as fh:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                continue  # in use right now
            if not stale(home):
                continue
            home.rename(root / f".trash-{home.name}-{os.getpid()}")  # a process waiting for the lock remakes it
        removed.append(home)
    for trash in root.glob(".trash-fwref-*"):  # this pass's and any a killed pass left
        shutil.rmtree(trash, ignore_errors=True)
    return removed


def source_dir() -> Path:
    """The copy of firmware_ref's sources that the cached builds are made from."""
    return fwref_home() / "src"


def host_build_dir(sanitize: bool = False) -> Path:
    """The host build of the installed sources (``build-asan`` with ``sanitize``)."""
    return fwref_home() / ("build-asan" if sanitize else "build")


def mcu_build_dir(cpu: str) -> Path:
    return fwref_home() / f"build-mcu-{cpu.removeprefix('cortex-')}"


def require(tool: str, why: str) -> str:
    path = shutil.which(tool)
    if path is None:
        raise QuadfdiError(f"{tool} not found on PATH ({why}); `make setup` installs it (scripts/setup.sh)")
    return path


@contextlib.contextmanager
def locked(folder: Path) -> Iterator[None]:
    """Exclusive lock of ``folder`` (made if missing) for the duration of the block. The lock file is
    checked to be the one at the path after the wait: a folder pruned meanwhile is made anew."""
    while True:
        Path(folder).mkdir(parents=True, exist_ok=True)
        fh = open(Path(folder) / LOCK, "a")
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            if os.fstat(fh.fileno()).st_ino == os.stat(Path(folder) / LOCK).st_ino:
                break
        except FileNotFoundError:
            pass
        fh.close()
    try:
        yield
    finally:
        fcntl.flock(fh, fcntl.LOCK_UN)
        fh.close()


def compiler_launcher() -> dict[str, str]:
    """The CMake options that run every compile through ccache when it is on PATH (``QUADFDI_CCACHE=0``:
    never): a build of sources already compiled with the same flags (another checkout's or a wheel's
    copy of the same sources, a Cortex-M image rebuilt for a model of dimensions seen before) reads the
    objects back instead of compiling them. ccache hashes the preprocessed source, the compiler and its
    flags, so an object it returns is the one the compiler would write."""
    ccache = shutil.which("ccache")
    if os.environ.get("QUADFDI_CCACHE", "1") == "0":
        ccache = None
    # "" when there is none, so that a folder configured with it is configured again without it
    return {"CMAKE_C_COMPILER_LAUNCHER": ccache or "", "CMAKE_CXX_COMPILER_LAUNCHER": ccache or ""}


def _run_logged(cmd: list[str], log_file: Path, what: str, base_dir: Path | None = None) -> None:
    env = dict(os.environ, LC_ALL="C")
    if base_dir is not None:
        # ccache rewrites the paths under base_dir relative to the build folder, so that copies of the
        # sources and builds at another place with the same layout share its cache
        env["CCACHE_BASEDIR"] = str(base_dir)
    # the host build's precompiled Eigen/Core (firmware_ref/CMakeLists.txt) is cacheable only so: ccache
    # then hashes the .gch itself rather than the macros and __TIME__ it was made with
    env.setdefault("CCACHE_SLOPPINESS", "pch_defines,time_macros")
    with open(log_file, "a") as log:
        log.write("$ " + " ".join(cmd) + "\n")
        log.flush()
        res = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
    if res.returncode != 0:
        tail = [ln for ln in log_file.read_text(errors="replace").splitlines() if "error" in ln.lower()]
        hint = f": {tail[0].strip()[:200]}" if tail else ""
        raise QuadfdiError(f"{what} failed (exit {res.returncode}){hint}; full log: {log_file}")


def configure_and_build(source: Path, build_dir: Path, options: dict[str, str], what: str,
                         targets: tuple[str, ...] = ()) -> None:
    """cmake -S source -B build_dir -D... (again only when an option changed), then cmake --build; through
    ccache when there is one (``compiler_launcher``)."""
    require("cmake", "it builds firmware_ref")
    options = {**compiler_launcher(), **options}
    common = Path(os.path.commonpath([Path(source).resolve(), Path(build_dir).resolve()]))
    base_dir = common if len(common.parts) > 2 else None  # not / or a top-level folder such as /tmp
    log_file = build_dir / "quadfdi-build.log"
    log_file.write_text("")
    cache = build_dir / "CMakeCache.txt"
    cached = cache.read_text(errors="replace") if cache.is_file() else ""
    home_dir = _cache_line(cached, "CMAKE_HOME_DIRECTORY").partition("=")[2].strip()
    if cached and (not home_dir or Path(home_dir).resolve() != Path(source).resolve()):
        # a build folder configured from another copy of the sources (the caller's own folder, kept
        # while the sources changed): CMake refuses to switch, so configure it afresh
        cache.unlink()
        shutil.rmtree(build_dir / "CMakeFiles", ignore_errors=True)
        cached = ""
    stale = not cached or any(f"{k}:" not in cached or f"={v}\n" not in _cache_line(cached, k) for k, v in options.items())
    if stale:
        _run_logged(["cmake", "-S", str(source), "-B", str(build_dir)] + [f"-D{k}={v}" for k, v in options.items()],
                    log_file, f"configuring {what}", base_dir)
    cmd = ["cmake", "--build", str(build_dir), "-j", str(JOBS)]
    for t in targets:
        cmd += ["--target", t]
    _run_logged(cmd, log_file, f"building {what}", base_dir)


def _cache_line(cache: str, key: str) -> str:
    for line in cache.splitlines():
        if line.startswith(f"{key}:"):
            return line + "\n"
    return ""


def build_host(build_dir: Path | None = None, sanitize: bool = False, log: Callable[[str], None] = print,
               targets: tuple[str, ...] = ()) -> Path:
    """Build the host programs (Release; with ``sanitize`` ASan + UBSan, assertions on) into ``build_dir``
    (default: ``host_build_dir(sanitize)``): ``targets`` alone, or all of them, checked for
    ``HOST_PROGRAMS``. Returns the build folder."""
    require("c++", "it compiles firmware_ref")
    home = fwref_home()
    build_dir = Path(build_dir) if build_dir is not None else home / ("build-asan" if sanitize else "build")
    options = {"CMAKE_BUILD_TYPE": "Debug" if sanitize else "Release", "FWREF_SANITIZE": "ON" if sanitize else "OFF"}
    with locked(build_dir):
        configure_and_build(home / "src", build_dir, options, f"firmware_ref ({'sanitizer' if sanitize else 'host'})",
                             targets)
    for name in targets or HOST_PROGRAMS:
        if not (build_dir / name).is_file():
            raise QuadfdiError(f"the firmware_ref build did not produce {build_dir / name}")
    log(f"parity: firmware_ref built in {build_dir}{' (ASan + UBSan)' if sanitize else ''}")
    return build_dir


def build_mcu(cpu: str, weights: Path, reference: Path, build_dir: Path | None = None,
              log: Callable[[str], None] = print, streams: tuple[Path, ...] = (),
              cnode_w_int16: bool = True) -> Path:
    """Cross-build the Cortex-M images for ``cpu`` with ``weights`` and ``reference`` compiled in;
    with ``streams`` (stream files) also the stream image fwref_mcu_stream.elf, which replays them.
    ``cnode_w_int16``: the CNODE's stage weights as int16 copies in RAM (FWREF_CNODE_W_INT16).

    The caller holds ``locked(build_dir)`` while it also runs the images, so that another process
    cannot rebuild them with other weights in between. CMake runs the weights generator with this
    interpreter (``-m quadfdi.runtimes.mcu_weights_src``), so it reads the files with this quadfdi.
    """
    if cpu not in MCU_CPUS:
        raise QuadfdiError(f"unknown Cortex-M target {cpu!r}; valid: {', '.join(MCU_CPUS)}")
    require("arm-none-eabi-g++", "it cross-compiles the Cortex-M build")
    src = source_dir()
    build_dir = build_dir or mcu_build_dir(cpu)
    options = mcu_options(src, cpu, weights, reference, streams)
    options["FWREF_CNODE_W_INT16"] = "ON" if cnode_w_int16 else "OFF"
    configure_and_build(src / "mcu", build_dir, options, f"the {cpu} images")
    log(f"parity: {cpu} images built in {build_dir}")
    return build_dir


def mcu_options(src: Path, cpu: str, weights: Path, reference: Path, streams: tuple[Path, ...] = ()) -> dict[str, str]:
    """The CMake options of a Cortex-M build of ``src`` with ``weights``, ``reference`` and ``streams``
    compiled in."""
    options = {"CMAKE_TOOLCHAIN_FILE": str(src / "mcu" / "toolchain-arm-none-eabi.cmake"), "FWREF_CPU": cpu,
               "FWREF_WEIGHTS": str(Path(weights).resolve()), "FWREF_REFERENCE": str(Path(reference).resolve()),
               "Python3_EXECUTABLE": sys.executable,
               # "" = no stream image: stream files of another export must not be rebuilt with these weights
               "FWREF_STREAMS": ";".join(str(Path(s).resolve()) for s in streams)}
    manifest = Path(weights).resolve().parent / "manifest.json"
    # the generator checks weights.bin and reference.bin against the export's manifest; "" = no check
    options["FWREF_MANIFEST"] = str(manifest) if manifest.is_file() else ""
    return options


def main(argv: list[str] | None = None) -> int:
    """``python -m quadfdi.runtimes.build [--asan]``: build the host programs (fwref_infer, fwref_stream,
    ...) of the installed sources and print their folder, e.g. to run fwref_stream on a stream file."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m quadfdi.runtimes.build",
                                 description="Build firmware_ref's host programs in the per-user cache; "
                                             "print the folder.")
    ap.add_argument("--asan", action="store_true", help="the sanitizer build (ASan + UBSan, assertions on)")
    args = ap.parse_args(argv)
    return one_line_main("python -m quadfdi.runtimes.build", lambda: build_host(sanitize=args.asan, log=lambda _: None))


if __name__ == "__main__":
    sys.exit(main())
