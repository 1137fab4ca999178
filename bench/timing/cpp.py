"""The C++ adapter of the latency worker: firmware_ref's ``fwref_infer`` in its own process.

fwref_infer runs windows one at a time and times each call with std::chrono::steady_clock; its
batch-96 figure is 96 consecutive single-window calls (the program has no batched path). Its
memory is its own process's: peak RSS (GNU time's %M) of a one-window run minus that of
``fwref_infer --help`` (the loaded program and its libraries).

The timed run is repeated in ``CPP_PROCESSES`` separate processes and their per-window times pooled:
on the 2-core AMD EPYC the same binary on the same windows lands in one of two speed modes from one
process to the next (CNODE fp32 p50 7.1-7.6 us in 8 of 12 processes, 11.1-11.8 us in 4:
lab/cpp_process_spread.py, docs/bench.md), so one process is one draw of that mode.
"""

from __future__ import annotations

import subprocess
import tempfile
import time
from pathlib import Path

CPP_PROCESSES = 5  # timed processes per setting, their per-window times pooled (see the module doc)


def run_child(cmd: list[str], time_exe: str | None = None) -> tuple[int, str, int | None]:
    """(exit code, stderr, peak RSS KiB or None) of a child process.

    The peak comes from GNU time's %M when ``time_exe`` is given. Not from this process's own
    wait4: Linux carries the parent's RSS high-water mark into a forked child through exec, so a
    child of a 200 MB Python process would "peak" at 200 MB; GNU time forks from its own small
    image, which is far below the program's.
    """
    with tempfile.TemporaryDirectory(prefix="quadfdi-child-") as tmp:
        rss_file = Path(tmp) / "rss"
        full = [time_exe, "-f", "%M", "-o", str(rss_file), *cmd] if time_exe else cmd
        res = subprocess.run(full, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        rss = None
        if time_exe and rss_file.is_file():
            lines = [ln for ln in rss_file.read_text().splitlines() if ln.strip()]
            rss = int(lines[-1]) if lines and lines[-1].strip().isdigit() else None
        return res.returncode, res.stderr, rss


def kernel_info(fwref_infer: str) -> dict:
    """The CPU's instruction-set flags, the fp32 build's ISA and the int8 kernel that runs, from
    ``fwref_parity --kernel-info`` beside ``fwref_infer`` (the same build); {} if it cannot say."""
    exe = Path(fwref_infer).with_name("fwref_parity")
    try:
        res = subprocess.run([str(exe), "--kernel-info"], capture_output=True, text=True, timeout=30)
    except OSError:
        return {}
    if res.returncode != 0:
        return {}
    return dict(ln.split(": ", 1) for ln in res.stdout.splitlines() if ": " in ln)


def cpp_measure(args, x) -> dict:
    """Time fwref_infer on the windows; return records, memory and info (see the module doc)."""
    import numpy as np

    exe = args.fwref
    base = [exe, "--weights", args.artifact, "--model", args.model] + (["--int8"] if args.precision == "int8" else [])
    with tempfile.TemporaryDirectory(prefix="quadfdi-fwref-") as tmp:
        tmpd = Path(tmp)
        code, err, rss_base = run_child([exe, "--help"], args.time_exe)
        if code != 0:
            raise RuntimeError(f"{exe} --help failed: {err.strip()}")
        one = tmpd / "one.f32"
        np.ascontiguousarray(x[:1], dtype="<f4").tofile(one)
        code, err, rss_peak = run_child(base + ["--in", str(one), "--out", str(tmpd / "one.out"), "--repeat", "20",
                                                "--timings", str(tmpd / "one.t")], args.time_exe)
        if code != 0:
            raise RuntimeError(err.strip().splitlines()[-1] if err.strip() else f"{exe} exit code {code}")
        # Input: warm-up windows, then the timed batch-1 windows, then the batch-96 blocks; each
        # window is run once (--repeat 1), so every window is timed once, after the warm-up.
        warm = max(1, args.warmup)
        idx = np.concatenate([np.arange(warm), np.arange(args.n), np.arange(args.batch * args.batches)]) % len(x)
        windows = tmpd / "windows.f32"
        np.ascontiguousarray(x[idx], dtype="<f4").tofile(windows)
        timings = tmpd / "t.f64"
        t0 = time.perf_counter()
        b1, blocks = [], []
        for _ in range(CPP_PROCESSES):
            code, err, _ = run_child(base + ["--in", str(windows), "--out", str(tmpd / "out.f32"), "--repeat", "1",
                                             "--timings", str(timings)])
            if code != 0:
                raise RuntimeError(err.strip().splitlines()[-1] if err.strip() else f"{exe} exit code {code}")
            sec = np.fromfile(timings, dtype="<f8")
            b1 += (sec[warm:warm + args.n] * 1e6).tolist()
            blocks += (sec[warm + args.n:].reshape(args.batches, args.batch).sum(axis=1) * 1e6).tolist()
        wall = time.perf_counter() - t0
    return {
        "batch1": b1,
        "batchN": blocks,
        "memory": {"baseline_kib": rss_base, "peak_batch1_kib": rss_peak, "peak_batch_kib": None,
                   "method": "GNU time %M: one-window run (20 repeats) minus `fwref_infer --help`"
                             if args.time_exe else "not measured: GNU time (/usr/bin/time) not found"},
        "info": {"fwref": exe, "wall_s": wall, "processes": CPP_PROCESSES,
                 "note": f"batch figure = consecutive single-window calls; {CPP_PROCESSES} processes pooled",
                 "kernel": kernel_info(exe)},
    }
