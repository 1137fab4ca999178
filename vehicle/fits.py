"""The small least-squares models of a vehicle reference: each motor's share against forward speed and
yaw rate, the pack's per-cell voltage against current (or time), the vibration floor against thrust.

Every fit is ordinary least squares (``numpy.linalg.lstsq``) on the rows where the response and every
regressor are finite, and reports its rows' seconds and the residual std (the spread it leaves).
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.hover import collective
from quadfdi.core.resample import GRID_DT
from quadfdi.vehicle import quantities as q
from quadfdi.vehicle.flights import Flight
from quadfdi.vehicle.stats import WINDOW

MIN_FIT_SAMPLES = 2 * WINDOW  # 4 s: fewer rows leave a slope to two or three window means
MIN_CURRENT_RANGE_A = 1.0  # a sag slope needs the current to move; less and it fits the sensor's noise


def lstsq(y: np.ndarray, cols: list[np.ndarray]) -> tuple[list[float], float, int] | None:
    """Coefficients [intercept, one per column], residual std and rows used; None with too few rows."""
    x = np.stack([np.ones_like(y)] + cols, axis=1)
    ok = np.isfinite(y) & np.isfinite(x).all(axis=1)
    if ok.sum() < max(MIN_FIT_SAMPLES, x.shape[1] + 1):
        return None
    coef = np.linalg.lstsq(x[ok], y[ok], rcond=None)[0]
    resid = y[ok] - x[ok] @ coef
    return [float(c) for c in coef], float(np.std(resid, ddof=x.shape[1])), int(ok.sum())


def summary(values: list[float | None]) -> dict:
    """A per-flight coefficient over the flights: ``mean``, ``between_std`` (ddof 1), ``flights``."""
    v = np.array([x for x in values if x is not None])
    return {"mean": float(v.mean()) if len(v) else None,
            "between_std": float(np.std(v, ddof=1)) if len(v) >= 2 else None, "flights": values}


def _range(x: np.ndarray) -> list[float] | None:
    x = x[np.isfinite(x)]
    return [float(np.percentile(x, 5)), float(np.percentile(x, 95))] if len(x) else None


def share_model(flights: list[Flight], log_names: list[str]) -> dict:
    """share_k = a + b v_forward + c yaw_rate per motor, pooled over the flights' steady samples.

    Steady samples (core.hover's test): in a climb, a descent or a steep bank the shares carry the
    controller's transient torques, and the first 2 s after a take-off hold spool-up and ground effect;
    the steady rest is where the airframe's own thrust distribution shows. A regressor a flight does not
    log (no yaw: no forward speed) is dropped for every flight, so one model holds for all."""
    rows = []
    sources = set()
    for fl in flights:
        sel = q.steady(fl)
        rate, src = q.yaw_rate(fl)
        sources.add(src)
        rows.append((q.motor_shares(fl)[sel], q.forward_speed(fl)[sel], rate[sel]))
    shares = np.concatenate([r[0] for r in rows])
    regs = {"v_forward": np.concatenate([r[1] for r in rows]), "yaw_rate": np.concatenate([r[2] for r in rows])}
    # a regressor counts as logged by a flight when it is finite on most of its steady samples
    used = [n for i, n in enumerate(regs) if all(np.isfinite(r[i + 1]).mean() > 0.5 for r in rows if len(r[0]))]
    out = {"regressors": used, "units": {"v_forward": "m/s", "yaw_rate": "rad/s"},
           "yaw_rate_source": sorted(sources), "samples": "steady (core.hover: settled 2 s after take-off, "
           "|vz| <= 0.5 m/s, |roll|, |pitch| <= 0.25 rad, collective >= 0.05)",
           "range_5_95": {n: _range(regs[n]) for n in used}, "motors": []}
    for k in range(4):
        fit = lstsq(shares[:, k], [regs[n] for n in used])
        if fit is None:
            return dict(out, motors=None, why=f"fewer than {MIN_FIT_SAMPLES * GRID_DT:g} s of steady samples")
        coef, resid, n = fit
        out["motors"].append({"rotor": k + 1, "log_motor": log_names[k], "intercept": coef[0],
                              **{f"per_{name}": c for name, c in zip(used, coef[1:])},
                              "residual_std": resid, "seconds": round(n * GRID_DT, 2)})
    return out


def _airborne_minutes(fl: Flight) -> np.ndarray:
    t = np.asarray(fl.arrays["time"], np.float64)
    air = fl.airborne
    return (t - (t[air][0] if air.any() else t[0])) / 60.0


def battery_flight(fl: Flight, with_current: bool = True) -> dict | None:
    """One flight's per-cell voltage model on airborne samples: with a usable current sensor
    V_cell = v0 + sag * I + drift * t (the drift term takes the discharge, which over a long flight
    rises with the current and would otherwise steepen the sag); without, V_cell = v0 + drift * t."""
    cells = fl.cells
    if not fl.usable("V_b") or not cells:
        return None
    v = np.where(fl.airborne, fl.col("V_b") / cells, np.nan)
    t = _airborne_minutes(fl)
    cur = np.where(fl.airborne, fl.col("I_b"), np.nan)
    finite = cur[np.isfinite(cur)]
    use_current = with_current and fl.usable("I_b") and finite.size > 0 and np.ptp(finite) >= MIN_CURRENT_RANGE_A
    fit = lstsq(v, [cur, t] if use_current else [t])
    if fit is None:
        return None
    coef, resid, n = fit
    out = {"mode": "sag" if use_current else "level", "v0": coef[0], "drift_v_per_min": coef[-1],
           "residual_std": resid, "level": float(np.nanmean(v)), "seconds": round(n * GRID_DT, 2)}
    if use_current:
        out.update(sag_v_per_a=coef[1], current_range_a=_range(cur))
    return out


def vibration_flight(fl: Flight, name: str) -> dict | None:
    """One flight's vibration floor against thrust on airborne samples: vib = floor + slope * collective."""
    if not fl.usable(name):
        return None
    vib = np.where(fl.airborne, fl.col(name), np.nan)
    fit = lstsq(vib, [collective(q.motor_commands(fl)).astype(np.float64)])
    if fit is None:
        return None
    coef, resid, n = fit
    return {"floor": coef[0], "per_collective": coef[1], "residual_std": resid, "seconds": round(n * GRID_DT, 2)}


def predict_shares(model: dict, fl: Flight) -> np.ndarray | None:
    """(T, 4) each motor's share that ``share_model``'s fit gives at the flight's own forward speed and yaw
    rate, each regressor clipped to the 5-95 % range the reference flew (a line is not extrapolated beyond
    what it saw); NaN where a regressor is missing; None when the reference holds no fit."""
    if not model.get("motors"):
        return None
    regs = {"v_forward": q.forward_speed(fl), "yaw_rate": q.yaw_rate(fl)[0]}
    out = np.empty((len(fl.arrays["time"]), 4))
    for k, m in enumerate(model["motors"]):
        y = np.full(len(out), float(m["intercept"]))
        for name in model["regressors"]:
            lo, hi = model["range_5_95"][name]
            y = y + float(m[f"per_{name}"]) * np.clip(regs[name], lo, hi)
        out[:, k] = y
    return out
