"""What every runtime adapter of the latency worker shares: statistics, process memory, timing loops."""

from __future__ import annotations

import math
import time
from typing import Callable, Sequence

from quadfdi.bench.config import BenchConfig

WARMUP_SECONDS = BenchConfig.warmup_s  # default: warm-up stops after this long even when fewer calls ran
MIN_SAMPLES = BenchConfig.min_samples  # default: a time budget never cuts a measurement below this many calls


def percentile(values: Sequence[float], q: float) -> float:
    """The q-th percentile (0..100) by linear interpolation between order statistics.

    The same definition as ``numpy.percentile``'s default (method "linear"): position
    (n - 1) * q / 100 in the sorted values, interpolated between its two neighbours.
    """
    if not values:
        raise ValueError("percentile of no values")
    if not 0.0 <= q <= 100.0:
        raise ValueError(f"percentile q must be in [0, 100], found {q}")
    v = sorted(values)
    pos = (len(v) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (pos - lo)


def summarise(samples_us: Sequence[float], batch: int) -> dict:
    """p50/p90/p99, mean, min, max (microseconds per call) and throughput = batch * 1e6 / p50."""
    p50 = percentile(samples_us, 50)
    return {
        "p50_us": p50,
        "p90_us": percentile(samples_us, 90),
        "p99_us": percentile(samples_us, 99),
        "mean_us": sum(samples_us) / len(samples_us),
        "min_us": min(samples_us),
        "max_us": max(samples_us),
        "n_calls": len(samples_us),
        "throughput_wps": batch * 1e6 / p50 if p50 > 0 else None,
    }


def proc_status_kib(field: str) -> int | None:
    """A ``/proc/self/status`` field in KiB (VmRSS, VmHWM); None where /proc is not available."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def reset_peak_rss() -> bool:
    """Reset VmHWM to the current RSS (Linux: write 5 to /proc/self/clear_refs); False if refused."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def peak_rss_kib() -> int | None:
    """Peak RSS of this process in KiB: VmHWM, else getrusage's ru_maxrss (KiB on Linux)."""
    hwm = proc_status_kib("VmHWM")
    if hwm is not None:
        return hwm
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def time_calls(call: Callable[[object], object], inputs: Sequence[object], n: int, warmup: int,
               budget_s: float, min_samples: int = MIN_SAMPLES, warmup_s: float = WARMUP_SECONDS) -> list[float]:
    """Microseconds of each of up to ``n`` calls ``call(inputs[i % len(inputs)])``, after warm-up.

    Warm-up: ``warmup`` calls or ``warmup_s`` seconds, whichever ends first (at least one call). The
    timed loop stops after ``n`` calls or once ``budget_s`` has elapsed (never below ``min_samples``).
    """
    t_end = time.perf_counter() + warmup_s
    for i in range(max(1, warmup)):
        call(inputs[i % len(inputs)])
        if time.perf_counter() > t_end:
            break
    samples: list[float] = []
    deadline = time.perf_counter() + budget_s
    clock = time.perf_counter_ns
    for i in range(n):
        x = inputs[i % len(inputs)]
        t0 = clock()
        call(x)
        samples.append((clock() - t0) / 1e3)
        if i + 1 >= min_samples and time.perf_counter() > deadline:
            break
    return samples


def batches_of(x, batch: int, count: int) -> list:
    """``count`` batches of ``batch`` consecutive windows of ``x`` (cycling over x)."""
    import numpy as np

    idx = np.arange(batch * count) % len(x)
    return [np.ascontiguousarray(x[idx[k * batch:(k + 1) * batch]]) for k in range(count)]


def pair_summary(f32: list[float], i8: list[float], batch: int) -> dict:
    """p50 of each and the per-round ratios int8 / fp32 time (median, p10, p90): bench/ort_pairs.py and
    bench/cpp_pairs.py (fp32 and int8 timed in one process, taking turns)."""
    ratios = [b / a for a, b in zip(f32, i8)]
    return {"batch": batch, "rounds": len(ratios), "fp32_p50_us": percentile(f32, 50),
            "int8_p50_us": percentile(i8, 50),
            "int8_over_fp32_median": percentile(ratios, 50), "int8_over_fp32_p10": percentile(ratios, 10),
            "int8_over_fp32_p90": percentile(ratios, 90)}
