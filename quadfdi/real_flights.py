"""``quadfdi real-flights OUT``: the real-flight tables from nothing. The realistic suite is simulated
once, each channel profile's networks -- the fixed flightlog-min, -nocur and -esc and the masked
flightlog-mask -- are trained on it, applied, evaluated, exported and checked, compared on the
suite's test flights (the masked one under every mask pattern), and every shared real quad log and
every CrazyPAD log then goes through ``quadfdi detect``.

    quadfdi real-flights OUT [--profiles min,nocur,esc,mask] [--logs DIR] [--flights LOG,...]
                             [--crazypad DIR] [--workers N] [--config realistic] [--mask-config realistic-mask]
                             [--set SECTION.KEY=VALUE ...]

1. sim (``--config``, ``--set``) into ``OUT/base`` (sim seed of the config), and sim seed 1 into
   ``OUT/base/sims/seed1``: one simulation that every profile trains and is scored on;
2. per profile P, both datasets linked into ``OUT/P``, then train (``train.profile=flightlog-P``; the
   masked profile with ``--mask-config``'s [train], the ``--set train.*`` overrides on top: its own
   network sizes, the same data), train apply (training seed 0 on sim seed 1), evaluate (each
   network's alarm policy chosen on validation), export with those policies, parity on the host (C++
   against ONNX Runtime and PyTorch; no Cortex-M); for the masked profile also its test flights under
   each mask pattern (train.study_apply.run_patterns);
3. the realistic suite's table (quadfdi/real_flights_suite.py): each network's test flights under
   the policy its evaluation chose -- the masked one also under each pattern, not re-tuned -- with
   flight-bootstrap intervals and the paired difference to flightlog-min;
4. every log (``--flights``, default ``LOGS``) through detect (quadfdi/real_flights_detect.py) with
   each export, both networks, both runtimes (ort, cpp) and both precisions (the flightlog-esc model
   only on logs with ESC telemetry; the UAVCAN mission again with its gaps bridged); every CrazyPAD
   log (``--crazypad``) with the masked export, in ``--workers`` processes
   (quadfdi/real_flights_crazypad.py; the fixed profiles need pitch, which no Crazyflie log has);
5. ``OUT/real_flights.md`` (quadfdi/real_flights_report.py) and ``OUT/real_flights.json``.

``--export DIR`` runs steps 4 and 5 only, with a finished export (quadfdi/real_flights_export.py).

It is an app-layer command because it runs seven stages (sim, train, evaluate, export, parity,
ingest, detect) that no stage may import side by side. A stage that fails stops it with its
one-line error, but for export and parity: a profile whose networks they refuse keeps its suite rows
and decides no log, and the refusal is a line of the tables. A log that ingest or detect refuses is
a row of the refusals, not an error.
The logs are ``../shared/data/flightlogs`` and ``../shared/data/crazypad/motor_data`` beside a
checkout; from an installed package ``--logs`` and ``--crazypad`` name them (without CrazyPAD logs
that part is skipped, in one line).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import time
from pathlib import Path
from typing import Callable

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import ExecSettings, add_executor_args, session

LOGS = ("px4_quad_6s_uavcan_mission.ulg", "px4_quad_6s_vibration_tipover.ulg", "px4_quad_6s_gps_interference.ulg",
        "px4_fmuv5_quad_real_short.ulg", "px4_quad_battery_monitor_disconnected.ulg", "px4_sitl_quad_esc.ulg",
        "ardupilot_copter_quadx_ground.BIN")
PROFILES = {"min": "flightlog-min", "esc": "flightlog-esc", "nocur": "flightlog-nocur", "mask": "flightlog-mask"}
DEFAULT_PROFILES = "min,nocur,esc,mask"
SIM_STAGE = ("config.toml", "dataset.npz", ".stages/sim.json")
APPLY_TRAIN_SEEDS, APPLY_SIM_SEEDS = [0], [1]


def default_logs() -> Path:
    """``../shared/data/flightlogs`` beside the checkout this package runs from."""
    return Path(__file__).resolve().parents[2] / "shared" / "data" / "flightlogs"


def default_crazypad() -> Path:
    """``../shared/data/crazypad/motor_data`` beside the checkout this package runs from."""
    return Path(__file__).resolve().parents[2] / "shared" / "data" / "crazypad" / "motor_data"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("real-flights", help="the realistic suite's models of each channel profile on its test flights "
                                            "(the masked one under every mask pattern), every shared real quad log "
                                            "and every CrazyPAD log (sim, train, evaluate, export, parity, detect)",
                       description="Simulate the realistic suite once; for each channel profile train, apply, "
                                   "evaluate, export and check (parity on the host) its networks; compare them on "
                                   "the suite's test flights (the masked model under every mask pattern); run "
                                   "quadfdi detect with each export on every shared real quad log and with the "
                                   "masked export on every CrazyPAD log (both networks, runtimes and precisions); "
                                   "write OUT/real_flights.md and OUT/real_flights.json.")
    add_config_args(p)
    p.set_defaults(config="realistic")
    add_executor_args(p)
    workers = next(a for a in p._actions if a.dest == "workers")
    workers.help = ("worker processes: of the sim and apply jobs (default 1, in this process) and of the CrazyPAD "
                    "detections (default: one per core)")
    p.add_argument("out", metavar="OUT", help="folder for the runs, the detect outputs and real_flights.md")
    p.add_argument("--profiles", default=DEFAULT_PROFILES, help="comma-separated, of " + ", ".join(PROFILES)
                                                                + " (default: %(default)s)")
    p.add_argument("--mask-config", default="realistic-mask",
                   help="the config whose [train] trains the masked profile; its [sim] is not read: every "
                        "profile trains on --config's simulation (default: %(default)s)")
    p.add_argument("--logs", default=None, help="the folder of real flight logs (default: ../shared/data/flightlogs "
                                                "beside the checkout)")
    p.add_argument("--flights", default=None, help="comma-separated log file names in --logs (default: "
                                                   + ", ".join(LOGS) + ")")
    p.add_argument("--crazypad", default=None, help="the CrazyPAD folder of condition folders of Crazyflie logs "
                                                    "(default: ../shared/data/crazypad/motor_data beside the "
                                                    "checkout; skipped when absent)")
    p.add_argument("--export", default=None, metavar="DIR",
                   help="decide the logs with this finished export (RUN/export) instead: nothing simulated or "
                        "trained, no suite table (quadfdi/real_flights_export.py)")
    p.set_defaults(func=run_real_flights)


def _checked_args(args: argparse.Namespace) -> tuple[list[str], Path, list[str], Path | None]:
    """(profiles, logs folder, log names, CrazyPAD folder or None), or a one-line QuadfdiError before
    anything is written."""
    profs = [p for p in args.profiles.split(",") if p]
    if not profs or set(profs) - set(PROFILES) or len(set(profs)) != len(profs):
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
    crazypad = default_crazypad() if args.crazypad is None else Path(args.crazypad)
    if args.crazypad is not None and not crazypad.is_dir():
        raise QuadfdiError(f"--crazypad {crazypad}: no such folder")
    return profs, logs.resolve(), names, crazypad.resolve() if crazypad.is_dir() else None


def run_real_flights(args: argparse.Namespace) -> int:
    from quadfdi.core.config import load_config
    from quadfdi.real_flights_crazypad import detect_crazypad
    from quadfdi.real_flights_detect import detect_shared
    from quadfdi.real_flights_suite import suite

    checked = _checked_args(args)
    if args.export is not None:
        from quadfdi.real_flights_export import run_export_only

        if args.overrides or args.profiles != DEFAULT_PROFILES or args.config != "realistic" or \
                args.mask_config != "realistic-mask":
            raise QuadfdiError("--export decides the logs with a finished export: --profiles, --set, --config and "
                               "--mask-config do not apply")
        return _write(Path(args.out), run_export_only(args, checked, _command(args)))
    profs, logs, names, crazypad = checked
    cfg = load_config(args.config, args.overrides)
    trains = {p: {"profile": PROFILES[p]} for p in profs}
    if "mask" in profs:
        mask_cfg = load_config(args.mask_config, [o for o in args.overrides if o.startswith("train.")])
        trains["mask"] = dict(_fields(mask_cfg.train), profile=PROFILES["mask"])
    out, times, t0 = Path(args.out), {}, time.monotonic()
    settings = ExecSettings(args.scheduler, args.workers or (1 if args.scheduler == "local" else None))
    settings.validate()
    with session(settings):
        _sim(out / "base", cfg, settings)
        times["sim_s"] = time.monotonic() - t0
        made = {p: model(out, p, settings, trains[p]) for p in profs}
        times["models_s"] = time.monotonic() - t0 - times["sim_s"]
    exports = {p: e for p, e in made.items() if isinstance(e, Path)}
    result = {"command": _command(args), "logs": str(logs), "exports": {p: str(e) for p, e in exports.items()},
              "export_refused": {PROFILES[p]: e for p, e in made.items() if not isinstance(e, Path)},
              "suite": suite(out, {p: PROFILES[p] for p in profs}, cfg)}
    t1 = time.monotonic()
    result.update(detect_shared(out, exports, logs, names, PROFILES))
    times["detect_shared_s"] = time.monotonic() - t1
    result["crazypad"] = None
    if "mask" not in exports or crazypad is None:
        print("real-flights: CrazyPAD logs skipped: " + ("no flightlog-mask export" if "mask" not in exports
                                                         else f"no folder at {default_crazypad()} (give --crazypad DIR)"))
    else:
        result["crazypad"] = detect_crazypad(out / "crazypad", exports["mask"], crazypad, args.workers or os.cpu_count())
    times["total_s"] = time.monotonic() - t0
    result["times"] = {k: round(v, 1) for k, v in times.items()}
    return _write(out, result)


def _write(out: Path, result: dict) -> int:
    """OUT/real_flights.json and .md (quadfdi/real_flights_report.py), the summary printed."""
    from quadfdi.core.atomic import write_text
    from quadfdi.core.jsonio import write_json
    from quadfdi.real_flights_report import markdown

    text = markdown(result)
    write_json(out / "real_flights.json", result, indent=1)
    write_text(out / "real_flights.md", text)
    print(text)
    return 0


def _fields(section) -> dict:
    return {f.name: getattr(section, f.name) for f in dataclasses.fields(section)}


def _command(args: argparse.Namespace) -> str:
    parts = ["quadfdi real-flights", str(args.out)]
    opts = ("export", "logs", "flights", "crazypad", "workers") if args.export else \
        ("profiles", "logs", "flights", "crazypad", "workers", "config", "mask_config")
    for opt in opts:
        value = getattr(args, opt)
        if value is not None and not (opt == "profiles" and value == DEFAULT_PROFILES):
            parts += [f"--{opt.replace('_', '-')}", str(value)]
    return " ".join(parts + [f"--set {o}" for o in args.overrides])


def _sim(run_dir: Path, cfg, settings: ExecSettings) -> None:
    """The suite's dataset (the config's sim seed) and sim seed 1's in ``run_dir/sims/seed1``."""
    from quadfdi.core.rundir import create_run
    from quadfdi.sim.cli import generate_into
    from quadfdi.train.study_sims import study_datasets

    print(f"real-flights: sim into {run_dir}", flush=True)
    run = create_run(run_dir, cfg)
    generate_into(run, cfg, settings=settings)
    study_datasets(run, cfg, [s for s in APPLY_SIM_SEEDS if s != cfg.sim.seed], settings)


