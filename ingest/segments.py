"""Armed and airborne intervals, and the refusals that follow from them.

Autopilots publish state topics on change (plus a slow heartbeat), so a state sample holds until
the next one: intervals are read as step functions and end at the last data sample.
Airborne = armed AND not landed (PX4 vehicle_land_detected.landed; ArduPilot has no land
detector message, so there and whenever it is missing: the throttle-and-altitude fallback,
mean motor command above THR_AIRBORNE and height above the armed ground level above H_AIRBORNE).

Each airborne interval that ends in a landing (before the data ends) is then cut back to the
touchdown (``end_at_touchdown``): a land detector declares "landed" only after its conditions
(low thrust, no vertical motion) have held for a while (PX4: LNDMC_TRIG_TIME, default 1 s, once the
thrust has ramped down), so its last "airborne" second holds the impact and the
spin-down on the ground, which no simulated flight has. The mission log measures it: descending at
0.6 m/s until 41.44 s, arrested at 41.52 s, ``ground_contact`` 42.23 s, ``landed`` 42.85 s.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.errors import QuadfdiError

THR_AIRBORNE = 0.15  # -: a multirotor hovers at 0.25-0.6 thrust; idle spin is below 0.1
H_AIRBORNE = 0.5  # m: above the ground level at arming, clear of ground effect and baro noise
MIN_AIRBORNE_S = 2.0  # s: the shortest flight worth ingesting (default of --min-airborne)
V_TOUCHDOWN = 0.3  # m/s: a descent at least this fast is still in free air (PX4's MPC_LAND_CRWL default)
LANDING_LOOKBACK_S = 3.0  # s: bounds the land detector's lag behind touchdown (module docstring: 1.0-2.4 s measured)


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


def end_at_touchdown(airborne: Intervals, t: np.ndarray, vz_up: np.ndarray, t_end: float) -> Intervals:
    """Each interval ending before ``t_end`` (a landing) ends instead at the last sample of the
    LANDING_LOOKBACK_S before its end where the vehicle still descended at V_TOUCHDOWN or faster
    (``vz_up`` up-positive, m/s, at times ``t``); with no such sample (a landing too gentle to see,
    or no vertical speed logged) it loses the whole lookback. Never lengthens an interval; drops
    one left empty."""
    t, vz_up = np.asarray(t, float), np.asarray(vz_up, float)
    out: Intervals = []
    for a, b in airborne:
        if b < t_end:
            lo = max(a, b - LANDING_LOOKBACK_S)
            with np.errstate(invalid="ignore"):
                falling = (t >= lo) & (t <= b) & (-vz_up >= V_TOUCHDOWN)
            b = float(t[falling][-1]) if falling.any() else lo
        if b > a:
            out.append((a, b))
    return out


def cut_landings(lr) -> None:
    """``end_at_touchdown`` on a LogRead's airborne intervals with its ``vz`` channel (in place); nothing
    for a log whose airborne rule ends at touchdown itself (``landing_lag`` False)."""
    if not lr.airborne or not lr.landing_lag:
        return
    vz = lr.channels.get("vz")
    t, v = (vz.t, vz.v) if vz is not None else (np.zeros(0), np.zeros(0))
    lr.airborne = end_at_touchdown(lr.airborne, t, v, lr.data_span[1])
    lr.airborne_source += (f"; each landing cut back to the last descent at >= {V_TOUCHDOWN} m/s in the "
                           f"{LANDING_LOOKBACK_S:g} s before it (touchdown)")


MAX_MIN_AIRBORNE_S = 24 * 3600.0  # s: --min-airborne above a day is a typo


def check_min_airborne(min_airborne_s: float) -> None:
    if not (np.isfinite(min_airborne_s) and 0.0 <= min_airborne_s <= MAX_MIN_AIRBORNE_S):
        raise QuadfdiError(f"--min-airborne must be a number of seconds in [0, {MAX_MIN_AIRBORNE_S:g}], "
                           f"found {min_airborne_s}")


def check_airborne(airborne: Intervals, min_airborne_s: float, span: tuple[float, float]) -> None:
    """Refuse a log that never flies or flies too briefly (one line, exit 2, nothing written)."""
    dur = span[1] - span[0]
    if not airborne:
        raise QuadfdiError(f"never airborne: no airborne segment in {dur:.1f} s of data")
    if total(airborne) < min_airborne_s:
        raise QuadfdiError(f"too short: {total(airborne):.1f} s airborne in {dur:.1f} s of data "
                           f"(at least {min_airborne_s:g} s needed; --min-airborne)")
