"""``quadfdi``: one console script, a subcommand per stage.

Each stage package has a thin ``cli`` module with ``add_parser(subparsers)``; it is imported
lazily so that ``quadfdi sim`` never pays for importing torch. Any ``QuadfdiError`` (bad
input) is printed as one line and exits with code 2; a usage error exits with code 2 too
(argparse's convention).
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys

from quadfdi.core.errors import QuadfdiError

STAGES = {
    "sim": "quadfdi.sim.cli",
    "train": "quadfdi.train.cli",
    "export": "quadfdi.export.cli",
    "parity": "quadfdi.parity.cli",
    "solvers": "quadfdi.solverstudy.cli",
    "bench": "quadfdi.bench.cli",
    "ingest": "quadfdi.ingest.cli",
    "detect": "quadfdi.detect.cli",
    "stream-file": "quadfdi.detect.stream_cli",
    "realism": "quadfdi.realism.cli",
    "vehicle": "quadfdi.vehicle.cli",
    "evaluate": "quadfdi.evaluate.cli",
    "report": "quadfdi.report",
    "check": "quadfdi.check",
    "readme": "quadfdi.readme",
    "run": "quadfdi.pipeline",
    "real-flights": "quadfdi.real_flights",
    "crazypad": "quadfdi.crazypad",
    "sweep": "quadfdi.sweep",
}
DESCRIPTION = ("quadfdi: quadrotor fault diagnosis, from the physics simulator to the firmware reference; "
               "one subcommand per stage (quadfdi run: all of them into one run folder).")


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="quadfdi", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="stage", required=True, metavar="{" + ",".join(STAGES) + "}")
    # Only import the stage that was asked for (``--help`` imports them all).
    wanted = [a for a in argv[:1] if a in STAGES] or list(STAGES)
    for name in STAGES:
        if name in wanted:
            module = importlib.import_module(STAGES[name])
            module.add_parser(sub)
        else:
            sub.add_parser(name)
    return parser


class Terminated(BaseException):
    """SIGTERM as an exception, so that a stage's staging folder is removed on the way out."""


def _on_sigterm(signum, frame):  # noqa: ARG001
    raise Terminated()


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, _on_sigterm)
    # A file-size limit (ulimit -f) then fails the write with EFBIG, reported below, instead of
    # killing the process with SIGXFSZ in the middle of a file.
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    try:
        return int(args.func(args) or 0)
    except QuadfdiError as exc:
        print(f"quadfdi {args.stage}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:  # full disk, file-size limit, permissions: the file and the reason
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"quadfdi {args.stage}: error: {where}{exc.strerror or _one_line(exc)}",
              file=sys.stderr)
        return 2
    except MemoryError:
        print(f"quadfdi {args.stage}: error: out of memory; lower the sizes in the config", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"quadfdi {args.stage}: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print(f"quadfdi {args.stage}: terminated (SIGTERM)", file=sys.stderr)
        return 143


if __name__ == "__main__":
    sys.exit(main())
