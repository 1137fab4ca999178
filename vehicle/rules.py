"""The simple reference rules: four scores of a flight's airborne mean motor command shares, the bars a
network must beat on real damage (docs/vehicle.md).

A flight's share of motor k is the mean over its airborne samples (all four commands logged, the
collective spinning) of ``thr_k / mean(thr)``. Each rule takes the largest over the four motors and
names that motor (the log's own name):

| rule | score | the vehicle's healthy state |
|---|---|---|
| ``abs_sym`` | max_k abs(share_k - 1) | ignored: a symmetric quad shares 1.0 each |
| ``pos_sym`` | max_k (share_k - 1) | ignored |
| ``abs_ref`` | max_k abs(share_k - ref_k) | the reference's mean share of motor k |
| ``pos_ref`` | max_k (share_k - ref_k) | the reference's mean share of motor k |

The signed rules look for a motor that works harder than it should: a damaged or debris-laden
propeller makes less thrust per command, so the controller commands its motor more.

**Thresholds**, fixed before any damaged flight is scored: the larger of (a) ``MARGIN`` x the largest
score over the reference's own flights (their mean shares are in the reference) and (b) a noise floor,
``K_FLOOR`` x sqrt(2) x the standard error of a flight's mean share (the reference's ``se``, largest over
the motors): the difference of two flight means that noise alone passes about once in 400. (b) decides
for a reference of one flight, which scores 0 against itself. ``MARGIN`` = 1.5 because a few reference
flights do not show the largest healthy score (a fifth healthy flight beats the largest of four with
probability 1/5 when they are exchangeable); how well it holds is measured, not assumed: the healthy
test flights' alarms are false alarms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.vehicle import quantities as q
from quadfdi.vehicle.flights import Flight
from quadfdi.vehicle.learn import vehicle_of
from quadfdi.vehicle.stats import flight_stat

MARGIN = 1.5
K_FLOOR = 3.0


@dataclass(frozen=True)
class Rule:
    name: str
    signed: bool  # largest positive deviation (True) or largest absolute deviation
    with_reference: bool
    what: str


RULES = (
    Rule("abs_sym", False, False, "largest abs(share - 1) (no reference: a symmetric quad)"),
    Rule("pos_sym", True, False, "largest share - 1 (no reference)"),
    Rule("abs_ref", False, True, "largest abs(share - reference share)"),
    Rule("pos_ref", True, True, "largest share - reference share"),
)


def baseline(rule: Rule, reference: dict) -> np.ndarray:
    """(4,) the share each motor is held against: the reference's means, or 1.0."""
    return np.array([m["mean"] for m in reference["motor_share"]]) if rule.with_reference else np.ones(4)


def score(rule: Rule, shares: np.ndarray, reference: dict) -> tuple[float, int]:
    """(score, project rotor index 0..3 of the motor it names) of a flight's (4,) mean shares."""
    d = np.asarray(shares, float) - baseline(rule, reference)
    d = d if rule.signed else np.abs(d)
    k = int(np.argmax(d))
    return float(d[k]), k


def reference_shares(reference: dict) -> np.ndarray:
    """(flights, 4) the reference flights' own mean shares."""
    return np.array([[m["flights"][i]["mean"] for m in reference["motor_share"]]
                     for i in range(len(reference["flights"]))], float)


def thresholds(reference: dict) -> dict[str, dict]:
    """Each rule's threshold and what it came from (module docstring)."""
    se = max((m["se"] for m in reference["motor_share"] if m["se"] is not None), default=None)
    floor = K_FLOOR * math.sqrt(2.0) * se if se is not None else 0.0
    own = reference_shares(reference)
    out = {}
    for rule in RULES:
        scores = [score(rule, s, reference)[0] for s in own]
        i = int(np.argmax(scores))
        out[rule.name] = {"threshold": max(MARGIN * scores[i], floor), "largest_reference_score": scores[i],
                          "reference_flight": reference["flights"][i]["file"], "noise_floor": floor, "margin": MARGIN,
                          "what": rule.what}
    return out


def check_same_vehicle(fl: Flight, reference: dict) -> None:
    """A flight of another vehicle is not scored against this reference (one line naming the field)."""
    mine, ref = vehicle_of(fl), reference["vehicle"]
    for key in ("autopilot", "frame", "cells", "motor_map"):
        if mine[key] != ref[key]:
            raise QuadfdiError(f"{fl.name}: not the reference's vehicle ({key} {mine[key]!r} against {ref[key]!r})")


def flight_shares(fl: Flight) -> tuple[np.ndarray, float]:
    """(4,) airborne mean shares in project rotor order, and the seconds they rest on."""
    sh, sel = q.motor_shares(fl), q.share_samples(fl)
    stats = [flight_stat(sh[:, k], sel) for k in range(4)]
    if stats[0]["mean"] is None:
        raise QuadfdiError(f"{fl.name}: no airborne sample with all four motor commands logged")
    return np.array([s["mean"] for s in stats]), stats[0]["seconds"]


def score_flight(fl: Flight, reference: dict, limits: dict[str, dict]) -> dict:
    """One flight's shares (log motor order and names), each rule's score, alarm and motor named."""
    check_same_vehicle(fl, reference)
    shares, seconds = flight_shares(fl)
    veh = reference["vehicle"]
    names = [veh["log_motor_names"][m] for m in veh["motor_map"]]
    row = {"flight": fl.name, "sha256": fl.sha256, "airborne_s": seconds,
           "shares": {names[k]: float(shares[k]) for k in np.argsort(veh["motor_map"])}, "rules": {}}
    for rule in RULES:
        s, k = score(rule, shares, reference)
        row["rules"][rule.name] = {"score": s, "motor": names[k], "alarm": bool(s > limits[rule.name]["threshold"])}
    return row


def score_paths(paths: list[str], reference: dict) -> tuple[list[dict], list[Path], list[dict]]:
    """Every flight given or found in a folder given, scored: (rows, their paths, not scored with the
    one-line reason: a refused log, another vehicle). A path that does not exist raises."""
    from quadfdi.vehicle.flights import find_flights, read_flight

    limits = thresholds(reference)
    rows, done, refused = [], [], []
    for path, name in find_flights(paths):
        try:
            rows.append(score_flight(read_flight(path, name), reference, limits))
            done.append(path)
        except QuadfdiError as exc:
            refused.append({"flight": name, "reason": str(exc)})
    return rows, done, refused
