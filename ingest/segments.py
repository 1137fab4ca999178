"""Armed and airborne intervals, and the refusals that follow from them.

Autopilots publish state topics on change (plus a slow heartbeat), so a state sample holds until
the next one: intervals are read as step functions and end at the last data sample.
Airborne = armed AND not landed (PX4 vehicle_land_detected.landed; ArduPilot has no land
detector message, so there and whenever it is missing: the throttle-and-altitude fallback,
mean motor command above THR_AIRBORNE and height above the armed ground level above H_AIRBORNE).
"""

from __future__ import annotations

import numpy as np

from core.errors import QuadfdiError

THR_AIRBORNE = 0.15  # -: a multirotor hovers at 0.25-0.6 thrust; idle spin is below 0.1
H_AIRBORNE = 0.5  # m: above the ground level at arming, clear of ground effect and baro noise
MIN_AIRBORNE_S = 2.0  # s: the shortest flight worth ingesting (default of --min-airborne)


Intervals = list[tuple[float, float]]


def step_intervals(t: np.ndarray, on: np.ndarray, t_end: float) -> Intervals:
    """Intervals where a step signal (held from each sample to the next) is true; the last holds to t_end."""
    out: Intervals = []
    start = None
    for ti, oi in zip(np.asarray(t, float), np.asarray(on, bool)):
        if oi and start is None:
            start = ti
        elif not oi and start is not None:
            out.append((start, ti))
            start = None
    if start is not None and t_end > start:
        out.append((start, t_end))
    return out


def intersect(a: Intervals, b: Intervals) -> Intervals:
    out = []
    for a0, a1 in a:
        for b0, b1 in b:
            lo, hi = max(a0, b0), min(a1, b1)
            if hi > lo:
                out.append((lo, hi))
    return sorted(out)


def total(iv: Intervals) -> float:
    return float(sum(b - a for a, b in iv))


def fallback_airborne(t: np.ndarray, thr_mean: np.ndarray, height: np.ndarray, t_end: float) -> Intervals:
    """Throttle-and-altitude rule on a common time base (NaN counts as not airborne)."""
    with np.errstate(invalid="ignore"):
        on = (thr_mean > THR_AIRBORNE) & (height > H_AIRBORNE)
    return step_intervals(t, on, t_end)


def check_airborne(airborne: Intervals, min_airborne_s: float, span: tuple[float, float]) -> None:
    """Refuse a log that never flies or flies too briefly (one line, exit 2, nothing written)."""
    dur = span[1] - span[0]
    if not airborne:
        raise QuadfdiError(f"never airborne: no airborne segment in {dur:.1f} s of data")
    if total(airborne) < min_airborne_s:
        raise QuadfdiError(f"too short: {total(airborne):.1f} s airborne in {dur:.1f} s of data "
                           f"(at least {min_airborne_s:g} s needed; --min-airborne)")
