"""Every channel onto the 25 Hz telemetry grid of the simulator (sim.sample_dt_s = 0.04 s), with a mask.

Anti-aliasing: a channel logged faster than 25 Hz is first put on a uniform grid at its own median
interval (linear interpolation between neighbouring samples of one run), low-passed by a
zero-phase Butterworth filter (ORDER 6, cutoff CUTOFF_HZ = 10 Hz, scipy ``sosfiltfilt``: forward and
backward, so the magnitude is squared and no delay is added), then read at the grid times. The
folding frequency is 12.5 Hz; content at 15 Hz (which would alias onto 10 Hz) is attenuated by
42 dB and at 25 Hz (onto 0 Hz) by 96 dB. Channels at or below 25 Hz are interpolated linearly
(no content above their own Nyquist frequency, so nothing can alias).

Gaps: a run of samples ends where two samples lie more than GAP_FACTOR times the channel's median
interval apart, or where the log marked samples invalid (NaN). Grid points outside every run are
masked (mask False, value NaN): nothing is interpolated across a gap. ``quadfdi ingest --gap-factor``
sets another factor for one flight (recorded in flight.npz ``resampling``): a logger that drops
messages under load leaves gaps in slow, smoothed channels (PX4 1.9's ``estimator_status`` on the
UAVCAN mission: median interval 0.21 s, 11 intervals above 0.62 s, the longest 1.41 s) that a
user may choose to bridge; the simulator always uses GAP_FACTOR.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.frames import wrap

GRID_DT = 0.04  # s: the simulator's telemetry sample interval (configs/paper.toml sim.sample_dt_s)
CUTOFF_HZ = 10.0  # Hz: 0.8 x the grid's Nyquist frequency
ORDER = 6
GAP_FACTOR = 3.0  # a missing sample or two is jitter; three in a row is a gap


def spec(gap_factor: float = GAP_FACTOR) -> dict:
    """The resampler's settings, stored in flight.npz (``resampling``)."""
    return {"grid_dt_s": GRID_DT, "filter": "butterworth lowpass, zero-phase (scipy.signal.sosfiltfilt)",
            "order": ORDER, "cutoff_hz": CUTOFF_HZ, "applied_when": "logged rate > 25 Hz",
            "gap_factor": gap_factor, "interpolation": "linear within a run of samples; masked across gaps"}


def make_grid(t0: float, t1: float) -> np.ndarray:
    """Grid times k * GRID_DT covering [t0, t1] (multiples of GRID_DT from the log start)."""
    k0, k1 = int(np.ceil(t0 / GRID_DT - 1e-9)), int(np.floor(t1 / GRID_DT + 1e-9))
    return np.arange(k0, k1 + 1) * GRID_DT


@lru_cache(maxsize=64)
def _sos(rate_hz: float) -> np.ndarray:
    from scipy.signal import butter

    return butter(ORDER, CUTOFF_HZ, fs=rate_hz, output="sos")


def runs(t: np.ndarray, gap_s: float) -> list[tuple[int, int]]:
    """(first, last) indices of the runs of samples with no interval above gap_s."""
    cut = np.flatnonzero(np.diff(t) > gap_s)
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [len(t) - 1]])
    return list(zip(starts.tolist(), ends.tolist()))


def _lowpass(ts: np.ndarray, vs: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    from scipy.signal import sosfiltfilt

    tu = ts[0] + np.arange(int(np.floor((ts[-1] - ts[0]) / dt + 1e-9)) + 1) * dt
    vu = np.interp(tu, ts, vs)
    if len(vu) < 2 * ORDER:  # too short to filter meaningfully: the run is kept unfiltered
        return tu, vu
    return tu, sosfiltfilt(_sos(round(1.0 / dt, 6)), vu, padlen=min(3 * (2 * ORDER + 1), len(vu) - 1))


def check_gap_factor(gap_factor: float) -> None:
    if not (np.isfinite(gap_factor) and gap_factor >= 1.5):
        raise QuadfdiError(f"--gap-factor must be at least 1.5 (times a channel's median interval), found {gap_factor}")


def resample(t: np.ndarray, v: np.ndarray, grid: np.ndarray, angle: bool = False,
             gap_factor: float = GAP_FACTOR) -> tuple[np.ndarray, np.ndarray]:
    """Values (NaN where masked) and mask of one channel on ``grid``."""
    out = np.full(len(grid), np.nan)
    mask = np.zeros(len(grid), bool)
    ok = np.isfinite(v)
    t, v = np.asarray(t, float)[ok], np.asarray(v, float)[ok]
    if len(t) < 2:
        return out, mask
    t, first = np.unique(t, return_index=True)  # sorted, duplicated stamps dropped (keep the first)
    v = v[first]
    if angle:
        v = np.unwrap(v)
    dt = float(np.median(np.diff(t)))
    gap = gap_factor * dt
    for i0, i1 in runs(t, gap):
        if i1 <= i0:
            continue
        ts, vs = t[i0:i1 + 1], v[i0:i1 + 1]
        sel = (grid >= ts[0]) & (grid <= ts[-1])
        if not sel.any():
            continue
        if 1.0 / dt > 1.0 / GRID_DT * 1.05:
            ts, vs = _lowpass(ts, vs, dt)
        out[sel] = np.interp(grid[sel], ts, vs)
        mask[sel] = True
    if angle:
        out = np.where(mask, wrap(out), np.nan)
    return out, mask
