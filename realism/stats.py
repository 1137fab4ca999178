"""Per-channel statistics of one signal on steady segments, the same for real and simulated data.

noise: std of the high-passed signal at the channel's logged rate. The high-pass is the first
difference of consecutive samples divided by sqrt(2): for white noise it returns the noise std,
and a steady flight's slow motion (well below the logged rate) contributes almost nothing to it.
Pairs across a gap (interval above 3 x the median) are skipped.
psd: Welch spectrum of the 25 Hz grid signal (Hann, NPERSEG samples, linear trend removed per
segment), averaged over segments; hf_rms: sqrt of its integral over HF_BAND.
"""

from __future__ import annotations

import numpy as np

NPERSEG = 128  # 5.12 s at 25 Hz: 0.2 Hz resolution, at least 3 averages in a 20 s segment
HF_BAND = (1.0, 10.0)  # Hz: control activity and vibration, above the flight manoeuvres


def hp_noise(t: np.ndarray, v: np.ndarray, windows: list[tuple[float, float]]) -> tuple[float, int]:
    """Noise std at the logged rate (first-difference high-pass) over the windows, and the number of pairs."""
    if len(t) < 3:
        return float("nan"), 0
    dt = np.diff(t)
    gap = 3.0 * np.median(dt[dt > 0]) if np.any(dt > 0) else 0.0
    inside = np.zeros(len(t), bool)
    for a, b in windows:
        inside |= (t >= a) & (t <= b)
    pair = inside[1:] & inside[:-1] & (dt > 0) & (dt <= gap)
    d = np.diff(v)[pair]
    d = d[np.isfinite(d)]
    if len(d) < 10:
        return float("nan"), int(len(d))
    return float(np.std(d) / np.sqrt(2.0)), int(len(d))


def psd(grid_v: np.ndarray, runs: list[tuple[int, int]], fs: float = 25.0) -> tuple[np.ndarray, np.ndarray] | None:
    """Welch PSD averaged over the index runs [i0, i1) of a grid signal (NaN runs skipped)."""
    from scipy.signal import welch

    acc, n = None, 0
    for i0, i1 in runs:
        seg = grid_v[i0:i1]
        fin = np.flatnonzero(np.isfinite(seg))
        seg = seg[fin[0]:fin[-1] + 1] if len(fin) else seg[:0]  # masked grid ends (log started late) are cut
        if len(seg) < NPERSEG or not np.isfinite(seg).all():
            continue
        f, p = welch(seg, fs=fs, nperseg=NPERSEG, detrend="linear")
        acc = p * len(seg) if acc is None else acc + p * len(seg)
        n += len(seg)
    return None if acc is None else (f, acc / n)


def hf_rms(spec: tuple[np.ndarray, np.ndarray] | None) -> float:
    if spec is None:
        return float("nan")
    f, p = spec
    band = (f >= HF_BAND[0]) & (f <= HF_BAND[1])
    return float(np.sqrt(np.trapezoid(p[band], f[band])))


def log_like(t_sim: np.ndarray, v_sim: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """A simulated 25 Hz signal as a logger at ``rate_hz`` would record it: the latest sample at each
    logging instant (zero-order hold, no filter: what uORB/DataFlash logging does). The simulator
    cannot be logged faster than it samples, so rates above 25 Hz are capped at its rate."""
    dt_sim = float(t_sim[1] - t_sim[0])
    rate = min(rate_hz, 1.0 / dt_sim) if rate_hz > 0 else 1.0 / dt_sim
    tl = np.arange(t_sim[0], t_sim[-1] + 1e-9, 1.0 / rate)
    idx = np.clip(np.searchsorted(t_sim, tl + 1e-9, side="right") - 1, 0, len(t_sim) - 1)
    return tl, v_sim[idx]
