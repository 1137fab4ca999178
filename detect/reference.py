"""The vehicle reference a flight is read beside (``quadfdi detect --vehicle V`` for every flight, or
``--vehicles MAP``: the first log path glob of the map that a flight's path matches), and what it adds
to the flight's outputs. A model of a reference profile (``flightlog-ref``) reads it as its vehicle
record (core/vehicle_record.py: deviations from the vehicle's own healthy flights among its inputs);
a model of any other profile does not (it never changes its probabilities, alarms or exit status).
Either way it puts beside them what the vehicle's own healthy flights say (vehicle.compare, the code
of ``quadfdi vehicle learn`` and ``rules``).

- ``alarms.json`` ``vehicle_reference``: ``version``, the reference's ``file``, ``sha256`` and how it
  was chosen (``chosen_by``), then vehicle.compare's quantities, deviations and rules; null without one.
- the page: each motor's reference share at the flight's operating point with its band of +- the
  reference's between-flight spread (``series``), and per alarm the share deviations over its span.

A reference of another vehicle (autopilot, frame, cell count or motor map differ) refuses the flight
with one line naming the field; a bad reference file or map refuses the whole command (one line, exit 2,
nothing written) before any flight is read.

Globs: ``*`` and ``?`` match within one path component, ``**`` any number of components; a glob is
relative to the map file's folder and matched against the log's absolute path, both normalised.
"""

from __future__ import annotations

import fnmatch
import functools
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.vehicle.coverage import said as coverage_said

VERSION = 2
NO_REFERENCE = "no vehicle reference: the model judges the flight against the simulated vehicles"


@dataclass(frozen=True)
class Reference:
    file: str  # the vehicle.json's file name
    path: str
    sha256: str
    data: dict = field(repr=False)
    chosen_by: str = "--vehicle"


def load_reference(path: str | Path, chosen_by: str = "--vehicle") -> Reference:
    """A vehicle.json read and checked by formats/vehicle.py (one-line QuadfdiError when refused)."""
    from quadfdi.core.jobcache import file_sha256
    from quadfdi.formats.vehicle import load_vehicle

    data = load_vehicle(path)
    return Reference(Path(path).name, str(path), file_sha256(path), data, chosen_by)


def glob_match(pattern: str, path: str | Path) -> bool:
    """``path`` (absolute) matches ``pattern`` (absolute): component by component, ``**`` any number."""
    pat = Path(os.path.normpath(os.path.abspath(pattern))).parts
    parts = Path(os.path.normpath(os.path.abspath(path))).parts

    @functools.lru_cache(maxsize=None)
    def match(i: int, j: int) -> bool:
        if i == len(pat):
            return j == len(parts)
        if pat[i] == "**":
            return any(match(i + 1, k) for k in range(j, len(parts) + 1))
        return j < len(parts) and fnmatch.fnmatchcase(parts[j], pat[i]) and match(i + 1, j + 1)

    return match(0, 0)


@dataclass(frozen=True)
class References:
    """Which reference each log is read beside: one for all (``--vehicle``), the map's first match
    (``--vehicles``), or none."""

    every: Reference | None = None
    rules: tuple[tuple[str, Reference], ...] = ()
    map_file: str | None = None

    def for_log(self, log: str | Path) -> tuple[Reference | None, str | None]:
        """(the reference, None) or (None, the line that says there is none and why)."""
        if self.every is not None:
            return self.every, None
        for pattern, ref in self.rules:
            if glob_match(pattern, log):
                return ref, None
        if self.map_file is None:
            return None, NO_REFERENCE
        return None, NO_REFERENCE.replace("reference:", f"reference (no glob of {Path(self.map_file).name} matches "
                                          "this log):", 1)


def references(vehicle: str | None, vehicles: str | None) -> References:
    """The command's references, every file read and checked before any flight (one line when refused)."""
    if vehicle and vehicles:
        raise QuadfdiError("give --vehicle (one reference for every flight) or --vehicles (a map), not both")
    if vehicle:
        return References(every=load_reference(vehicle))
    if vehicles:
        from quadfdi.formats.vehicle import read_vehicle_map

        rules, loaded = [], {}
        for pattern, path in read_vehicle_map(vehicles):
            key = os.path.normpath(os.path.abspath(path))
            if key not in loaded:
                try:
                    loaded[key] = load_reference(path, f"--vehicles {Path(vehicles).name}")
                except QuadfdiError as exc:
                    raise QuadfdiError(f"vehicles map {vehicles}, {pattern!r}: {exc}") from None
            rules.append((pattern, loaded[key]))
        return References(rules=tuple(rules), map_file=str(vehicles))
    return References()


