"""``quadfdi bench``: latency, memory, machine limits and the solver study of a run -> bench.json, report.md.

    quadfdi bench --run runs/<name> [--quick] [--skip-solvers] [--skip-cpp] [--cpus 0,1] [--fwref PATH]
    quadfdi bench report --run runs/<name>        redraw the bench figures, rewrite report.md (no measuring)
    quadfdi bench limits [--quick] [--cpus 0,1]   print the machine limits as JSON
    quadfdi bench solvers --run ...               the solver study alone (bench/cli_solvers.py)
    quadfdi bench solver-matrix --run ...         the train-solver by deploy-solver matrix (bench/cli_solvers.py)
    quadfdi bench solver-render --run ...         redraw the solver figures and markdown from their JSON

``bench_run`` (bench/run.py) does the work; docs/bench.md describes bench.json.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys

from core.errors import QuadfdiError


def _command(args: argparse.Namespace) -> str:
    return "quadfdi " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if len(sys.argv) > 1 else \
        f"quadfdi bench --run {args.run}"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from core.cliargs import add_config_args

    p = sub.add_parser("bench", help="latency, memory and solver benchmarks of a run (bench.json, report.md)",
                       description=__doc__.splitlines()[0])
    p.add_argument("--run", default=None, help="run folder with an export (e.g. runs/paper)")
    p.add_argument("--quick", action="store_true",
                   help="tiny measurement: few windows, 1 thread, spinning off, a small solver study (for tests)")
    p.add_argument("--skip-solvers", action="store_true",
                   help="do not run the solver study (an existing bench/solvers.json is still reported)")
    p.add_argument("--skip-cpp", action="store_true", help="do not measure the C++ reference (no build either)")
    p.add_argument("--cpus", default="0,1", help="CPUs every benchmark process is pinned to (default: %(default)s)")
    p.add_argument("--fwref", default=None,
                   help="fwref_infer program (default: firmware_ref/build/fwref_infer, built if missing)")
    add_config_args(p, config=False)
    p.set_defaults(func=run_bench)
    acts = p.add_subparsers(dest="action", metavar="{report,limits,solvers,solver-matrix,solver-render}")
    pr = acts.add_parser("report", help="redraw the bench figures and rewrite report.md from the run's files")
    pr.add_argument("--run", required=True, help="run folder")
    pr.set_defaults(func=run_report)
    pl = acts.add_parser("limits", help="measure peak GFLOP/s, L2 bandwidth and ORT's call cost; print JSON")
    pl.add_argument("--quick", action="store_true")
    pl.add_argument("--cpus", default="0,1", help="CPUs to pin to (default: %(default)s)")
    pl.set_defaults(func=run_limits)
    try:
        from bench.cli_solvers import add_render_args, add_solver_args, run_render, run_solvers
    except ImportError:
        return
    ps = acts.add_parser("solvers", help="fixed against adaptive solvers on one trained CNODE")
    add_solver_args(ps)
    ps.set_defaults(func=run_solvers)
    # add_matrix_args imports torch and scikit-learn for its defaults; building it for every
    # `quadfdi bench ...` would add seconds to each, so this stub takes the arguments verbatim
    # ("+" as its only prefix: "--run" is an ordinary word to it) and the real parser runs on demand.
    pm = acts.add_parser("solver-matrix", help="train-solver by deploy-solver matrix and control representations",
                         add_help=False, prefix_chars="+")
    pm.add_argument("argv", nargs=argparse.REMAINDER)
    pm.set_defaults(func=run_solver_matrix)
    pn = acts.add_parser("solver-render", help="redraw the solver figures and markdown from their JSON files")
    add_render_args(pn)
    pn.set_defaults(func=run_render)


def run_solver_matrix(args: argparse.Namespace) -> int:
    from bench.cli_solvers import add_matrix_args, run_matrix_cmd

    p = argparse.ArgumentParser(prog="quadfdi bench solver-matrix",
                                description="Train-solver by deploy-solver matrix and control representations.")
    add_matrix_args(p)
    return run_matrix_cmd(p.parse_args(args.argv))


def run_bench(args: argparse.Namespace) -> int:
    from bench.run import bench_run
    from core.rundir import open_run

    if args.run is None:
        raise QuadfdiError("quadfdi bench needs --run <run folder> (a run with an export: quadfdi export --run ...)")
    run, cfg = open_run(args.run, args.overrides, need=("dataset", "export"))
    bench_run(run, cfg, quick=args.quick, skip_solvers=args.skip_solvers, skip_cpp=args.skip_cpp, cpus=args.cpus,
              fwref=args.fwref,
              command=_command(args))
    return 0


def run_report(args: argparse.Namespace) -> int:
    from pathlib import Path

    from bench.report import draw_bench_figures, write_run_report

    root = Path(args.run)
    if not root.is_dir():
        raise QuadfdiError(f"run folder {root} does not exist")
    bench_path = root / "bench.json"
    if bench_path.is_file():
        try:
            bench = json.loads(bench_path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise QuadfdiError(f"{bench_path} cannot be read as JSON (truncated or foreign file?): {exc}") from None
        if bench.get("schema_version") != 1 or "latency" not in bench:
            raise QuadfdiError(f"{bench_path} is not a quadfdi bench.json of schema version 1 (re-run quadfdi bench)")
        for f in draw_bench_figures(bench, root / "figures"):
            print(f"wrote {f}")
    print(f"wrote {write_run_report(root)}")
    return 0


def run_limits(args: argparse.Namespace) -> int:
    from bench.limits import measure_limits

    limits = measure_limits(args.cpus, args.quick, log=lambda s: print(s, file=sys.stderr))
    print(json.dumps(limits, indent=1))
    return 0
