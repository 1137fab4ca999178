"""One flight beside a vehicle reference: the quantities ``learn`` describes, computed on this flight with
the same code (quantities.py, fits.py, stats.py), each against what the reference expects of it at the
flight's own operating point, and the four share rules (rules.py).

Each quantity is an *entry*: ``value`` (this flight), ``reference`` (what the reference gives for it),
``deviation`` (value - reference), ``spread`` (the reference's between-flight std of that quantity; null
for a reference of one flight) and ``z`` (deviation / spread: how many of the vehicle's own day-to-day
changes the flight is away; null without a spread).

- ``motor_share``, per project rotor (and the log's name of that motor): the mean share over the flight's
  steady samples (core.hover's test, the samples the share model was fitted on) against the mean over the
  same samples of the reference's share model at each sample's forward speed and yaw rate
  (fits.predict_shares): a reference flight scores 0 against a reference of itself, where its airborne mean
  (climbs and banks included) would not. A flight with under 4 s of such samples (a regressor not logged:
  no yaw) is compared on its airborne samples (quantities.share_samples) with the reference's airborne mean
  share (``basis`` says which; ``airborne``: the flight's airborne mean share, the rules' input). Spread:
  the reference's between-flight std of the airborne mean share.
- ``hover_collective``: core.hover's estimate on this flight against the reference flights' estimates.
- ``sag_v_per_a_cell``: the pack's voltage drop per ampere per cell (fits.battery_flight), when the
  reference's flights and this one log a current that moves; else null with ``why``.
- ``vibration``, per metric the reference holds: the airborne mean against the reference's floor + slope x
  this flight's mean collective over the same samples; spread: the std of that prediction over the
  reference flights' own fits.
- ``esc``, per ESC quantity both log: per motor, the airborne mean against the reference's mean.
- ``coverage`` (coverage.py): how much of the flight flies a forward speed or yaw rate outside what the
  reference flights flew, where the share model is held at its edge.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.hover import collective
from quadfdi.core.resample import GRID_DT
from quadfdi.vehicle import fits
from quadfdi.vehicle.coverage import coverage
from quadfdi.vehicle import quantities as q
from quadfdi.vehicle.flights import Flight
from quadfdi.vehicle.rules import check_same_vehicle, score_flight, thresholds
from quadfdi.vehicle.stats import flight_stat

VERSION = 2


def entry(value: float | None, reference: float | None, spread: float | None, unit: str, **extra) -> dict:
    dev = None if value is None or reference is None else float(value) - float(reference)
    z = None if dev is None or not spread else dev / float(spread)
    return {"value": value, "reference": reference, "deviation": dev, "spread": spread, "z": z, "unit": unit, **extra}


def share_series(fl: Flight, reference: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(T, 4) shares (NaN where not spinning), (T, 4) the reference's shares at each sample's operating
    point, project rotor order, and (T,) bool where that came from the share model: where a regressor is
    not logged (or the reference has no model) the reference's airborne mean share stands in."""
    shares = q.motor_shares(fl)
    mean = np.broadcast_to(np.array([m["mean"] for m in reference["motor_share"]], float), shares.shape)
    ref = fits.predict_shares(reference["share_model"], fl)
    modelled = np.zeros(len(shares), bool) if ref is None else np.isfinite(ref).all(axis=1)
    return shares, np.where(modelled[:, None], ref if ref is not None else mean, mean), modelled


def _motor_share(fl: Flight, reference: dict, shares: np.ndarray, ref: np.ndarray, modelled: np.ndarray) -> list[dict]:
    air = q.share_samples(fl)
    steady = air & q.steady(fl) & modelled
    if steady.sum() >= fits.MIN_FIT_SAMPLES:
        sel, basis, expect = steady, "steady samples against the share model", ref
    else:
        sel, basis = air, "airborne samples against the reference's airborne mean share"
        expect = np.broadcast_to(np.array([m["mean"] for m in reference["motor_share"]], float), shares.shape)
    out = []
    for k, m in enumerate(reference["motor_share"]):
        val, exp = flight_stat(shares[:, k], sel)["mean"], flight_stat(expect[:, k], sel)["mean"]
        out.append(entry(val, exp, m["between_std"], "-", rotor=k + 1, log_motor=m["log_motor"], basis=basis,
                         seconds=round(float(sel.sum() * GRID_DT), 2), airborne=flight_stat(shares[:, k], air)["mean"]))
    return out


