"""Learn a vehicle reference from healthy flights of one airframe (``quadfdi vehicle learn``): what a
healthy flight of this vehicle looks like in the quantities the models read (docs/formats.md,
"Vehicle reference"; the file: ``formats/vehicle.py``).

Refused in one line, before anything is written: flights of different vehicles (autopilot, frame,
cell count or motor map differ), the same file twice, a flight with less than ``MIN_AIRBORNE_S`` of
airborne samples with all four motor commands, flights none of which holds the hover estimate's 2 s
of steady flight. Flights that disagree (stats.py) are kept: every spread is computed over all of them,
so a disagreeing flight widens the between-flight spread, and a warning names the quantity and flight.
"""

from __future__ import annotations

from quadfdi.core import hover
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.resample import GRID_DT
from quadfdi.formats.vehicle import FORMAT_VERSION, KIND
from quadfdi.vehicle import fits
from quadfdi.vehicle import quantities as q
from quadfdi.vehicle.flights import Flight
from quadfdi.vehicle.stats import K_DISAGREE, WINDOW, combine, disagreements, flight_stat

# Five 2 s windows: the fewest whose spread (4 degrees of freedom) gives a flight's mean a standard error
# worth the name; on the Crazyflie that error is then about 0.45 x a window spread of 0.02, below the 0.01
# by which flights of one session differ. It also covers the hover estimate's 2 s settle + 2 s steady run.
MIN_AIRBORNE_S = 10.0


def vehicle_of(fl: Flight) -> dict:
    names = fl.log_motor_names
    return {"autopilot": fl.autopilot, "frame": fl.vehicle.get("frame"), "cells": fl.cells,
            "motor_map": list(fl.vehicle.get("motor_map") or []), "log_motor_names": names}


def check_flights(flights: list[Flight]) -> None:
    """One vehicle, each file once, each flight long enough: else one line naming the flight."""
    if not flights:
        raise QuadfdiError("a vehicle reference needs at least one healthy flight")
    first, ref = flights[0], vehicle_of(flights[0])
    if sorted(ref["motor_map"]) != [0, 1, 2, 3]:
        raise QuadfdiError(f"{first.name}: motor_map {ref['motor_map']!r} is not four motors (not a quadrotor flight)")
    seen = {}
    for fl in flights:
        if fl.sha256 in seen:
            raise QuadfdiError(f"{fl.name} is the same file as {seen[fl.sha256]} (sha256 {fl.sha256[:12]}); give each "
                               "flight once")
        seen[fl.sha256] = fl.name
        other = vehicle_of(fl)
        for key, what in (("autopilot", "autopilot"), ("frame", "frame"), ("cells", "cell count"),
                          ("motor_map", "motor map")):
            if other[key] != ref[key]:
                raise QuadfdiError(f"{fl.name} and {first.name} are not one vehicle: {what} {other[key]!r} against "
                                   f"{ref[key]!r}; a reference is learned from the flights of one airframe")
        sec = float(q.share_samples(fl).sum() * GRID_DT)
        if sec < MIN_AIRBORNE_S:
            raise QuadfdiError(f"{fl.name}: {sec:.1f} s airborne with all four motor commands, a vehicle reference "
                               f"needs at least {MIN_AIRBORNE_S:g} s per flight (five 2 s windows: the fewest that "
                               "give its mean share a standard error)")


def _motor_stats(per_flight_x: list, sels: list, names: list[str]) -> list[dict]:
    """Four statistics (project rotor order) of a (T, 4) quantity per flight."""
    return [dict(rotor=k + 1, log_motor=names[k], **combine([flight_stat(x[:, k], s)
                                                             for x, s in zip(per_flight_x, sels)]))
            for k in range(4)]


def _hover(flights: list[Flight]) -> dict:
    ests = [q.hover_estimate(fl) for fl in flights]
    if not any(h.ok for h in ests):
        raise QuadfdiError(f"no flight holds {hover.STEADY_SAMPLES * GRID_DT:g} s of steady flight (core.hover: "
                           f"|vz| <= {float(hover.VZ_MAX):g} m/s, tilt <= {float(hover.TILT_MAX):g} rad) after "
                           f"{hover.SETTLE_SAMPLES * GRID_DT:g} s airborne: the hover collective cannot be estimated")
    coll = [hover.collective(q.motor_commands(fl)).astype(float) for fl in flights]
    return {"cmd": fits.summary([float(h.cmd) if h.ok else None for h in ests]),
            "cur_a": fits.summary([float(h.cur) if h.ok and h.cur == h.cur else None for h in ests]),
            "freeze_s": [float(fl.arrays["time"][h.freeze]) if h.ok else None for fl, h in zip(flights, ests)],
            "collective": combine([flight_stat(c, q.steady(fl)) for c, fl in zip(coll, flights)])}


