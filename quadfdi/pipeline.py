"""``quadfdi run``: every stage, in order, into one run folder, with each stage's time.

sim, plots, train, export, parity, solvers (the solver study, ``solverstudy.run.study_run``),
bench, report: each a library call with the run folder and its config; no command lines are built.
The solver study's settings are the config's ``[solvers]`` section, bench's its ``[bench]`` section.
"""

from __future__ import annotations

import argparse
import time
from typing import Callable

from core.cliargs import add_config_args
from core.config import Config, load_config
from core.rundir import RunDir, create_run
from core.runlock import run_lock


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the whole pipeline (sim, train, export, parity, solvers, bench, report) "
                                   "into one run folder")
    add_config_args(p)
    p.add_argument("--out", default="runs/paper", help="run folder (default: %(default)s)")
    p.set_defaults(func=run_all)


def _sim(run: RunDir, cfg: Config) -> None:
    from sim.cli import generate_into

    generate_into(run, cfg)


def _plots(run: RunDir, cfg: Config) -> None:
    from sim.cli import plots_into

    plots_into(run, cfg)


def _train(run: RunDir, cfg: Config) -> None:
    from train.run import train_run

    train_run(run, cfg, cfg.train.model)


def _export(run: RunDir, cfg: Config) -> None:
    from export.run import export_run

    export_run(run, cfg)


def _parity(run: RunDir, cfg: Config) -> None:
    from parity.run import parity_run

    parity_run(run, cfg)


def _solvers(run: RunDir, cfg: Config) -> None:
    from solverstudy.run import study_run

    study_run(run, cfg)


def _bench(run: RunDir, cfg: Config) -> None:
    from bench.run import bench_run

    bench_run(run, cfg)


def _report(run: RunDir, cfg: Config) -> None:
    from quadfdi.report import write_run_report

    write_run_report(run.root, log=print)


STAGES: tuple[tuple[str, Callable[[RunDir, Config], None]], ...] = (
    ("sim", _sim), ("plots", _plots), ("train", _train), ("export", _export), ("parity", _parity),
    ("solvers", _solvers), ("bench", _bench), ("report", _report))


def run_stages(run: RunDir, cfg: Config, stages=STAGES, log: Callable[[str], None] = print) -> dict[str, float]:
    """Run ``stages`` in order on ``run``; seconds per stage."""
    timings = {}
    for name, stage in stages:
        t0 = time.perf_counter()
        stage(run, cfg)
        timings[name] = time.perf_counter() - t0
    log("stage times: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items())
        + f"; total {sum(timings.values()):.0f} s")
    return timings


def run_all(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, args.overrides)
    run = create_run(args.out, cfg)
    with run_lock(run.root):  # one writer for the whole pipeline; each stage re-enters the lock
        run_stages(run, cfg)
    print(f"report: {run.root / 'report.md'}")
    return 0