def _hover(fl: Flight, reference: dict) -> dict:
    h, ref = q.hover_estimate(fl), reference["hover"]["cmd"]
    return entry(float(h.cmd) if h.ok else None, ref["mean"], ref["between_std"], "command")


def _sag(fl: Flight, reference: dict) -> dict:
    bat = reference.get("battery")
    if not bat or bat["mode"] != "sag":
        return entry(None, None, None, "V/A/cell", why="the reference's flights log no current that moves")
    mine = fits.battery_flight(fl)
    if mine is None or mine["mode"] != "sag":
        return entry(None, bat["sag_v_per_a"]["mean"], bat["sag_v_per_a"]["between_std"], "V/A/cell",
                     why="this flight logs no pack voltage, cell count or current that moves")
    return entry(mine["sag_v_per_a"], bat["sag_v_per_a"]["mean"], bat["sag_v_per_a"]["between_std"], "V/A/cell")


def vibration_floor(ref: dict, coll):
    """A vibration metric's reference floor at collective ``coll`` (a number or an array): the mean floor
    plus the mean slope per collective; None when the reference flights held no floor."""
    if ref["floor"]["mean"] is None:
        return None
    return ref["floor"]["mean"] + ref["per_collective"]["mean"] * coll


def _vibration(fl: Flight, reference: dict) -> dict:
    out = {}
    coll = collective(q.motor_commands(fl)).astype(np.float64)
    for name, ref in reference["vibration"].items():
        vib = fl.col(name)
        sel = fl.airborne & np.isfinite(vib) & np.isfinite(coll)
        if not sel.any():
            out[name] = entry(None, None, ref["level"]["between_std"], "m/s^2", why=f"{name} not logged airborne")
            continue
        c = float(coll[sel].mean())
        per = [(f, s) for f, s in zip(ref["floor"]["flights"], ref["per_collective"]["flights"])
               if f is not None and s is not None]
        preds = [f + s * c for f, s in per]
        spread = float(np.std(preds, ddof=1)) if len(preds) >= 2 else ref["level"]["between_std"]
        exp = vibration_floor(ref, c)
        out[name] = entry(float(vib[sel].mean()), exp, spread, "m/s^2", collective=c)
    return out


def _esc(fl: Flight, reference: dict) -> dict:
    mine, out = q.esc_quantities(fl), {}
    for key, ref in reference["esc"].items():
        if key in mine:
            x, unit = mine[key]
            out[key] = [entry(flight_stat(x[:, k], fl.airborne)["mean"], m["mean"], m["between_std"], unit,
                              rotor=k + 1, log_motor=m["log_motor"]) for k, m in enumerate(ref["motors"])]
    return out


def largest_deviation(motor_share: list[dict]) -> dict | None:
    """The motor whose share deviates most from the reference (absolute), as the log names it."""
    ok = [m for m in motor_share if m["deviation"] is not None]
    if not ok:
        return None
    m = max(ok, key=lambda e: abs(e["deviation"]))
    return {k: m[k] for k in ("rotor", "log_motor", "deviation", "z")}


def compare(fl: Flight, reference: dict) -> tuple[dict, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(the flight's quantities against the reference (module docstring), share_series' three arrays);
    QuadfdiError (one line) when the flight is not the reference's vehicle or has no airborne share."""
    check_same_vehicle(fl, reference)
    shares, ref, modelled = share_series(fl, reference)
    limits = thresholds(reference)
    rules = score_flight(fl, reference, limits)["rules"]
    motor = _motor_share(fl, reference, shares, ref, modelled)
    own = {f.get("log_sha256") for f in reference["flights"]}
    out = {"version": VERSION, "learned_from": [f["file"] for f in reference["flights"]],
           "reference_flight": str(fl.arrays["log_sha256"]) in own,
           "share_model": bool(reference["share_model"].get("motors")),
           "coverage": coverage(fl, reference), "motor_share": motor, "largest_deviation": largest_deviation(motor),
           "hover_collective": _hover(fl, reference),
           "sag_v_per_a_cell": _sag(fl, reference), "vibration": _vibration(fl, reference), "esc": _esc(fl, reference),
           "rules": {name: dict(r, threshold=limits[name]["threshold"]) for name, r in rules.items()}}
    return out, (shares, ref, modelled)