def _battery(flights: list[Flight]) -> dict | None:
    per = [fits.battery_flight(fl) for fl in flights]
    if any(p is None for p in per):
        return None
    if len({p["mode"] for p in per}) > 1:  # one model for all: the current only where every flight has it
        per = [fits.battery_flight(fl, with_current=False) for fl in flights]
    keys = ("v0", "drift_v_per_min", "level", "residual_std") + (("sag_v_per_a",) if per[0]["mode"] == "sag" else ())
    return {"cells": flights[0].cells, "mode": per[0]["mode"], **{k: fits.summary([p[k] for p in per]) for k in keys},
            "flights": per}


def _vibration(flights: list[Flight]) -> dict:
    out = {}
    for name in ("vib_px4", "vib_ap"):
        if not all(fl.usable(name) for fl in flights):
            continue
        per = [fits.vibration_flight(fl, name) for fl in flights]
        level = combine([flight_stat(fl.col(name), fl.airborne) for fl in flights])
        out[name] = {"unit": "m/s^2", "level": level, **{k: fits.summary([p[k] if p else None for p in per])
                                                         for k in ("floor", "per_collective", "residual_std")}}
    return out


def _esc(flights: list[Flight], names: list[str]) -> dict:
    per = [q.esc_quantities(fl) for fl in flights]
    common = [k for k in per[0] if all(k in p for p in per)]
    sels = [fl.airborne for fl in flights]
    return {k: {"unit": per[0][k][1], "motors": _motor_stats([p[k][0] for p in per], sels, names)} for k in common}


def _motor_temp(flights: list[Flight], names: list[str]) -> list[dict] | None:
    """Airborne motor temperature offsets (K) when every flight logs T1..T4 (simulated flights), else None."""
    per = [q.motor_temp_offsets(fl) for fl in flights]
    return None if any(p is None for p in per) else _motor_stats(per, [fl.airborne for fl in flights], names)


def _warnings(ref: dict, flights: list[Flight]) -> list[str]:
    """One line per quantity on which flights disagree (stats.disagreements), naming each such flight."""
    checked = [(f"motor {m['log_motor']} command share", m) for m in ref["motor_share"]]
    checked.append(("hover collective (steady samples)", ref["hover"]["collective"]))
    checked += [(f"{name} level", v["level"]) for name, v in ref["vibration"].items()]
    checked += [(f"ESC {key} of motor {m['log_motor']}", m) for key, v in ref["esc"].items() for m in v["motors"]]
    out = []
    for what, stat in checked:
        found = disagreements(stat["flights"])
        if found:
            each = "; ".join(f"{flights[d['flight']].name} {d['mean']:.4g} against {d['others']:.4g} "
                             f"({d['z']:.1f} x {d['spread']:.2g})" for d in found)
            out.append(f"{what}: flights disagree beyond {K_DISAGREE:g} x the spread their noise gives: {each}; kept, "
                       "they widen the between-flight spread")
    return out


def learn(flights: list[Flight]) -> dict:
    """The reference (formats/vehicle.py) of the flights' vehicle; QuadfdiError (one line) when refused."""
    check_flights(flights)
    veh = vehicle_of(flights[0])
    names = [veh["log_motor_names"][m] for m in veh["motor_map"]]  # the log's name of project rotor k
    sels = [q.share_samples(fl) for fl in flights]
    ref = {
        "format_version": FORMAT_VERSION, "kind": KIND, "vehicle": veh,
        "flights": [{"file": fl.name, "sha256": fl.sha256, "log_file": str(fl.arrays["log_file"]),
                     "log_sha256": str(fl.arrays["log_sha256"]),
                     "airborne_s": round(float(fl.airborne.sum() * GRID_DT), 2)}
                    for fl in flights],
        "settings": {"min_airborne_s": MIN_AIRBORNE_S, "window_s": WINDOW * GRID_DT, "disagreement_k": K_DISAGREE,
                     "share_samples": "airborne, all four motor commands logged, collective >= "
                                      f"{q.CMD_MIN:g}", "min_fit_s": fits.MIN_FIT_SAMPLES * GRID_DT},
        "motor_share": _motor_stats([q.motor_shares(fl) for fl in flights], sels, names),
        "share_model": fits.share_model(flights, names),
        "hover": _hover(flights), "battery": _battery(flights), "vibration": _vibration(flights),
        "esc": _esc(flights, names), "motor_temp": _motor_temp(flights, names),
    }
    ref["warnings"] = _warnings(ref, flights)
    return ref
