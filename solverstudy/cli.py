"""``quadfdi solvers study|matrix|render --run R [--set solvers.key=value ...]``: the solver study.

    quadfdi solvers study --run runs/<name> [--checkpoint P]   fixed vs adaptive solvers on one trained CNODE
                                                               (one job per setting: --scheduler/--workers)
    quadfdi solvers matrix --run runs/<name> [--reuse]         train-solver by deploy-solver matrix, controls
    quadfdi solvers render --run runs/<name>                   redraw figures and markdown from the JSON

What is measured is the run's config, section [solvers] (docs/solvers.md), changed with
``--set solvers.key=value``; the flags here only say what to read and whether to reuse models.
Outputs: ``runs/<name>/solvers/`` and ``runs/<name>/figures/solver_*.png`` (``solverstudy.run``).
"""

from __future__ import annotations

import argparse
import shlex

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.executor import add_executor_args


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("solvers", help="the ODE-solver study of a trained CNODE and the train-by-deploy matrix",
                       description="The ODE-solver study of a run's CNODE: fixed against adaptive solvers, "
                                   "the train-by-deploy matrix, their report. Settings: config section [solvers].")
    acts = p.add_subparsers(dest="action", required=True, metavar="{study,matrix,render}")
    ps = acts.add_parser("study", help="fixed against adaptive solvers on one trained CNODE (solvers/solvers.json)")
    ps.add_argument("--checkpoint", default=None, help="CNODE checkpoint (default: <run>/cnode.pt)")
    add_executor_args(ps)
    pm = acts.add_parser("matrix", help="train with several solvers, deploy each with each (solvers/solver_matrix.json)")
    pm.add_argument("--reuse", action="store_true",
                    help="in this process, reuse models in <run>/solvers/matrix_models/ trained with the same solver, "
                         "data and settings (without it, the matrix runs as cached jobs on --scheduler/--workers)")
    add_executor_args(pm)
    pr = acts.add_parser("render", help="redraw the solver figures and markdown from their JSON files")
    for q, func in ((ps, run_study_cmd), (pm, run_matrix_cmd), (pr, run_render_cmd)):
        q.add_argument("--run", required=True, help="run folder (e.g. runs/paper)")
        add_config_args(q, config=False)
        q.set_defaults(func=func)


def _command(args: argparse.Namespace) -> str:
    """The command line of this output, rebuilt from the parsed arguments (stored in the JSON)."""
    words = ["quadfdi", "solvers", args.action, "--run", str(args.run)]
    if getattr(args, "checkpoint", None):
        words += ["--checkpoint", args.checkpoint]
    if getattr(args, "reuse", False):
        words.append("--reuse")
    for o in args.overrides:
        words += ["--set", o]
    return shlex.join(words)


def run_study_cmd(args: argparse.Namespace) -> int:
    from quadfdi.core.executor import ExecSettings
    from quadfdi.core.rundir import open_run
    from quadfdi.solverstudy.run import study_run

    settings = ExecSettings.from_args(args)
    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    # one job per setting on --scheduler/--workers, each cached by its key (a rerun resumes)
    study_run(run, cfg, checkpoint=args.checkpoint, command=_command(args), settings=settings)
    return 0


def run_matrix_cmd(args: argparse.Namespace) -> int:
    from quadfdi.core.rundir import open_run
    from quadfdi.solverstudy.run import matrix_run

    from quadfdi.core.executor import ExecSettings

    settings = ExecSettings.from_args(args)
    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    # --reuse keeps the in-process path that reads matrix_models/; otherwise one job per model,
    # reference and cell, each cached by its key (which is what makes a rerun cheap there).
    matrix_run(run, cfg, reuse=args.reuse, command=_command(args), settings=None if args.reuse else settings)
    return 0


def run_render_cmd(args: argparse.Namespace) -> int:
    from quadfdi.core.rundir import open_run
    from quadfdi.solverstudy.run import render

    run, cfg = open_run(args.run, args.overrides)
    render(run.root, cfg)
    return 0
