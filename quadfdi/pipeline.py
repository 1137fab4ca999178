"""``quadfdi run``: every stage, in order, into one run folder, with each stage's time."""

from __future__ import annotations

import argparse
import time

from core.cliargs import add_config_args
from core.config import load_config
from core.rundir import create_run

PIPELINE_SOLVER_ARGS = ("--sample", "64")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the whole pipeline (sim, train, export, parity, bench) into one run folder")
    add_config_args(p)
    p.add_argument("--out", default="runs/paper", help="run folder (default: %(default)s)")
    p.set_defaults(func=run_all)


def run_all(args: argparse.Namespace) -> int:
    from sim.cli import default_plot_rows, generate_into
    from sim.dataset import load_dataset
    from sim.plot import plot_trajectory
    from bench.report import write_run_report
    from bench.run import bench_run
    from export.run import export_run
    from parity.run import parity_run
    from train.run import train_run

    cfg = load_config(args.config, args.overrides)
    run = create_run(args.out, cfg)
    timings = {}
    t0 = time.perf_counter()
    generate_into(run, cfg)
    ds = load_dataset(run.dataset)
    for row in default_plot_rows(ds):
        plot_trajectory(ds, row, run.figures / f"sim_traj{row}.png")
    timings["sim"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    train_run(run, cfg, cfg.train.model)
    timings["train"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    export_run(run, cfg)
    timings["export"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    parity_run(run, cfg)
    timings["parity"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    # The solver study on 64 sampled test windows keeps the whole run inside ~20 minutes on
    # 2 cores; `make solvers` runs it on 128 (about 11 minutes by itself).
    bench_run(run, cfg, solver_args=list(PIPELINE_SOLVER_ARGS))
    timings["bench"] = time.perf_counter() - t0
    report = write_run_report(run.root)
    print("stage times: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items())
          + f"; total {sum(timings.values()):.0f} s")
    print(f"report: {report}")
    return 0
