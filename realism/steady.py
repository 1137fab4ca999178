"""Steady segments: hover or constant-velocity flight, found automatically on the 25 Hz grid.

A sample is steady when, smoothed over SMOOTH_S: tilt below TILT_MAX, yaw rate below YAW_RATE_MAX,
horizontal acceleration (derivative of the smoothed velocity) below ACC_MAX and vertical speed
below VZ_MAX. A channel the flight lacks drops its criterion (said in the segment's ``criteria``).
Segments are maximal runs of steady samples lasting at least ``min_s`` (20 s for real flights).
Hover: mean horizontal speed below HOVER_SPEED; else constant velocity.
"""

from __future__ import annotations

import numpy as np

SMOOTH_S = 2.0  # s: manoeuvres shorter than this are control activity, not a change of flight phase
TILT_MAX = 0.26  # rad (15 deg): a multirotor cruising steadily leans less than this
YAW_RATE_MAX = 0.35  # rad/s
ACC_MAX = 0.8  # m/s^2: the simulator's references reach up to 1.5 m/s^2 only at their peaks
VZ_MAX = 0.6  # m/s
HOVER_SPEED = 0.5  # m/s


def _smooth(v: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over n samples; NaN where any input in the window is NaN."""
    if n <= 1 or len(v) < n:
        return v.copy()
    c = np.convolve(np.nan_to_num(v), np.ones(n) / n, mode="same")
    bad = np.convolve(~np.isfinite(v), np.ones(n), mode="same") > 0
    return np.where(bad, np.nan, c)


def steady_mask(t: np.ndarray, ch: dict[str, np.ndarray], base: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Per-sample steadiness and the criteria used; ``ch`` maps channel -> grid values (NaN = masked)."""
    dt = float(np.median(np.diff(t)))
    n = max(1, int(round(SMOOTH_S / dt)))
    ok = base.copy()
    used = []
    with np.errstate(invalid="ignore"):
        if "roll" in ch and "pitch" in ch:
            ok &= _smooth(np.hypot(ch["roll"], ch["pitch"]), n) < TILT_MAX
            used.append(f"tilt < {TILT_MAX} rad")
        if "r" in ch:
            ok &= np.abs(_smooth(ch["r"], n)) < YAW_RATE_MAX
            used.append(f"|r| < {YAW_RATE_MAX} rad/s")
        if "vx" in ch and "vy" in ch:
            ax = np.gradient(_smooth(ch["vx"], n), dt)
            ay = np.gradient(_smooth(ch["vy"], n), dt)
            ok &= np.hypot(ax, ay) < ACC_MAX
            used.append(f"horizontal acceleration < {ACC_MAX} m/s^2")
        if "vz" in ch:
            ok &= np.abs(_smooth(ch["vz"], n)) < VZ_MAX
            used.append(f"|vz| < {VZ_MAX} m/s")
    return ok, used


def segments(t: np.ndarray, ch: dict[str, np.ndarray], base: np.ndarray, min_s: float) -> list[dict]:
    """Steady segments of at least min_s: start, end, kind, mean speed and the criteria applied."""
    ok, used = steady_mask(t, ch, base)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    out = []
    for i0, i1 in zip(edges[::2], edges[1::2]):
        if t[i1 - 1] - t[i0] + 1e-9 < min_s:
            continue
        speed = float(np.nanmean(np.hypot(ch["vx"][i0:i1], ch["vy"][i0:i1]))) if "vx" in ch else float("nan")
        kind = "hover" if speed < HOVER_SPEED else "constant velocity" if np.isfinite(speed) else "steady attitude"
        out.append({"start_s": float(t[i0]), "end_s": float(t[i1 - 1]), "kind": kind, "mean_speed_ms": speed,
                    "i0": int(i0), "i1": int(i1), "criteria": used})
    return out
