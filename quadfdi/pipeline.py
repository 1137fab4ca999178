"""``quadfdi run``: every stage that exists, in order, into one run folder."""

from __future__ import annotations

import argparse
import time

from quadfdi.cli import add_config_args
from quadfdi.config import load_config
from quadfdi.rundir import create_run


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the whole pipeline (sim, plots, ...) into one run folder")
    add_config_args(p)
    p.add_argument("--out", default="runs/paper", help="run folder (default: %(default)s)")
    p.set_defaults(func=run_all)


def run_all(args: argparse.Namespace) -> int:
    from sim.cli import default_plot_rows, generate_into
    from sim.dataset import load_dataset
    from sim.plot import plot_trajectory

    cfg = load_config(args.config, args.overrides)
    run = create_run(args.out, cfg)
    t0 = time.perf_counter()
    generate_into(run, cfg)
    ds = load_dataset(run.dataset)
    for row in default_plot_rows(ds):
        plot_trajectory(ds, row, run.figures / f"sim_traj{row}.png")
    print(f"sim: {run.dataset} and plots in {time.perf_counter() - t0:.1f} s")
    return 0
