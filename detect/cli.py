"""``quadfdi detect --model RUN/export [--net cnode|gru] [--precision fp32|int8] [--runtime ort|cpp]
(FLIGHT | --dataset DATASET.npz --flight N) --out DIR``: an exported model on a real flight (a .ulg /
.BIN log, ingested on the fly, or an ingested flight.npz) or a simulated one (sim/flight_npz.py).
A flight it cannot use is refused: one line, exit 2, nothing written."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("detect", help="run an exported model on a real flight: probabilities, alarms, a figure",
                       description="Per-window class probabilities, the alarm timeline under the manifest's "
                                   "policy, DIR/alarms.json, DIR/windows.npz and DIR/detect.png (docs/detect.md).")
    p.add_argument("flight", metavar="FLIGHT", nargs="?", help="a PX4 .ulg, an ArduPilot .BIN or an ingested flight.npz")
    p.add_argument("--dataset", help="a simulated dataset.npz instead of FLIGHT (the realistic suite's)")
    p.add_argument("--flight", dest="index", type=int, help="with --dataset: the flight's index")
    p.add_argument("--model", required=True, help="the export folder (RUN/export) holding manifest.json")
    p.add_argument("--net", choices=("cnode", "gru"), default="cnode", help="which network (default: %(default)s)")
    p.add_argument("--precision", choices=("fp32", "int8"), default="fp32")
    p.add_argument("--runtime", choices=("ort", "cpp"), default="ort",
                   help="ONNX Runtime on the exported graph, or the C++ reference on weights.bin")
    p.add_argument("--out", required=True, help="folder to write alarms.json, windows.npz and detect.png into")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.detect.run import detect, write_detect
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.sim.flight_npz import flight_arrays

    if (args.dataset is None) == (args.flight is None) or (args.dataset is not None and args.index is None):
        raise QuadfdiError("detect needs either FLIGHT or --dataset DATASET.npz --flight N")
    flight = (flight_arrays(load_dataset(args.dataset).arrays, args.index, Path(args.dataset).name) if args.dataset
              else args.flight)
    result = detect(args.model, flight, args.net, args.precision, args.runtime)  # refusals raise here
    write_detect(args.out, result)
    return 0