def apply(flight: dict, ref: Reference, path: str | Path) -> tuple[dict, dict]:
    """(alarms.json's ``vehicle_reference``, the per-sample series the page and the evidence draw) of one
    flight (flight.npz arrays); QuadfdiError naming the reference when it is another vehicle's."""
    from quadfdi.vehicle.compare import compare
    from quadfdi.vehicle.flights import Flight

    fl = Flight(Path(str(path)).name, Path(str(path)), str(flight["log_sha256"]), flight)
    try:
        out, (shares, expect, modelled) = compare(fl, ref.data)
    except QuadfdiError as exc:
        raise QuadfdiError(f"vehicle reference {ref.file} refused: {exc}") from None
    record = {"version": VERSION, "file": ref.file, "sha256": ref.sha256, "chosen_by": ref.chosen_by,
              **{k: v for k, v in out.items() if k != "version"}}
    spread = [m["between_std"] for m in ref.data["motor_share"]]
    series = {"shares": shares, "reference": expect, "modelled": modelled, "airborne": fl.airborne,
              "spread": spread, "log_motor": [m["log_motor"] for m in ref.data["motor_share"]]}
    return record, series


def alarm_deviations(series: dict, time: np.ndarray, start_s: float, end_s: float | None) -> list[dict] | None:
    """Per motor over an alarm's airborne samples (all four shares defined): the median share, the median
    reference share at those samples, their difference and that in between-flight spreads."""
    t = np.asarray(time, np.float64)
    shares, expect = series["shares"], series["reference"]
    sel = (series["airborne"] & np.isfinite(shares).all(axis=1) & (t >= start_s)
           & (t <= (np.inf if end_s is None else end_s)))
    if not sel.any():
        return None
    out = []
    for k in range(4):
        s, r = float(np.median(shares[sel, k])), float(np.median(expect[sel, k]))
        spread = series["spread"][k]
        out.append({"motor": k + 1, "log_motor": series["log_motor"][k], "share": round(s, 4),
                    "reference": round(r, 4), "deviation": round(s - r, 4),
                    "z": None if not spread else round((s - r) / spread, 2)})
    return out


def add_to_evidence(evidence: list[dict], series: dict | None, time: np.ndarray) -> None:
    """Each alarm's evidence gets ``reference_shares`` (alarm_deviations; null without a reference)."""
    for ev in evidence:
        ev["reference_shares"] = None if series is None else alarm_deviations(series, time, ev["start_s"],
                                                                               ev["end_s"])


def summary(record: dict | None) -> dict | None:
    """The few numbers the fleet index shows of a flight's ``vehicle_reference``."""
    if record is None:
        return None
    vib = {k: v["deviation"] for k, v in record["vibration"].items()}
    return {"file": record["file"], "sha256": record["sha256"],
            "shares": [{k: m[k] for k in ("rotor", "log_motor", "deviation", "z")} for m in record["motor_share"]],
            "hover": record["hover_collective"]["deviation"], "sag": record["sag_v_per_a_cell"]["deviation"],
            "vibration": next(iter(vib.values())) if vib else None, "vibration_metric": next(iter(vib), None),
            "largest": record["largest_deviation"], "outside": (record.get("coverage") or {}).get("outside"),
            "beyond": bool((record.get("coverage") or {}).get("beyond")),
            "rules": {k: {"score": r["score"], "motor": r["motor"], "alarm": r["alarm"], "threshold": r["threshold"]}
                      for k, r in record["rules"].items()}}


def said(record: dict | None, note: str | None) -> str:
    """One line for the printed summary of one flight."""
    if record is None:
        return note or NO_REFERENCE
    big, r = record["largest_deviation"], record["rules"]["abs_ref"]
    if big is None:
        return f"vehicle reference {record['file']}: no motor share to compare"
    z = "" if big["z"] is None else f", {big['z']:+.1f} x the between-flight spread"
    beyond = coverage_said(record.get("coverage"))
    return (f"vehicle reference {record['file']}: largest motor share deviation {big['log_motor']} "
            f"{big['deviation']:+.3f}{z}; rule abs_ref {r['score']:.3f} against {r['threshold']:.3f}"
            f"{' (alarm)' if r['alarm'] else ''}{'; ' + beyond if beyond else ''}")
