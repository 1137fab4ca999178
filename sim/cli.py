"""``quadfdi sim``: generate the dataset; ``quadfdi sim plot``: draw a trajectory;
``quadfdi sim bench``: trajectories per second."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from core.cliargs import add_config_args
from core.config import Config, load_config
from core.errors import QuadfdiError
from core.executor import SERIAL, ExecSettings, add_executor_args
from core.rundir import RunDir, create_run, open_run


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sim", help="simulate flights and write dataset.npz",
                       description="Simulate the paper's dataset into <out>/dataset.npz.")
    add_config_args(p)
    p.add_argument("--out", default=None, help="run folder to write (e.g. runs/paper)")
    add_executor_args(p)
    p.set_defaults(func=run_generate)
    acts = p.add_subparsers(dest="action", metavar="{plot,bench}")
    pp = acts.add_parser("plot", help="draw one trajectory of a run's dataset")
    pp.add_argument("--run", required=True, help="run folder holding dataset.npz")
    pp.add_argument("--traj", type=int, action="append", default=None,
                    help="dataset row(s) to draw (default: the first test trajectory of each fault class)")
    pp.add_argument("--out", default=None, help="PNG path (default: <run>/figures/sim_traj<i>.png)")
    pp.set_defaults(func=run_plot)
    pb = acts.add_parser("bench", help="measure generation speed (trajectories per second)")
    add_config_args(pb)
    pb.add_argument("--repeat", type=int, default=3, help="timed repetitions (default: %(default)s)")
    pb.set_defaults(func=run_bench)


def generate_into(run: RunDir, cfg: Config, show_progress: bool = True, settings: ExecSettings = SERIAL) -> Path:
    """Simulate ``cfg.sim`` in shards of ``sim.chunk`` trajectories on ``settings``' executor and write
    ``run.dataset`` (atomically); finished shards stay cached in ``<run>/cache/sim/``, so an
    interrupted run resumes. Return the dataset's path."""
    from sim.shards import generate_sharded

    return generate_sharded(run, cfg, settings, progress=show_progress)


def run_generate(args: argparse.Namespace) -> int:
    if args.out is None:
        raise QuadfdiError("quadfdi sim needs --out <run folder>")
    settings = ExecSettings.from_args(args)
    cfg = load_config(args.config, args.overrides)
    run = create_run(args.out, cfg)
    path = generate_into(run, cfg, settings=settings)
    print(f"wrote {path}")
    return 0


def default_plot_rows(ds) -> list[int]:
    """The first test trajectory of each fault class (the paper's Figs. 13-27 show one each)."""
    import numpy as np

    rows = []
    for cls in (1, 2, 3):
        hits = np.flatnonzero((ds["fault_class"] == cls) & (ds["split"] == 2))
        if len(hits) == 0:
            hits = np.flatnonzero(ds["fault_class"] == cls)
        if len(hits):
            rows.append(int(hits[0]))
    return rows or [0]


def run_plot(args: argparse.Namespace) -> int:
    from sim.dataset import load_dataset
    from sim.plot import plot_trajectory

    run, _ = open_run(args.run, need=("dataset",))
    ds = load_dataset(run.dataset)
    rows = args.traj or default_plot_rows(ds)
    n = ds["telemetry"].shape[0]
    for row in rows:
        if not 0 <= row < n:
            raise QuadfdiError(f"--traj {row} is out of range: the dataset holds trajectories 0..{n - 1}")
    if args.out is not None and len(rows) > 1:
        raise QuadfdiError("--out names one file: give exactly one --traj with it")
    for row in rows:
        out = Path(args.out) if args.out else run.figures / f"sim_traj{row}.png"
        plot_trajectory(ds, row, out)
        print(f"wrote {out}")
    return 0


def run_bench(args: argparse.Namespace) -> int:
    """Time ``generate`` on the config (paper scale by default); median over repeats."""
    import statistics

    from sim.simulate import generate

    cfg = load_config(args.config, args.overrides)
    generate(cfg.sim, indices=range(min(8, cfg.sim.n_traj)))  # warm-up: imports, page faults
    times = []
    for _ in range(max(1, args.repeat)):
        t0 = time.perf_counter()
        generate(cfg.sim)
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    print(f"sim bench: {cfg.sim.n_traj} trajectories x {cfg.sim.duration_s:g} s "
          f"({cfg.sim.n_samples} samples, {cfg.sim.substeps} substeps each): "
          f"median {med:.2f} s over {len(times)} runs = {cfg.sim.n_traj / med:.0f} trajectories/s "
          f"(runs: {', '.join(f'{t:.2f}' for t in times)} s)")
    return 0
