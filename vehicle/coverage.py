"""Does a vehicle reference cover a flight? The reference's share model was fitted on the forward speeds
and yaw rates its flights flew (``share_model.range_5_95``); beyond that range fits.predict_shares holds
the line at its edge, so a flight flown faster or turning harder than the reference flights is compared
against an extrapolation. ``coverage`` says how much of a flight lies there, per regressor.

A sample counts as outside only where its excess over the range matters (``matters``). The line ``LIMIT``:
the range is taken over the reference flights' steady samples and a flight is counted over its airborne
ones (climbs and banks included), so even a reference flight has some samples outside; the simulated
fleet's 368 reference flights (simulator seed 0) have at most 0.21 outside against their own vehicle's
reference (``python lab/reference_coverage.py RUN``, docs/vehicle.md "Does the reference cover the
flight?"). Above 0.25 a flight flies unlike every reference flight of that measurement.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.resample import GRID_DT
from quadfdi.vehicle import quantities as q
from quadfdi.vehicle.flights import Flight

LIMIT = 0.25
WHAT = {"v_forward": ("forward speed", "m/s"), "yaw_rate": ("yaw rate", "rad/s")}


def flown_text(model: dict) -> str:
    """What a share model was fitted on, as text: each regressor's 5-95 % range ("flown forward speed ...")."""
    if not model.get("motors") or not model.get("regressors"):
        return "no share model (too few steady samples)"
    return "flown " + ", ".join(f"{WHAT[n][0]} {model['range_5_95'][n][0]:.2f} to {model['range_5_95'][n][1]:.2f} "
                                f"{WHAT[n][1]}" for n in model["regressors"])


def regressor_values(fl: Flight) -> dict[str, np.ndarray]:
    """(T,) each share-model regressor of the flight, NaN where it is not logged."""
    return {"v_forward": q.forward_speed(fl), "yaw_rate": q.yaw_rate(fl)[0]}


def matters(model: dict, name: str, excess: np.ndarray) -> np.ndarray:
    """(n,) bool: where the regressor's excess over its range, through the share model's own slope, would
    move some motor's share by more than that motor's scatter about the fit (its residual std). A sample
    just past the edge of a range the reference flew only as noise (a yaw rate of a few hundredths of a
    rad/s) changes nothing the model compares, and is not counted."""
    out = np.zeros(excess.shape, bool)
    for m in model["motors"]:
        out |= np.abs(float(m[f"per_{name}"]) * excess) > float(m["residual_std"])
    return out


def coverage(fl: Flight, reference: dict) -> dict | None:
    """Per regressor of the reference's share model: its 5-95 % range, the share of this flight's airborne
    samples with all four motor commands (quantities.share_samples) past it by enough to matter
    (``matters``), and those seconds;
    ``outside`` the largest of those shares, ``beyond`` whether it passes ``LIMIT`` (``outside`` null and
    ``why`` when the flight logs none of the regressors). None when the reference holds no share model
    (too few steady samples, or neither regressor logged)."""
    model = reference["share_model"]
    if not model.get("motors") or not model.get("regressors"):
        return None
    sel = q.share_samples(fl)
    values = regressor_values(fl)
    per = {}
    for name in model["regressors"]:
        lo, hi = model["range_5_95"][name]
        x = values[name][sel]
        x = x[np.isfinite(x)]
        out = int(matters(model, name, x - np.clip(x, lo, hi)).sum())
        per[name] = {"what": WHAT[name][0], "unit": WHAT[name][1], "range_5_95": [lo, hi],
                     "outside": round(out / len(x), 4) if len(x) else None,
                     "seconds_outside": round(out * GRID_DT, 2), "seconds": round(len(x) * GRID_DT, 2)}
    fractions = [p["outside"] for p in per.values() if p["outside"] is not None]
    outside = max(fractions) if fractions else None
    out = {"regressors": per, "outside": outside, "limit": LIMIT, "beyond": outside is not None and outside > LIMIT}
    if outside is None:
        out["why"] = f"the flight logs no {' or '.join(WHAT[n][0] for n in per)} on its airborne samples"
    return out


def said(cov: dict | None) -> str | None:
    """One clause for a printed summary when the flight lies beyond ``LIMIT``; else None."""
    if not cov or not cov["beyond"]:
        return None
    worst = max((p for p in cov["regressors"].values() if p["outside"] is not None), key=lambda p: p["outside"])
    lo, hi = worst["range_5_95"]
    return (f"{worst['outside']:.0%} of its airborne samples fly a {worst['what']} outside the reference flights' "
            f"{lo:.2f} to {hi:.2f} {worst['unit']} (shares compared against the reference's edge there)")
