"""Vehicle references of a fleet dataset, for the baselines' reference-relative physics features
(train/features_ref.py; docs/training.md "Baselines against the vehicle's reference").

Each vehicle's reference is ``vehicle.learn.learn`` on that vehicle's own reference flights
(``reference_flight``), and nothing else: no other vehicle's flight and none of its own later flights
enters it. A dataset row becomes a ``vehicle.flights.Flight`` through ``sim.flight_npz.flight_arrays``
(the simulated flight as an ingested flight.npz); the simulator numbers its rotors in the project's
order, so its motor map is the identity. What a reference expects of a flight, sample by sample, is
computed with vehicle/'s own code: the share at the sample's forward speed and yaw rate
(``vehicle.compare.share_series``), the vibration floor at the sample's collective (the reference's
floor + slope x collective), the motor temperature offsets and the pack's sag per ampere per cell.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfdi.core import vehicle_record as vr
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.profiles import has_reference
from quadfdi.core.hover import collective
from quadfdi.formats.dataset import FLEET_KEYS, Dataset, vehicle_columns
from quadfdi.sim.flight_npz import flight_arrays
from quadfdi.train.features import VIBRATION_CHANNELS
from quadfdi.vehicle import quantities as q
from quadfdi.vehicle.compare import share_series, vibration_floor
from quadfdi.vehicle.flights import Flight
from quadfdi.vehicle.learn import learn

IDENTITY = [0, 1, 2, 3]  # the simulator's rotor k is the project's rotor k


def has_vehicles(arrays: dict[str, np.ndarray]) -> bool:
    """True for a dataset whose vehicles fly several flights with reference flights (the fleet suite)."""
    return all(k in arrays for k in FLEET_KEYS) and bool(np.asarray(arrays["reference_flight"]).any())


def dataset_flight(arrays: dict[str, np.ndarray], row: int, source: str) -> Flight:
    """Dataset row ``row`` as the Flight vehicle/ reads (named ``source#row``)."""
    a = flight_arrays(arrays, int(row), source)
    veh = json.loads(str(a["vehicle"]))
    veh["motor_map"] = IDENTITY
    a["vehicle"] = np.array(json.dumps(veh, sort_keys=True))
    return Flight(f"{source}#{int(row)}", Path(source), str(a["log_sha256"]), a)


def learn_references(arrays: dict[str, np.ndarray], source: str) -> dict[int, dict]:
    """vehicle id -> its reference, learned from its own reference flights only; one-line QuadfdiError
    naming the vehicle when it has none or ``learn`` refuses them."""
    cols = vehicle_columns(arrays)
    vid, ref = cols["vehicle_id"], cols["reference_flight"]
    out = {}
    for v in np.unique(vid).tolist():
        rows = np.flatnonzero((vid == v) & ref)
        if rows.size == 0:
            raise QuadfdiError(f"{source}: vehicle {v} has no reference flight")
        try:
            out[v] = learn([dataset_flight(arrays, r, source) for r in rows])
        except QuadfdiError as exc:
            raise QuadfdiError(f"{source}: vehicle {v}'s reference: {exc}") from None
    return out


def vehicle_records(ds: Dataset) -> np.ndarray:
    """(F, 24) float32: each flight's vehicle record (core/vehicle_record.py) from its own vehicle's
    reference; NaN rows for every flight of a dataset without vehicles (the realistic and paper suites)."""
    n = len(ds["telemetry"])
    if not has_vehicles(ds.arrays):
        return np.full((n, vr.SIZE), np.nan, np.float32)
    refs = learn_references(ds.arrays, str(ds.path))
    records = {v: vr.from_reference(r) for v, r in refs.items()}
    vid = vehicle_columns(ds.arrays)["vehicle_id"]
    return np.stack([records[int(v)] for v in vid]).astype(np.float32)


def profiled(ds: Dataset, profile: str, patterns: bool = True, reference: bool = True) -> Dataset:
    """models.inputs.profiled_dataset with each flight's vehicle record for a reference profile
    (``reference`` False: no flight gets one, the model's decisions without the reference)."""
    from quadfdi.models.inputs import profiled_dataset

    records = vehicle_records(ds) if has_reference(profile) and reference else None
    return profiled_dataset(ds, profile, patterns, records)


def vib_channels(channel_names) -> list[str]:
    return [v for v in VIBRATION_CHANNELS if v in list(channel_names)]


def expected_series(fl: Flight, reference: dict, vibs: list[str]) -> np.ndarray:
    """(T, 4 + len(vibs)) what the reference expects at each sample: the four shares (project rotor order),
    then each vibration metric at the sample's collective (the reference's mean floor + slope; its mean
    level where it holds no floor)."""
    _, share, _ = share_series(fl, reference)
    coll = collective(q.motor_commands(fl)).astype(np.float64)
    cols = [share]
    for name in vibs:
        r = reference["vibration"].get(name)
        if r is None:
            raise QuadfdiError(f"{fl.name}: the reference holds no {name} (its flights do not log it)")
        floor = vibration_floor(r, coll)
        cols.append(np.full((len(coll), 1), float(r["level"]["mean"])) if floor is None else floor[:, None])
    return np.concatenate(cols, axis=1)


def constants(reference: dict) -> np.ndarray:
    """(5,) the reference's motor temperature offsets (K; the windings', else the ESC boards' where its
    flights log them, else 0) and its sag per ampere per cell (V/A; 0 when its flights log no current
    that moves). Which temperatures: those the baselines' windows carry (train/baselines_channels.py)."""
    temp = reference.get("motor_temp") or (reference.get("esc") or {}).get("temp_offset", {}).get("motors")
    dt = [float(m["mean"]) for m in temp] if temp else [0.0] * 4
    bat = reference.get("battery")
    sag = float(bat["sag_v_per_a"]["mean"]) if bat and bat["mode"] == "sag" else 0.0
    return np.array(dt + [sag])


@dataclass(frozen=True)
class VehicleRefs:
    """Per dataset row: ``series`` (N, T, S) float32 from ``expected_series`` and ``const`` (N, 5) from
    ``constants``, both of the row's own vehicle; ``reference_flight`` (N,) bool; ``vibs`` the vibration
    metrics of ``series``' last columns."""

    series: np.ndarray
    const: np.ndarray
    reference_flight: np.ndarray
    vibs: tuple[str, ...]

    def windows(self, traj: np.ndarray, start: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
        """(n, W, S) the expected series over the windows (traj[i], start[i]) and (n, 5) their constants."""
        idx = start[:, None] + np.arange(width)[None, :]
        return self.series[traj[:, None], idx], self.const[traj]


def vehicle_refs(arrays: dict[str, np.ndarray], source: str) -> VehicleRefs:
    """Every row's expected series and constants against its own vehicle's reference."""
    refs = learn_references(arrays, source)
    vid = vehicle_columns(arrays)["vehicle_id"]
    vibs = vib_channels(arrays["channel_names"])
    n, t = arrays["telemetry"].shape[:2]
    series = np.empty((n, t, 4 + len(vibs)), np.float32)
    const = np.empty((n, 5))
    for row in range(n):
        reference = refs[int(vid[row])]
        series[row] = expected_series(dataset_flight(arrays, row, source), reference, vibs)
        const[row] = constants(reference)
    if not np.isfinite(series).all():
        raise QuadfdiError(f"{source}: a reference's expected share or vibration is not finite (regressor missing?)")
    return VehicleRefs(series, const, np.asarray(arrays["reference_flight"], bool), tuple(vibs))
