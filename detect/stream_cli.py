"""``quadfdi stream-file --model RUN/export (FLIGHT | --dataset DATASET.npz --flight N) --out STREAM.bin``:
a flight as the raw telemetry stream that ``fwref_stream`` (firmware_ref's streaming runtime) reads,
with the raw channels in the order the export's on-board record names (docs/formats.md "Stream
file"). A flight the model cannot use is refused as by ``quadfdi detect``: one line, exit 2, nothing written.
``--vehicle vehicle.json`` (a reference profile's export, flightlog-ref): the stream carries the vehicle record
(formats/vehicle_record_bin.py) and replays with it."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from quadfdi.core.channels import AIRBORNE
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.stream import RawStream


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("stream-file", help="write a flight as a raw telemetry stream for fwref_stream",
                       description="A simulated flight of a dataset or a real flight (.ulg, .BIN, flight.npz) as a "
                                   "stream file: header (channels, period, profile, cells), then f64 time + f32 "
                                   "samples (docs/formats.md).")
    p.add_argument("flight", metavar="FLIGHT", nargs="?", help="a PX4 .ulg, an ArduPilot .BIN or a flight.npz")
    p.add_argument("--model", required=True, help="the export folder (RUN/export): its weights.bin's on-board record")
    p.add_argument("--dataset", help="a simulated dataset.npz instead of FLIGHT")
    p.add_argument("--flight", dest="index", type=int, help="with --dataset: the flight's index")
    p.add_argument("--out", required=True, help="the stream file to write")
    p.add_argument("--vehicle", help="a vehicle reference (quadfdi vehicle learn) whose record the stream carries "
                                     "(a flightlog-ref export)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.stream import from_dataset, write_stream

    if (args.dataset is None) == (args.flight is None) or (args.dataset is not None and args.index is None):
        raise QuadfdiError("stream-file needs either FLIGHT or --dataset DATASET.npz --flight N")
    src = args.dataset or args.flight
    if Path(args.out).exists() and Path(src).exists() and Path(args.out).samefile(src):
        raise QuadfdiError(f"stream-file: --out {args.out} is the input {src}: refusing to overwrite it")
    record = Export.open(args.model).onboard()
    vehicle = None
    if args.vehicle is not None:
        from quadfdi.formats.vehicle_record_bin import check_profile, record_from_vehicle_json

        check_profile(record["profile"])
        vehicle = record_from_vehicle_json(args.vehicle)
    rs = from_dataset(args.dataset, args.index, record) if args.dataset else from_flight(args.flight, record)
    rs.vehicle = vehicle
    write_stream(args.out, rs)
    print(f"stream-file: {rs.source}: {len(rs.time)} samples x {len(rs.names)} channels ({rs.profile}, "
          f"{rs.cells} cells{', vehicle record' if vehicle is not None else ''}) -> {args.out}")
    return 0


def from_flight(path: str | Path, record: dict) -> RawStream:
    """A real flight (.ulg / .BIN ingested on the fly, or flight.npz) with detect's refusals; the masked
    profile's stream carries the channels detect uses (detect.inputs.flight_raw), the others NaN."""
    from quadfdi.detect.inputs import flight_raw, read_flight

    if not record["cells_from_stream"]:
        raise QuadfdiError(f"profile {record['profile']!r} is the simulator's telemetry: a real flight cannot feed it "
                           "(train with --set train.profile=flightlog-min)")
    arrays = read_flight(path)
    fr = flight_raw(arrays, record["profile"])
    t = len(arrays["time"])
    carried = np.array([r == AIRBORNE or r in fr.raw for r in record["raw_channels"]])
    cols = [np.asarray(arrays["airborne"], np.float32) if r == AIRBORNE else fr.raw.get(r, np.full(t, np.nan, np.float32))
            for r in record["raw_channels"]]
    return RawStream(Path(path).name, record["profile"], list(record["raw_channels"]), float(record["sample_dt_s"]),
                     fr.cells, np.asarray(arrays["time"], np.float64), np.stack(cols, axis=1).astype(np.float32),
                     None if carried.all() else carried)
