"""``quadfdi vehicle learn|rules``: a vehicle reference from its healthy flights, and the simple reference
rules on other flights (docs/vehicle.md).

    quadfdi vehicle learn LOG_OR_FLIGHT... --out vehicle.json
    quadfdi vehicle rules --vehicle vehicle.json LOG_OR_FOLDER... --out DIR
    quadfdi vehicle record vehicle.json --out record.bin   (the on-board record: fwref_stream --vehicle)
    quadfdi vehicle show vehicle.json                     (what the reference holds, as text)

Bad input (a refused reference, an unreadable vehicle.json, a path that does not exist, nothing to
score) is one line on stderr, exit 2, and nothing written.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from quadfdi.core.errors import QuadfdiError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("vehicle", help="learn a vehicle reference from its healthy flights; score flights against it",
                       description="A reference of one airframe from its own healthy flights (motor command shares, "
                                   "hover collective, pack, vibration, ESC), and the simple share rules on other "
                                   "flights (docs/vehicle.md).")
    acts = p.add_subparsers(dest="action", required=True, metavar="{learn,rules,record,show}")
    pl = acts.add_parser("learn", help="learn vehicle.json from healthy flights of one airframe")
    pl.add_argument("flights", nargs="+", metavar="LOG_OR_FLIGHT",
                    help="healthy flights: PX4 .ulg, ArduPilot .BIN, Crazyflie uSD logs or flight.npz files")
    pl.add_argument("--out", required=True, help="the reference file to write (vehicle.json)")
    pl.set_defaults(func=run_learn)
    pr = acts.add_parser("rules", help="score flights with the four share rules against a reference")
    pr.add_argument("flights", nargs="+", metavar="LOG_OR_FOLDER", help="flights, or folders searched by content")
    pr.add_argument("--vehicle", required=True, help="the reference (quadfdi vehicle learn)")
    pr.add_argument("--out", required=True, help="folder to write rules.json and rules.md into")
    pr.set_defaults(func=run_rules)
    pc = acts.add_parser("record", help="write a reference's vehicle record file (25 float32) for fwref_stream")
    pc.add_argument("vehicle", metavar="VEHICLE_JSON", help="the reference (quadfdi vehicle learn)")
    pc.add_argument("--profile", default="flightlog-ref",
                    help="the reference profile it is for (flightlog-ref or flightlog-phys)")
    pc.add_argument("--out", required=True, help="the record file to write (docs/formats.md \"Vehicle record file\")")
    pc.set_defaults(func=run_record)
    ps = acts.add_parser("show", help="print what a reference holds: flights, shares, share model and its range, ...")
    ps.add_argument("vehicle", metavar="VEHICLE_JSON", help="the reference (quadfdi vehicle learn)")
    ps.set_defaults(func=run_show)


def run_show(args: argparse.Namespace) -> int:
    from quadfdi.formats.vehicle import load_vehicle
    from quadfdi.vehicle.show import show

    print(show(load_vehicle(args.vehicle), Path(args.vehicle).name))
    return 0


def run_record(args: argparse.Namespace) -> int:
    from quadfdi.formats.vehicle_record_bin import check_profile, record_from_vehicle_json, write_record

    out = Path(args.out)
    if out.is_dir():
        raise QuadfdiError(f"--out {out} is a folder; give the record file to write (e.g. {out / 'record.bin'})")
    check_profile(args.profile)
    rec = record_from_vehicle_json(args.vehicle)
    write_record(out, rec, args.profile)
    held = int(sum(1 for x in rec if x == x))
    print(f"wrote {out}: the vehicle record of {args.vehicle} for {args.profile} ({held} of {len(rec)} fields held)")
    return 0


def _refuse_folder_output(out: Path) -> None:
    if out.is_dir():
        raise QuadfdiError(f"--out {out} is a folder; give the reference file to write (e.g. {out / 'vehicle.json'})")


def run_learn(args: argparse.Namespace) -> int:
    from quadfdi.formats.vehicle import write_vehicle
    from quadfdi.vehicle.coverage import flown_text
    from quadfdi.vehicle.flights import find_flights, read_flight
    from quadfdi.vehicle.learn import learn

    out = Path(args.out)
    _refuse_folder_output(out)
    found = find_flights(args.flights)
    if not found:
        raise QuadfdiError(f"no flight log or flight.npz found in {' '.join(args.flights)}")
    ref = learn([read_flight(path, name) for path, name in found])
    write_vehicle(out, ref)
    for w in ref["warnings"]:
        print(f"quadfdi vehicle: warning: {w}", file=sys.stderr)
    shares = ", ".join(f"{m['log_motor']} {m['mean']:.3f}" for m in ref["motor_share"])
    print(f"wrote {out}: {len(found)} flights, {ref['motor_share'][0]['seconds']:.1f} s airborne; motor shares "
          f"{shares}; hover collective {ref['hover']['cmd']['mean']:.3f}; {flown_text(ref['share_model'])}; "
          f"{len(ref['warnings'])} warnings")
    return 0


def run_rules(args: argparse.Namespace) -> int:
    from quadfdi.core.jobcache import file_sha256
    from quadfdi.formats.vehicle import load_vehicle
    from quadfdi.vehicle import crazypad
    from quadfdi.vehicle.rules import RULES, score_paths, thresholds
    from quadfdi.vehicle.rules_report import write_outputs

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise QuadfdiError(f"--out {out} exists and is not a folder")
    ref = load_vehicle(args.vehicle)
    rows, paths, refused = score_paths(args.flights, ref)
    if not rows:
        reasons = "; ".join(f"{x['flight']}: {x['reason']}" for x in refused[:3])
        raise QuadfdiError(f"no flight could be scored ({len(refused)} refused{': ' + reasons if reasons else ''})")
    crazypad.label(rows, paths, ref)
    command = shlex.join(["quadfdi", "vehicle", "rules", "--vehicle", args.vehicle, *args.flights, "--out", args.out])
    result = {"command": command,
              "reference": {"file": Path(args.vehicle).name, "sha256": file_sha256(args.vehicle),
                            "flights": [f["file"] for f in ref["flights"]]},
              "thresholds": thresholds(ref), "flights": rows, "refused": refused,
              "table": crazypad.table(rows, tuple(r.name for r in RULES)) if any(r["group"] for r in rows) else []}
    write_outputs(out, result)
    alarms = {r.name: sum(row["rules"][r.name]["alarm"] for row in rows) for r in RULES}
    print(f"wrote {out / 'rules.md'}: {len(rows)} flights scored, {len(refused)} not; alarms per rule "
          + ", ".join(f"{k} {v}" for k, v in alarms.items()))
    return 0
