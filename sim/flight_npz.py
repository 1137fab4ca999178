"""A simulated flight of a dataset as an ingested ``flight.npz`` (docs/flight_format.md), so that
``quadfdi detect`` runs on a simulated flight exactly as on a real log:

    python -m quadfdi.sim.flight_npz DATASET.npz INDEX OUT/flight.npz

Every ingest channel the dataset has is copied from ``telemetry`` or ``esc_telemetry`` (the realistic
suite's ESC rpm, current and temperature, sim.esc_telemetry) with a full mask, both vibration metrics
(``vib_px4``, ``vib_ap``) among them (``autopilot`` "sim"); the others (the
ESC channels of a dataset without them, ESC temperatures of one made before sim.esc_thermal) are
absent, fully masked, with that reason. The flight
is airborne throughout (every simulated flight starts in the air); the vehicle is a quadrotor with
the dataset's ``pack_cells``. ``log_sha256`` is the sha256 of the flight's float32 telemetry.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core import resample
from quadfdi.formats.flight import FORMAT_VERSION, write_flight
from quadfdi.core.channels import CHANNEL_NAMES, CHANNEL_UNITS
from quadfdi.formats.dataset import load_dataset

def _columns(arrays: dict) -> dict[str, np.ndarray]:
    """dataset channel name -> (N, T) view, from telemetry and (if present) esc_telemetry."""
    cols = {str(n): arrays["telemetry"][:, :, j] for j, n in enumerate(arrays["channel_names"])}
    if "esc_telemetry" in arrays:
        cols.update({str(n): arrays["esc_telemetry"][:, :, j] for j, n in enumerate(arrays["esc_channel_names"])})
    return cols


def flight_arrays(arrays: dict, index: int, source: str) -> dict[str, np.ndarray]:
    n = arrays["telemetry"].shape[0]
    if not 0 <= index < n:
        raise QuadfdiError(f"{source} has flights 0..{n - 1}, not {index}")
    if "pack_cells" not in arrays:
        raise QuadfdiError(f"{source} has no pack_cells (not a realistic-suite dataset)")
    cols = _columns(arrays)
    time = np.asarray(arrays["time"], np.float64)
    t = len(time)
    shape = (t, len(CHANNEL_NAMES))
    tel, mask, status, sources = np.full(shape, np.nan, np.float32), np.zeros(shape, bool), [], []
    for j, name in enumerate(CHANNEL_NAMES):
        src = name
        if src in cols:
            tel[:, j], mask[:, j] = cols[src][index], True
            status.append("ok")
            sources.append(f"simulated {src}")
        else:
            status.append("absent: not simulated")
            sources.append("")
    span = [float(time[0]), float(time[-1])]
    vehicle = {"frame": "quadrotor", "battery": {"cells": int(arrays["pack_cells"][index])}, "simulated": True,
               "airborne_source": "simulated (airborne throughout)", "data_span_s": span}
    rates = np.where(mask.any(axis=0), 1.0 / float(time[1] - time[0]), 0.0)
    return {"format_version": np.array(FORMAT_VERSION), "time": time, "telemetry": tel, "mask": mask,
            "channel_names": np.array(CHANNEL_NAMES), "channel_units": np.array([CHANNEL_UNITS[k] for k in CHANNEL_NAMES]),
            "channel_sources": np.array(sources), "channel_status": np.array(status), "channel_rates_hz": rates,
            "channel_counts": mask.sum(axis=0).astype(np.int64), "airborne": np.ones(t, bool),
            "airborne_segments": np.array([span]), "armed_segments": np.array([span]),
            "log_sha256": np.array(hashlib.sha256(tel.tobytes()).hexdigest()), "log_file": np.array(f"{source}#{index}"),
            "autopilot": np.array("sim"), "vehicle": np.array(json.dumps(vehicle, sort_keys=True)),
            "resampling": np.array(json.dumps(resample.spec(), sort_keys=True)),
            "notes": np.array(json.dumps([f"simulated flight {index} of {source}"]))}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m quadfdi.sim.flight_npz", description=__doc__.split("\n\n")[0])
    p.add_argument("dataset")
    p.add_argument("index", type=int)
    p.add_argument("out")
    a = p.parse_args(argv)
    try:
        ds = load_dataset(a.dataset)
        arrays = flight_arrays(ds.arrays, a.index, Path(a.dataset).name)
    except QuadfdiError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    write_flight(Path(a.out), arrays)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
