"""``quadfdi realism --run RUN --logs LOG...``: the simulator's telemetry against real flights, written
to <run>/realism/ (realism.md, realism.json, realism_<group>.png)."""

from __future__ import annotations

import argparse
import shlex
import sys


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("realism", help="compare a run's simulated telemetry with real flight logs",
                       description="Compare <run>/dataset.npz with real PX4/ArduPilot logs on steady segments.")
    p.add_argument("--run", required=True, help="run folder holding dataset.npz")
    p.add_argument("--logs", nargs="+", required=True, metavar="LOG", help="real flight logs (.ulg, .BIN)")
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
    from quadfdi.core.rundir import open_run

    run_dir, _ = open_run(args.run, need=("dataset",))
    command = "quadfdi realism " + shlex.join(sys.argv[2:] if sys.argv[1:2] == ["realism"] else ["--run", args.run, "--logs", *args.logs])
    realism_into(run_dir, args.logs, parse_masses(args.mass), command)
    return 0


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
