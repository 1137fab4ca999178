"""``quadfdi bench``: latency, memory and machine limits of a run's deployed runtimes -> bench.json.

    quadfdi bench --run runs/<name> [--quick] [--skip-cpp] [--cpus 0,1] [--fwref PATH] [--set bench.key=value]
    quadfdi bench limits [--quick] [--cpus 0,1]   print the machine limits as JSON
    quadfdi bench kernels --run runs/<name> [--fwref PATH] [--json FILE]
                                                  C++ instructions per kernel and per MAC (callgrind, bench/kernels.py)
    quadfdi bench stream --run runs/<name> [--flights N] [--cpus 0] [--fwref PATH] [--json FILE]
                                                  the streaming runtime alone (bench/stream.py): print its
                                                  report section; bench.json is not touched

The measurement settings are the run's ``[bench]`` config section (``--set bench.windows=100``);
``bench_run`` (bench/run.py) does the work; docs/bench.md describes bench.json. report.md is
rewritten by ``quadfdi report --run runs/<name>`` (and at the end of ``quadfdi run``).
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
from pathlib import Path

from quadfdi.core.errors import QuadfdiError

DESCRIPTION = "Latency, memory and machine limits of a run's deployed runtimes -> bench.json."


def _command(args: argparse.Namespace) -> str:
    return "quadfdi " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if len(sys.argv) > 1 else \
        f"quadfdi bench --run {args.run}"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from quadfdi.core.cliargs import add_config_args
    from quadfdi.bench.config import BenchConfig

    p = sub.add_parser("bench", help="latency, memory and limits of a run's deployed runtimes (bench.json)",
                       description=DESCRIPTION)
    p.add_argument("--run", default=None, help="run folder with an export (e.g. runs/paper)")
    p.add_argument("--quick", action="store_true",
                   help="tiny measurement: few windows, 1 thread, spinning off (for tests)")
    p.add_argument("--skip-cpp", action="store_true", help="do not measure the C++ reference (no build either)")
    p.add_argument("--cpus", default=None,
                   help="CPUs every benchmark process is pinned to (default: the run's bench.cpus)")
    p.add_argument("--fwref", default=None,
                   help="fwref_infer program (default: the per-user build cache's, built if missing)")
    add_config_args(p, config=False)
    p.set_defaults(func=run_bench)
    acts = p.add_subparsers(dest="action", metavar="{limits,kernels,stream}")
    pl = acts.add_parser("limits", help="measure peak GFLOP/s, L2 bandwidth and ORT's call cost; print JSON")
    pl.add_argument("--quick", action="store_true")
    pl.add_argument("--cpus", default=BenchConfig.cpus, help="CPUs to pin to (default: %(default)s)")
    pl.set_defaults(func=run_limits)
    pk = acts.add_parser("kernels", help="C++ instructions per kernel and per MAC (callgrind, 8 minus 4 windows)")
    pk.add_argument("--run", required=True, help="run folder with an export and a dataset (e.g. runs/paper)")
    pk.add_argument("--fwref", default=None,
                    help="fwref_infer program (default: the per-user build cache's, built if missing)")
    pk.add_argument("--json", default=None, help="also write the records to this JSON file")
    pk.set_defaults(func=run_kernels)
    ps = acts.add_parser("stream", help="fwref_stream's latency per sample and per decision, and the stream "
                         "object's memory (print; bench.json untouched)")
    ps.add_argument("--run", required=True, help="run folder with an export and a dataset")
    ps.add_argument("--flights", type=int, default=BenchConfig.stream_flights, help="test flights (default: %(default)s)")
    ps.add_argument("--cpus", default=BenchConfig.cpus, help="CPUs to pin to (default: %(default)s)")
    ps.add_argument("--fwref", default=None, help="fwref_infer whose build holds fwref_stream (default: the per-user build cache)")
    ps.add_argument("--json", default=None, help="also write the section to this JSON file")
    ps.set_defaults(func=run_stream)


def run_bench(args: argparse.Namespace) -> int:
    from quadfdi.bench.run import bench_run
    from quadfdi.core.rundir import open_run

    if args.run is None:
        raise QuadfdiError("quadfdi bench needs --run <run folder> (a run with an export: quadfdi export --run ...)")
    run, cfg = open_run(args.run, args.overrides, need=("dataset", "export"))
    bench_run(run, cfg, quick=args.quick, skip_cpp=args.skip_cpp, cpus=args.cpus, fwref=args.fwref,
              command=_command(args))
    return 0


def run_limits(args: argparse.Namespace) -> int:
    from quadfdi.bench.limits import measure_limits

    limits = measure_limits(args.cpus, args.quick, log=lambda s: print(s, file=sys.stderr))
    print(json.dumps(limits, indent=1))
    return 0


def run_kernels(args: argparse.Namespace) -> int:
    """Print the per-kernel instruction table of the run's weights.bin (bench.kernels)."""
    from quadfdi.bench.kernels import kernel_counts, kernels_table
    from quadfdi.bench.latency import find_fwref
    from quadfdi.bench.run import test_windows
    from quadfdi.core.jsonio import write_json
    from quadfdi.core.rundir import open_run
    from quadfdi.formats.export_folder import Export

    run, _cfg = open_run(args.run, [], need=("dataset", "export"))
    export = Export.open(run.export)
    fwref, how = find_fwref(args.fwref, log=lambda s: print(s, file=sys.stderr))
    if fwref is None:
        raise QuadfdiError(f"no fwref_infer to count: {how}")
    records = kernel_counts(fwref, str(export.weights_path), test_windows(run, export).x, export.manifest)
    kernels = Path(fwref).parent / "fwref_kernels"  # absent when find_fwref built fwref_infer alone
    # --info under valgrind, as the counts ran: valgrind hides AVX-512 from cpuid, so on an AVX-512 CPU the int8
    # kernel the counts saw is the AVX2 one, not the one this CPU picks natively
    info = subprocess.run(["valgrind", "--tool=none", "-q", str(kernels), "--info"], capture_output=True, text=True) \
        if kernels.is_file() else subprocess.CompletedProcess([], 1, "", "")
    print(f"fwref_infer: {fwref}")
    print(info.stdout.strip() or "(fwref_kernels --info not available)")
    print("\n".join(kernels_table(records)))
    if args.json:
        write_json(Path(args.json), {"fwref": fwref, "kernel_info": info.stdout.strip(), "records": records})
    return 0


def run_stream(args: argparse.Namespace) -> int:
    """The stream section alone (bench.stream), printed as report.md would show it."""
    from quadfdi.bench.latency import check_cpus
    from quadfdi.bench.report_stream import stream_report
    from quadfdi.bench.stream import stream_section
    from quadfdi.core.jsonio import write_json
    from quadfdi.core.rundir import open_run
    from quadfdi.formats.export_folder import Export

    cpus = check_cpus(args.cpus)
    if args.flights < 1:
        raise QuadfdiError(f"--flights must be 1 or more, found {args.flights}")
    run, _cfg = open_run(args.run, [], need=("dataset", "export"))
    section = stream_section(run.root, Export.open(run.export), args.fwref, cpus, args.flights,
                             log=lambda s: print(s, file=sys.stderr))
    print("\n".join(stream_report({"stream": section})))
    if args.json:
        write_json(Path(args.json), section, indent=1)
    return 0 if not section.get("skipped") else 2
