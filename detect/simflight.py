"""A simulated dataset flight as the arrays of an ingested flight.npz (docs/flight_format.md), so
``quadfdi detect --dataset DATASET.npz --flight N`` runs the real-flight path on it: the same
profile, hover estimate, windows and alarm code as on a log.

The simulator's channels keep their names in ingest's channel set (ingest.model.CHANNEL_NAMES); its
PX4 vibration metric ``vib_px4`` is flight.npz's ``vib_acc`` with autopilot ``px4`` (what
detect.inputs reads for a PX4 log). Channels the simulator does not make (ESC RPM, current and
temperature) are absent: NaN, mask false. Every simulated sample is airborne; the cell count is
the flight's ``pack_cells``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from core.errors import QuadfdiError

SIM_NAME = {"vib_acc": "vib_px4"}  # flight.npz name -> the simulator's


def dataset_flight(dataset: str | Path, flight: int) -> dict[str, np.ndarray]:
    from ingest.flight import FORMAT_VERSION
    from ingest.model import CHANNEL_NAMES, CHANNEL_UNITS
    from sim.dataset import load_dataset

    ds = load_dataset(dataset)
    tel = ds["telemetry"]
    if not 0 <= flight < tel.shape[0]:
        raise QuadfdiError(f"{dataset} has flights 0..{tel.shape[0] - 1}, not {flight}")
    if "pack_cells" not in ds.arrays:
        raise QuadfdiError(f"{dataset} has no pack_cells (a paper-suite dataset): detect needs the cell count")
    names, t = ds.channel_names, tel.shape[1]
    dt = float(ds.config.sim.sample_dt_s)
    out_tel = np.full((t, len(CHANNEL_NAMES)), np.nan, np.float32)
    mask = np.zeros((t, len(CHANNEL_NAMES)), bool)
    status = []
    for j, name in enumerate(CHANNEL_NAMES):
        src = SIM_NAME.get(name, name)
        if src in names:
            out_tel[:, j], mask[:, j] = tel[flight, :, names.index(src)], True
            status.append("ok")
        else:
            status.append("absent: not simulated")
    span = np.array([[0.0, (t - 1) * dt]])
    source = f"{Path(dataset).name}#{flight}"
    return {"format_version": np.array(FORMAT_VERSION), "time": np.arange(t) * dt, "telemetry": out_tel,
            "mask": mask, "channel_names": np.array(CHANNEL_NAMES),
            "channel_units": np.array([CHANNEL_UNITS[k] for k in CHANNEL_NAMES]),
            "channel_sources": np.array(["sim" if s == "ok" else "" for s in status]),
            "channel_status": np.array(status), "channel_rates_hz": np.array([1.0 / dt if s == "ok" else 0.0
                                                                               for s in status]),
            "channel_counts": np.array([t if s == "ok" else 0 for s in status]), "airborne": np.ones(t, bool),
            "airborne_segments": span, "armed_segments": span, "log_sha256": np.array(""),
            "log_file": np.array(source), "autopilot": np.array("px4"),
            "vehicle": np.array(json.dumps({"frame": "quad-x", "battery": {"cells": int(ds["pack_cells"][flight])},
                                            "source": "simulated"})),
            "resampling": np.array("{}"), "notes": np.array("[]")}