def _link(src: Path, dst: Path) -> None:
    """``dst`` the same file as ``src`` (a hard link; a copy across file systems): every stage replaces
    its outputs by renaming, never writes into them, so the runs share one dataset on disk."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy(src, dst)


def model(out: Path, prof: str, settings: ExecSettings, train: dict, log: Callable[[str], None] = print) -> Path | str:
    """Profile ``prof``'s export, from the sim stages in ``out / "base"`` (module docstring, step 2);
    ``train``: the [train] keys that differ from the run's config (its profile at least). An export
    or parity check that refuses the trained networks is the profile's one-line reason instead: the
    networks are evaluated by then, so the suite's table keeps them; no log is decided with them."""
    from quadfdi.core.config import replace_section
    from quadfdi.core.rundir import open_run
    from quadfdi.evaluate.run import evaluate_run
    from quadfdi.export.run import export_run
    from quadfdi.parity.run import parity_run
    from quadfdi.train.run import train_run
    from quadfdi.train.study_apply import run_apply, run_patterns, with_stage_train
    from quadfdi.train.study_sims import sim_seed_folder

    run_dir = out / prof
    shutil.rmtree(run_dir, ignore_errors=True)
    base = open_run(out / "base")[0]
    for seed in [None] + APPLY_SIM_SEEDS:
        src = base if seed is None else sim_seed_folder(base, seed)
        dst = run_dir if seed is None else run_dir / src.root.relative_to(base.root)
        if src.root.is_dir():
            for name in SIM_STAGE:
                _link(src.root / name, dst / name)
    log(f"real-flights: {PROFILES[prof]}: train, apply, evaluate, export, parity in {run_dir}")
    run, cfg = open_run(run_dir, need=("dataset",))
    trained = replace_section(cfg, "train", **train)
    train_run(run, trained, trained.train.model)
    applied = with_stage_train(run, cfg)  # apply takes [train] from the networks just trained
    run_apply(run, applied, APPLY_TRAIN_SEEDS, APPLY_SIM_SEEDS, settings)
    evaluate_run(run.root, cfg, f"quadfdi evaluate --run {run.root}")
    if prof == "mask":
        run_patterns(run, applied, [cfg.sim.seed] + APPLY_SIM_SEEDS, settings)
    try:
        export_run(run, cfg, alarm_from="evaluation")
        parity_run(run, cfg, mcu=False, command=f"quadfdi parity --run {run.root} --no-mcu")
    except QuadfdiError as exc:
        log(f"real-flights: {PROFILES[prof]}: no export, its logs not decided: {exc}")
        return " ".join(str(exc).split())
    return run.export
