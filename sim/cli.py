"""``quadfdi sim``: generate the dataset; ``quadfdi sim plot``: draw a trajectory;
``quadfdi sim bench``: trajectories per second."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.config import Config, load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import SERIAL, ExecSettings, add_executor_args
from quadfdi.core.rundir import RunDir, create_run, open_run


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


def generate_into(run: RunDir, cfg: Config, show_progress: bool = True, settings: ExecSettings = SERIAL,
                  cache_root: Path | None = None) -> Path:
    """``sim.publish.publish_dataset``: simulate and publish dataset.npz with config.toml."""
    from quadfdi.sim.publish import publish_dataset

    return publish_dataset(run, cfg, show_progress, settings, cache_root)


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
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.sim.plot import plot_trajectory

    run, cfg = open_run(args.run, need=("dataset",))
    if args.out is not None:  # a file outside the run's published state
        from quadfdi.core.stage import check_target

        if Path(args.out).resolve() == run.dataset.resolve():
            raise QuadfdiError(f"--out {args.out} is the input dataset: refusing to write over it")
        check_target(Path(args.out))
        ds = load_dataset(run.dataset)
        rows = _plot_rows(ds, args.traj)
        if len(rows) > 1:
            raise QuadfdiError("--out names one file: give exactly one --traj with it")
        plot_trajectory(ds, rows[0], Path(args.out))
        print(f"wrote {args.out}")
        return 0
    for out in plots_into(run, cfg, args.traj):
        print(f"wrote {out}")
    return 0


def _plot_rows(ds, traj: list[int] | None) -> list[int]:
    rows = traj or default_plot_rows(ds)
    n = ds["telemetry"].shape[0]
    for row in rows:
        if not 0 <= row < n:
            raise QuadfdiError(f"--traj {row} is out of range: the dataset holds trajectories 0..{n - 1}")
    return rows


def plots_into(run: RunDir, cfg: Config, traj: list[int] | None = None) -> list[Path]:
    """Draw trajectories of the published dataset as the ``plots`` stage (figures/sim_traj<i>.png);
    the figures of an earlier ``sim plot`` of the same dataset are kept."""
    from quadfdi.core.stage import stage
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.sim.plot import plot_trajectory

    with stage(run.root, "plots", {"sim": cfg.to_dict()["sim"]}) as st:
        ds = load_dataset(st.consume("dataset.npz", ("sim",)))
        rows = _plot_rows(ds, traj)
        st.carry_previous()
        for row in rows:
            plot_trajectory(ds, row, st.path(f"figures/sim_traj{row}.png"))
    return [run.figures / f"sim_traj{row}.png" for row in rows]


def run_bench(args: argparse.Namespace) -> int:
    """Time ``generate`` on the config (paper scale by default); median over repeats."""
    import statistics

    from quadfdi.sim.simulate import generate

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
