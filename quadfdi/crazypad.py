"""``quadfdi crazypad OUT --run RUN``: the CrazyPAD protocol (docs/vehicle.md) scored by one network chosen
on simulation, beside the four share rules.

    quadfdi crazypad OUT --run RUN [--crazypad DIR] [--logs DIR] [--workers N]

1. RUN: a finished run (or a folder holding ``export/`` and ``history.json``) whose export reads any log's
   channels (a masked profile); the network and its alarm policy are chosen from its simulated validation
   flights (quadfdi/crazypad_choice.py), before any CrazyPAD flight is read;
2. the vehicle reference is learned from exactly ``normal_flight/E8_log00``, ``E8_log01``, ``E9_log00``,
   ``E9_log01`` (vehicle.learn) and written to ``OUT/vehicle.json``;
3. every other CrazyPAD log is decided by that network (ONNX Runtime, fp32) with the reference and without
   it, and scored by the four share rules (quadfdi/crazypad_decide.py);
4. per protocol group and session: the network's and the rules' alarms, classes, motors named (the log's
   M1-M4), p(fault), AUROC; the gates met or missed (quadfdi/crazypad_table.py);
5. the same network and policy on the shared healthy PX4 flights in ``--logs``, each its own reference from
   its first part (quadfdi/crazypad_px4.py);
6. ``OUT/crazypad.md`` and ``OUT/crazypad.json`` (atomically). With OUT = ``RUN/crazypad`` the run's
   report.md is rewritten (``quadfdi report``) and carries the gates and the summary
   (quadfdi/crazypad_report.py ``report_section``).

Bad input (RUN without an export or with an unmasked profile, no CrazyPAD folder, a reference flight
missing or refused, ``--logs`` not a folder) is one line, exit 2, nothing written.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.crazypad_report import FOLDER

REFERENCE_FLIGHTS = ("E8_log00", "E8_log01", "E9_log00", "E9_log01")
HEALTHY_FOLDER = "normal_flight"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("crazypad", help="the CrazyPAD protocol scored by the run's network chosen on simulated "
                                        "validation flights, beside the four share rules",
                       description="Learn the Crazyflie's reference from four healthy CrazyPAD flights, decide "
                                   "every other CrazyPAD log with the run's network chosen on simulated validation "
                                   "flights (with and without the reference), score the four share rules beside "
                                   "it, and the same network on the shared healthy PX4 flights; write "
                                   "OUT/crazypad.md, OUT/crazypad.json and OUT/vehicle.json.")
    p.add_argument("out", metavar="OUT", help="folder to write into (RUN/crazypad: the run's report shows it)")
    p.add_argument("--run", required=True, help="a run folder with export/ (masked profile) and history.json")
    p.add_argument("--crazypad", default=None, help="the CrazyPAD folder of condition folders (default: "
                                                    "../shared/data/crazypad/motor_data beside the checkout)")
    p.add_argument("--logs", default=None, help="the shared flight log folder (default: ../shared/data/flightlogs "
                                                "beside the checkout; skipped in one line when absent)")
    p.add_argument("--workers", type=int, default=1, help="processes deciding CrazyPAD logs (default: %(default)s)")
    p.set_defaults(func=run_crazypad)


def _folders(args: argparse.Namespace) -> tuple[Path, Path | None]:
    from quadfdi.real_flights import default_crazypad, default_logs

    pad = default_crazypad() if args.crazypad is None else Path(args.crazypad)
    if not pad.is_dir():
        raise QuadfdiError(f"--crazypad {pad}: no such folder (the CrazyPAD motor_data folder of condition folders)")
    logs = default_logs() if args.logs is None else Path(args.logs)
    if args.logs is not None and not logs.is_dir():
        raise QuadfdiError(f"--logs {logs}: no such folder")
    if args.workers < 1:
        raise QuadfdiError(f"--workers must be at least 1, found {args.workers}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise QuadfdiError(f"OUT {out} exists and is not a folder")
    return pad.resolve(), logs.resolve() if logs.is_dir() else None


def learn_reference(pad: Path) -> tuple[dict, list[Path]]:
    """The reference of ``REFERENCE_FLIGHTS`` (vehicle.learn) and their paths; one line when one is missing."""
    from quadfdi.vehicle.flights import read_flight
    from quadfdi.vehicle.learn import learn

    paths = [pad / HEALTHY_FOLDER / n for n in REFERENCE_FLIGHTS]
    missing = [f"{HEALTHY_FOLDER}/{p.name}" for p in paths if not p.is_file()]
    if missing:
        raise QuadfdiError(f"{pad}: reference flight(s) {', '.join(missing)} missing (the reference is learned from "
                           f"exactly {', '.join(REFERENCE_FLIGHTS)} of {HEALTHY_FOLDER})")
    return learn([read_flight(p, f"{HEALTHY_FOLDER}/{p.name}") for p in paths]), paths


def test_logs(pad: Path, reference_paths: list[Path]) -> list[tuple[Path, str]]:
    """Every log under ``pad`` but the reference flights (vehicle.crazypad.label also drops a copy of one)."""
    from quadfdi.vehicle.flights import find_flights

    skip = {p.resolve() for p in reference_paths}
    found = [(p, n) for p, n in find_flights([pad]) if p.resolve() not in skip]
    if not found:
        raise QuadfdiError(f"--crazypad {pad}: no Crazyflie log besides the reference flights")
    return found


def score(run: str, pad: Path, logs: Path | None, workers: int, log=print) -> dict:
    """Everything crazypad.json holds (the module docstring's steps 1-5), nothing written."""
    from quadfdi.crazypad_choice import policy_text, scored_network
    from quadfdi.crazypad_decide import decide_all
    from quadfdi.crazypad_px4 import px4_part
    from quadfdi.crazypad_table import crazypad_gates, px4_gate, table
    from quadfdi.real_flights_detect import HEALTHY

    choice = scored_network(run)
    log(f"crazypad: network {choice['net']} (validation macro F1 {choice['chosen_by']['val_macro_f1']}), policy "
        f"{policy_text(choice['policy'])} ({choice['policy_source']})")
    reference, ref_paths = learn_reference(pad)
    found = test_logs(pad, ref_paths)
    decided = decide_all(choice["export"], choice["net"], found, reference, workers, log)
    cells = table(decided["rows"])
    px4 = None if logs is None else px4_part(choice["export"], choice["net"], logs, tuple(f"{h}.ulg" for h in HEALTHY),
                                            log=log)
    return {"choice": choice, "reference": reference, "crazypad": str(pad), "decided": decided, "table": cells,
            "gates": crazypad_gates(cells, decided["rows"]) + [px4_gate(px4)], "px4": px4}


def write_outputs(out: Path, result: dict) -> None:
    """OUT/vehicle.json, OUT/crazypad.json, OUT/crazypad.md, each atomically (the folder created now)."""
    from quadfdi.core.atomic import ensure_dir, write_text
    from quadfdi.core.jsonio import write_json
    from quadfdi.crazypad_report import markdown
    from quadfdi.formats.vehicle import write_vehicle

    d = ensure_dir(out)
    write_vehicle(d / "vehicle.json", result["reference"])
    body = {k: v for k, v in result.items() if k != "reference"}
    body["reference"] = {"file": "vehicle.json", "flights": [f["file"] for f in result["reference"]["flights"]],
                         "warnings": result["reference"]["warnings"]}
    write_json(d / "crazypad.json", body, indent=2)
    write_text(d / "crazypad.md", markdown(result))


def run_crazypad(args: argparse.Namespace) -> int:
    pad, logs = _folders(args)
    result = score(args.run, pad, logs, args.workers)
    result["command"] = shlex.join(["quadfdi", "crazypad", args.out, "--run", args.run]
                                   + (["--crazypad", args.crazypad] if args.crazypad else [])
                                   + (["--logs", args.logs] if args.logs else []) + ["--workers", str(args.workers)])
    if logs is None:
        print("crazypad: no shared flight log folder (--logs; ../shared/data/flightlogs beside the checkout): the "
              "PX4 part is skipped", file=sys.stderr)
    for w in result["reference"]["warnings"]:
        print(f"quadfdi crazypad: reference warning: {w}", file=sys.stderr)
    write_outputs(Path(args.out), result)
    met = sum(g["met"] for g in result["gates"])
    print(f"wrote {Path(args.out) / 'crazypad.md'}: {len(result['decided']['rows'])} logs decided, "
          f"{len(result['decided']['refused'])} refused; gates met {met} of {len(result['gates'])}")
    if Path(args.out).resolve() == (Path(args.run) / FOLDER).resolve():  # the run's report carries the table
        from quadfdi.report import write_run_report

        write_run_report(args.run, log=print)
    return 0
