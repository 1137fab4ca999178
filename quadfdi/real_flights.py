"""``quadfdi real-flights OUT``: the real-flight table from nothing. The realistic suite is simulated
once, each channel profile's networks are trained, applied, evaluated, exported and checked, and
every shared real quad log then goes through ``quadfdi detect`` with each of them.

    quadfdi real-flights OUT [--profiles min,nocur,esc] [--logs DIR] [--flights LOG,...] [--workers N]
                             [--config configs/realistic.toml] [--set SECTION.KEY=VALUE ...]

1. sim (``--config``, ``--set``) into ``OUT/base`` (sim seed of the config);
2. per profile P, a copy of that sim stage in ``OUT/P``, then train with ``train.profile=flightlog-P``,
   train apply (training seed 0 on sim seed 1: the validation and test flights the alarm policy is
   chosen and scored on), evaluate (each network's alarm policy chosen on validation), export with
   those policies, and parity on the host (C++ against ONNX Runtime and PyTorch; no Cortex-M);
3. every log (``--flights``, default ``LOGS``) ingested once into ``OUT/flights/ingest/<flight>``, then
   detect with each export, both networks, both runtimes (ort, cpp) and both precisions into
   ``OUT/flights/<P>/<flight>/<net>/<runtime>/<precision>/`` (the flightlog-esc model only on logs
   with ESC telemetry); the UAVCAN mission again with the gap rule bridged at 7 x the median
   interval (``OUT/flights_gap7``);
4. ``OUT/real_flights.md`` (both tables, quadfdi/real_flights_table.py) and ``OUT/real_flights.json``.

It is an app-layer command because it runs seven stages (sim, train, evaluate, export, parity,
ingest, detect) that no stage may import side by side. A stage that fails stops it with its
one-line error; a log that ingest or detect refuses is a row of the refusals list, not an error.
The logs are ``../shared/data/flightlogs`` beside a checkout; from an installed package ``--logs``
names them.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path
from typing import Callable

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import ExecSettings, add_executor_args, session

LOGS = ("px4_quad_6s_uavcan_mission.ulg", "px4_quad_6s_vibration_tipover.ulg", "px4_quad_6s_gps_interference.ulg",
        "px4_fmuv5_quad_real_short.ulg", "px4_quad_battery_monitor_disconnected.ulg", "px4_sitl_quad_esc.ulg",
        "ardupilot_copter_quadx_ground.BIN")
ESC_LOGS = {"px4_quad_6s_uavcan_mission.ulg", "px4_quad_6s_vibration_tipover.ulg", "px4_sitl_quad_esc.ulg"}
MISSION = "px4_quad_6s_uavcan_mission.ulg"
MISSION_GAP_FACTOR = 7.0  # the mission's logging gaps: bridged up to 7 x the median interval
PROFILES = {"min": "flightlog-min", "esc": "flightlog-esc", "nocur": "flightlog-nocur"}
CASES = tuple((net, rt, pr) for net in ("cnode", "gru") for rt in ("ort", "cpp") for pr in ("fp32", "int8"))
SIM_STAGE = ("config.toml", "dataset.npz", ".stages/sim.json")
APPLY_TRAIN_SEEDS, APPLY_SIM_SEEDS = [0], [1]


def default_logs() -> Path:
    """``../shared/data/flightlogs`` beside the checkout this package runs from."""
    return Path(__file__).resolve().parents[2] / "shared" / "data" / "flightlogs"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("real-flights", help="the realistic suite's models of each channel profile on every shared "
                                            "real quad log (sim, train, evaluate, export, parity, ingest, detect)",
                       description="Simulate the realistic suite once; for each channel profile train, apply, "
                                   "evaluate, export and check (parity on the host) its networks; run quadfdi detect "
                                   "with each export on every shared real quad log (both networks, runtimes and "
                                   "precisions); write OUT/real_flights.md and OUT/real_flights.json.")
    add_config_args(p)
    p.set_defaults(config="configs/realistic.toml")
    add_executor_args(p)
    workers = next(a for a in p._actions if a.dest == "workers")
    workers.default, workers.help = 1, "worker processes for the sim and apply jobs (default: 1, in this process)"
    p.add_argument("out", metavar="OUT", help="folder for the runs, the detect outputs and real_flights.md")
    p.add_argument("--profiles", default="min,nocur,esc", help="comma-separated, of " + ", ".join(PROFILES))
    p.add_argument("--logs", default=None, help="the folder of real flight logs (default: ../shared/data/flightlogs "
                                                "beside the checkout)")
    p.add_argument("--flights", default=None, help="comma-separated log file names in --logs (default: "
                                                   + ", ".join(LOGS) + ")")
    p.set_defaults(func=run_real_flights)


def _checked_args(args: argparse.Namespace) -> tuple[list[str], Path, list[str]]:
    """(profiles, logs folder, log names), or a one-line QuadfdiError before anything is written."""
    profs = [p for p in args.profiles.split(",") if p]
    if not profs or set(profs) - set(PROFILES):
        raise QuadfdiError(f"--profiles takes comma-separated names of {', '.join(PROFILES)}, found {args.profiles!r}")
    if args.logs is None:
        logs = default_logs()
        if not logs.is_dir():
            raise QuadfdiError(f"no flight log folder: give --logs DIR (the default, ../shared/data/flightlogs "
                               f"beside a checkout, is not at {logs})")
    else:
        logs = Path(args.logs)
        if not logs.is_dir():
            raise QuadfdiError(f"--logs {logs}: no such folder")
    names = [n for n in args.flights.split(",") if n] if args.flights else list(LOGS)
    missing = [n for n in names if not (logs / n).is_file()]
    if not names or missing:
        raise QuadfdiError(f"{logs}: no log {', '.join(missing) or '(none named)'}")
    return profs, logs.resolve(), names


def run_real_flights(args: argparse.Namespace) -> int:
    from quadfdi.core.atomic import write_text
    from quadfdi.core.config import load_config
    from quadfdi.core.jsonio import write_json
    from quadfdi.real_flights_table import markdown

    profs, logs, names = _checked_args(args)
    cfg = load_config(args.config, args.overrides)
    out = Path(args.out)
    settings = ExecSettings.from_args(args)
    with session(settings):
        _sim(out / "base", cfg, settings)
        exports = {p: model(out, p, settings) for p in profs}
    results = detect_all(out / "flights", exports, logs, names)
    gap7 = detect_all(out / "flights_gap7", exports, logs, [n for n in names if n == MISSION], MISSION_GAP_FACTOR)
    text = markdown(results, gap7, MISSION_GAP_FACTOR)
    write_json(out / "real_flights.json", {"logs": str(logs), "exports": {p: str(e) for p, e in exports.items()},
                                            "flights": results, "flights_gap7": gap7}, indent=1)
    write_text(out / "real_flights.md", text)
    print(text)
    return 0


def _sim(run_dir: Path, cfg, settings: ExecSettings) -> None:
    from quadfdi.core.rundir import create_run
    from quadfdi.sim.cli import generate_into

    print(f"real-flights: sim into {run_dir}", flush=True)
    generate_into(create_run(run_dir, cfg), cfg, settings=settings)


def model(out: Path, prof: str, settings: ExecSettings, log: Callable[[str], None] = print) -> Path:
    """Profile ``prof``'s export, from the sim stage in ``out / "base"`` (module docstring, step 2)."""
    from quadfdi.core.rundir import open_run
    from quadfdi.evaluate.run import evaluate_run
    from quadfdi.export.run import export_run
    from quadfdi.parity.run import parity_run
    from quadfdi.train.run import train_run
    from quadfdi.train.study_apply import run_apply, with_stage_train

    run_dir = out / prof
    shutil.rmtree(run_dir, ignore_errors=True)
    for name in SIM_STAGE:
        (run_dir / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(out / "base" / name, run_dir / name)
    profile = [f"train.profile={PROFILES[prof]}"]
    log(f"real-flights: {PROFILES[prof]}: train, apply, evaluate, export, parity in {run_dir}")
    run, cfg = open_run(run_dir, profile, need=("dataset",))
    train_run(run, cfg, cfg.train.model)
    run, cfg = open_run(run_dir, need=("dataset",))  # apply takes [train] from the networks just trained
    run_apply(run, with_stage_train(run, cfg), APPLY_TRAIN_SEEDS, APPLY_SIM_SEEDS, settings)
    evaluate_run(run.root, cfg, f"quadfdi evaluate --run {run.root}")
    export_run(run, cfg, alarm_from="evaluation")
    parity_run(run, cfg, mcu=False, command=f"quadfdi parity --run {run.root} --no-mcu")
    return run.export


def _ingest(log: Path, out: Path, gap: float | None) -> tuple[Path | None, str | None]:
    """(flight.npz, None) or (None, ingest's one-line refusal)."""
    from quadfdi.core.jsonio import write_json
    from quadfdi.core.resample import GAP_FACTOR
    from quadfdi.formats.flight import write_flight
    from quadfdi.ingest import segments
    from quadfdi.ingest.cli import summary
    from quadfdi.ingest.flight import ingest

    shutil.rmtree(out, ignore_errors=True)
    try:
        lr, arrays = ingest(str(log), segments.MIN_AIRBORNE_S, GAP_FACTOR if gap is None else gap)
    except QuadfdiError as exc:
        return None, " ".join(str(exc).split())
    write_flight(out / "flight.npz", arrays)
    write_json(out / "ingest.json", summary(lr, arrays))
    return out / "flight.npz", None


def detect_all(out: Path, exports: dict[str, Path], logs: Path, names: list[str],
               gap: float | None = None) -> list[dict]:
    """Every case (module docstring, step 3) of every log: one dict each, with ``record`` (what
    alarms.json holds) or ``refused`` (the one-line reason)."""
    from quadfdi.detect.run import detect, write_detect

    results = []
    for name in names:
        stem = name.split(".")[0]
        flight, refused = _ingest(logs / name, out / "ingest" / stem, gap)
        for prof, export in exports.items():
            if prof == "esc" and name not in ESC_LOGS:
                continue
            shutil.rmtree(out / prof / stem, ignore_errors=True)
            for net, rt, pr in CASES:
                case = {"profile": PROFILES[prof], "flight": stem, "net": net, "runtime": rt, "precision": pr}
                if flight is None:
                    case["refused"] = f"ingest: {refused}"
                else:
                    try:
                        result = detect(export, flight, net, pr, rt)
                        write_detect(out / prof / stem / net / rt / pr, result, log=lambda _: None)
                        case["record"] = result["record"]
                    except QuadfdiError as exc:
                        case["refused"] = " ".join(str(exc).split())
                print(prof, stem, net, rt, pr, "refused: " + case["refused"][:160] if "refused" in case else "ok",
                      flush=True)
                results.append(case)
    return results
