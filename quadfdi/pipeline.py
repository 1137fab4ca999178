"""``quadfdi run``: every stage, in order, into one run folder, with each stage's time.

sim, plots, train, study, baselines, evaluate, export, parity, solvers (the solver study,
``solverstudy.run.study_run``), bench, realism, report: each a library call with the run folder, its
config and the executor settings (``--workers``/``--scheduler``: the jobs of sim, study, baselines
and solvers); no command lines are built. ``study`` (simulator seeds x training seeds) runs when ``[run]
study_sim_seeds`` lists seeds and ``realism`` when ``[run] realism_logs`` lists logs; otherwise
they say so and take no time. The solver study's settings are ``[solvers]``, bench's ``[bench]``.
"""

from __future__ import annotations

import argparse
import functools
import time
from typing import Callable

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.config import Config, load_config
from quadfdi.core.executor import SERIAL, ExecSettings, add_executor_args, session
from quadfdi.core.rundir import RunDir, create_run
from quadfdi.core.runlock import run_lock


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the whole pipeline (sim, train, study, baselines, evaluate, export, parity, "
                                   "solvers, bench, realism, report) into one run folder")
    add_config_args(p)
    add_executor_args(p)
    p.add_argument("--out", default="runs/paper", help="run folder (default: %(default)s)")
    p.set_defaults(func=run_all)


def _sim(run: RunDir, cfg: Config, settings: ExecSettings = SERIAL) -> None:
    from quadfdi.sim.cli import generate_into

    generate_into(run, cfg, settings=settings)


def _plots(run: RunDir, cfg: Config) -> None:
    from quadfdi.sim.cli import plots_into

    plots_into(run, cfg)


def _train(run: RunDir, cfg: Config) -> None:
    from quadfdi.train.run import train_run

    train_run(run, cfg, cfg.train.model)


def _study(run: RunDir, cfg: Config, settings: ExecSettings = SERIAL) -> None:
    if not cfg.run.study_sim_seeds:
        print("study: not part of this pipeline ([run] study_sim_seeds is empty; make study runs it)")
        return
    from quadfdi.train.study import run_study

    seeds, sims = list(cfg.train.seeds), list(cfg.run.study_sim_seeds)
    command = (f"quadfdi train study --run {run.root} --sim-seeds {','.join(map(str, sims))} "
               f"--seeds {','.join(map(str, seeds))}")
    run_study(run, cfg, seeds, command, settings=settings, sim_seeds=sims)


def _baselines(run: RunDir, cfg: Config, settings: ExecSettings = SERIAL) -> None:
    from quadfdi.core.profiles import uses_hover
    from quadfdi.train.baselines_run import run_baselines

    # every dataset the index lists (the study's sim seeds); the reference models where [train] asks for them
    _, lines = run_baselines(run.root, cfg.train.seed, reference=cfg.train.baselines_reference,
                             logged=uses_hover(cfg.train.profile), settings=settings)
    print("\n".join(lines))


def _evaluate(run: RunDir, cfg: Config) -> None:
    from quadfdi.evaluate.run import evaluate_run

    evaluate_run(run.root, cfg, f"quadfdi evaluate --run {run.root}")


def _export(run: RunDir, cfg: Config) -> None:
    from quadfdi.export.run import export_run

    # the evaluate stage just chose each network's alarm policy on validation: the export carries those
    chosen = run.evaluation.is_file()
    export_run(run, cfg, alarm_from="evaluation" if chosen else "config")


def _parity(run: RunDir, cfg: Config) -> None:
    from quadfdi.parity.run import parity_run

    parity_run(run, cfg)


def _solvers(run: RunDir, cfg: Config, settings: ExecSettings = SERIAL) -> None:
    from quadfdi.solverstudy.run import study_run

    study_run(run, cfg, settings=settings)


def _bench(run: RunDir, cfg: Config) -> None:
    from quadfdi.bench.run import bench_run

    bench_run(run, cfg)


def _realism(run: RunDir, cfg: Config) -> None:
    if not cfg.run.realism_logs:
        print("realism: not part of this pipeline ([run] realism_logs is empty)")
        return
    from quadfdi.realism.cli import listed_logs, realism_into

    logs, why = listed_logs(cfg.run.realism_logs)
    if why:
        print(f"realism: {why}")
    if logs:
        realism_into(run, logs)


def _report(run: RunDir, cfg: Config) -> None:
    from quadfdi.report import write_run_report

    write_run_report(run.root, log=print)


STAGES: tuple[tuple[str, Callable[..., None]], ...] = (
    ("sim", _sim), ("plots", _plots), ("train", _train), ("study", _study), ("baselines", _baselines),
    ("evaluate", _evaluate), ("export", _export), ("parity", _parity), ("solvers", _solvers), ("bench", _bench),
    ("realism", _realism), ("report", _report))
PARALLEL = ("sim", "study", "baselines", "solvers")  # the stages whose jobs run on the executor


def run_stages(run: RunDir, cfg: Config, stages=STAGES, log: Callable[[str], None] = print,
               settings: ExecSettings = SERIAL) -> dict[str, float]:
    """Run ``stages`` in order on ``run``; seconds per stage. ``settings``: the executor of the
    stages in ``PARALLEL`` (the others run here)."""
    timings = {}
    for name, stage in stages:
        t0 = time.perf_counter()
        (functools.partial(stage, settings=settings) if name in PARALLEL else stage)(run, cfg)
        timings[name] = time.perf_counter() - t0
    log("stage times: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items())
        + f"; total {sum(timings.values()):.0f} s")
    return timings


def run_all(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, args.overrides)
    settings = ExecSettings.from_args(args)
    run = create_run(args.out, cfg)
    with run_lock(run.root), session(settings):  # one writer for the whole pipeline; one cluster for its jobs
        run_stages(run, cfg, settings=settings)
    print(f"report: {run.root / 'report.md'}")
    return 0
