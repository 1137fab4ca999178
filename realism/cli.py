"""``quadfdi realism --run RUN [--logs LOG...]``: the simulator's telemetry against real flights, written
to <run>/realism/ (realism.md, realism.json, realism_<group>.png). Without ``--logs``, the run config's
``[run] realism_logs``: paths relative to the source tree of a checkout (the shared logs beside it,
which carry their own licences and are not in the wheel) or absolute ones."""

from __future__ import annotations

import argparse
import shlex
import sys


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("realism", help="compare a run's simulated telemetry with real flight logs",
                       description="Compare <run>/dataset.npz with real PX4/ArduPilot logs on steady segments.")
    p.add_argument("--run", required=True, help="run folder holding dataset.npz")
    p.add_argument("--logs", nargs="+", metavar="LOG",
                   help="real flight logs (.ulg, .BIN); default: the run config's [run] realism_logs")
    p.add_argument("--mass", action="append", default=[], metavar="LOG=KG",
                   help="take-off mass of a log's vehicle (file name = kg), for current per kg; repeatable")
    p.set_defaults(func=run)


def parse_masses(items: list[str]) -> dict[str, float]:
    from pathlib import Path

    from quadfdi.core.errors import QuadfdiError

    out = {}
    for item in items:
        name, _, kg = item.rpartition("=")
        try:
            out[Path(name).name] = float(kg)
        except ValueError:
            raise QuadfdiError(f"--mass {item!r}: expected LOG=KG, e.g. flight.ulg=2.4") from None
        if not name or out[Path(name).name] <= 0:
            raise QuadfdiError(f"--mass {item!r}: expected LOG=KG with a positive mass")
    return out


def run(args: argparse.Namespace) -> int:
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.core.rundir import open_run

    run_dir, cfg = open_run(args.run, need=("dataset",))
    logs = args.logs
    if not logs:
        logs, why = listed_logs(cfg.run.realism_logs)
        if not logs:
            raise QuadfdiError(f"no real logs to compare with: name them with --logs LOG... "
                               f"({why or 'the run config has no [run] realism_logs'})")
    command = "quadfdi realism " + shlex.join(sys.argv[2:] if sys.argv[1:2] == ["realism"] else ["--run", args.run, "--logs", *logs])
    realism_into(run_dir, logs, parse_masses(args.mass), command)
    return 0


def listed_logs(listed: tuple[str, ...]) -> tuple[list[str], str | None]:
    """[run] realism_logs as paths, and why some were left out (None when none was). A relative path is
    relative to the source tree (core.resources.source_tree): an installed wheel, which has none, takes
    the absolute paths alone."""
    from pathlib import Path

    from quadfdi.core.resources import source_tree

    root = source_tree()
    logs = [str(p if Path(p).is_absolute() else (root / p).resolve()) for p in listed if root or Path(p).is_absolute()]
    if len(logs) == len(listed):
        return logs, None
    left = "skipped" if not logs else f"{len(listed) - len(logs)} of {len(listed)} logs skipped"
    return logs, (f"{left}: [run] realism_logs names logs relative to a quadfdi checkout, and this quadfdi is "
                  "installed from a wheel; name your own by absolute path: "
                  "--set 'run.realism_logs=[\"/path/flight.ulg\"]'")


def realism_into(run_dir, logs: list[str], masses: dict[str, float] | None = None, command: str | None = None) -> None:
    """Compare ``run_dir``'s dataset with ``logs`` and publish <run>/realism/ as one stage."""
    from pathlib import Path

    from quadfdi.core.errors import QuadfdiError
    from quadfdi.core.stage import stage
    from quadfdi.realism.compare import compare
    from quadfdi.realism.report import write

    missing = [p for p in logs if not Path(p).is_file()]
    if missing:
        raise QuadfdiError(f"realism: no such log {missing[0]}")
    command = command or "quadfdi realism " + shlex.join(["--run", str(run_dir.root), "--logs", *map(str, logs)])
    with stage(run_dir.root, "realism", {}, targets=("realism/realism.json",)) as st:  # published as one unit
        res = compare(st.consume("dataset.npz"), logs, masses or {})
        written = write(res, st.out / "realism", command)
    for path in written:
        print(f"wrote {run_dir.root / path.relative_to(st.out)}")
    none = [r["log"] for r in res["real"] if not r["segments"]]
    if none:
        print(f"no qualifying steady segment: {', '.join(none)}")
