"""``quadfdi detect --model RUN/export [--net cnode|gru] [--precision fp32|int8] [--runtime ort|cpp]
(LOG_OR_FOLDER... | --dataset DATASET.npz --flight N) --out DIR [--workers N] [--fleet]
[--vehicle vehicle.json | --vehicles MAP]``: an exported model on real flights (PX4 / ArduPilot /
Crazyflie logs, ingested on the fly, or ingested flight.npz files) or a simulated one (sim/flight_npz.py).

One flight (one file, or --dataset): DIR/alarms.json, windows.npz, detect.png, evidence.json and
the page index.html; a flight it cannot use is refused: one line, exit 2, nothing written.
A folder, several logs, or --fleet: one folder per flight, summary.json and the fleet index
(detect.batch), with the fleet's exit status (0 no alarm, 1 alarm, 3 some refused, 4 both; 2 error).
A vehicle reference (detect.reference) puts the vehicle's own healthy flights beside each decision,
never changing one.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("detect", help="run an exported model on real flights: probabilities, alarms, pages",
                       description="Per-window class probabilities, the alarm timeline under the manifest's "
                                   "policy, the evidence for each alarm and a page per flight (docs/detect.md). "
                                   "Exit status of a fleet (a folder, several logs or --fleet): 0 no alarm, "
                                   "1 an alarm raised, 3 some logs refused (no alarm), 4 an alarm raised and "
                                   "some logs refused, 2 bad usage or an error.")
    p.add_argument("logs", metavar="LOG_OR_FOLDER", nargs="*",
                   help="PX4 .ulg, ArduPilot .BIN, Crazyflie uSD logs or ingested flight.npz files, or folders "
                        "searched recursively for them (known by content, not by name)")
    p.add_argument("--dataset", help="a simulated dataset.npz instead of logs (the realistic suite's)")
    p.add_argument("--flight", dest="index", type=int, help="with --dataset: the flight's index")
    p.add_argument("--model", required=True, help="the export folder (RUN/export) holding manifest.json")
    p.add_argument("--net", choices=("cnode", "gru"), default=None,
                   help="which network (default: the one with the higher validation macro F1 the export records; "
                        "the CNODE when it records none)")
    p.add_argument("--precision", choices=("fp32", "int8"), default="fp32")
    p.add_argument("--runtime", choices=("ort", "cpp"), default="ort",
                   help="ONNX Runtime on the exported graph, or the C++ reference on weights.bin")
    p.add_argument("--out", required=True, help="the output folder")
    p.add_argument("--workers", type=int, default=None,
                   help="flights decided in parallel processes (default: the CPU count)")
    p.add_argument("--fleet", action="store_true",
                   help="the fleet layout and exit status even for one log file")
    p.add_argument("--vehicle", help="a vehicle reference (quadfdi vehicle learn) every flight is read beside")
    p.add_argument("--vehicles", metavar="MAP",
                   help="a .toml or .json map of log path globs (relative to the map; * within a folder, ** across "
                        "folders) to vehicle.json files: each flight is read beside the first match's reference; a "
                        "flight matching none, without one")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.detect.reference import references

    if args.workers is not None and args.workers < 1:
        raise QuadfdiError(f"--workers must be at least 1, not {args.workers}")
    refs = references(args.vehicle, args.vehicles)  # every reference file checked before any flight is read
    if args.net is None:
        from quadfdi.formats.manifest import better_network, load_manifest

        args.net, why = better_network(load_manifest(Path(args.model) / "manifest.json"))
        print(f"detect: --net {args.net}: {why}")
    if args.dataset is not None or args.index is not None:
        if args.dataset is None or args.index is None or args.logs:
            raise QuadfdiError("detect needs either logs or --dataset DATASET.npz --flight N")
        from quadfdi.formats.dataset import load_dataset
        from quadfdi.sim.flight_npz import flight_arrays

        flight = flight_arrays(load_dataset(args.dataset).arrays, args.index, Path(args.dataset).name)
        return single(args, flight, *refs.for_log(args.dataset))
    if not args.logs:
        raise QuadfdiError("detect needs either logs or --dataset DATASET.npz --flight N")
    if len(args.logs) == 1 and Path(args.logs[0]).is_file() and not args.fleet:
        return single(args, args.logs[0], *refs.for_log(args.logs[0]))
    from quadfdi.detect.batch import detect_many

    return detect_many(args.model, args.logs, args.out, args.net, args.precision, args.runtime,
                       args.workers, refs=refs)["exit_status"]


def single(args: argparse.Namespace, flight, reference=None, note: str | None = None) -> int:
    """One flight into DIR (alarms.json, windows.npz, detect.png, evidence.json, index.html, plotly.min.js)."""
    from quadfdi.core.alarm import reach_note
    from quadfdi.detect.batch import decide_flight, write_flight_folder
    from quadfdi.detect.html import write_plotly_js
    from quadfdi.detect.reference import said
    from quadfdi.detect.run import write_detect

    result, arrays, evidence, date = decide_flight(flight, args.model, args.net, args.precision,
                                                   args.runtime, reference, note)  # refusals raise here
    write_detect(args.out, result)
    write_plotly_js(Path(args.out))
    write_flight_folder(Path(args.out), result, arrays, evidence, date, "plotly.min.js", None)
    print(f"detect: {said(result['record']['vehicle_reference'], result['reference_note'])}")
    note = reach_note(result["record"].get("alarm_reach"))
    if note:
        print(f"detect: {note}")
    return 0
