"""``quadfdi evaluate --run RUN [--set section.key=value]``: every prediction set the run's index
lists, under the protocol of docs/evaluation.md, into <run>/evaluation/ (evaluation.json,
evaluation.md, alarm_sweep.png)."""

from __future__ import annotations

import argparse
import shlex
import sys


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="evaluate every indexed prediction set (intervals, alarms, paired differences)",
                       description="Evaluate <run>/predictions/index.json: window macro F1, false alarms per "
                                   "flight-hour, detection delays, localisation, paired bootstrap differences; the "
                                   "alarm policy is chosen on validation flights.")
    p.add_argument("--run", required=True, help="run folder holding predictions/index.json")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", dest="overrides",
                   help="override a config value ([alarm], [evaluate]); repeatable")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from quadfdi.core.rundir import open_run

    run_dir, cfg = open_run(args.run, args.overrides)  # a missing run or a bad override: refused before scipy loads
    from quadfdi.evaluate.run import evaluate_run

    argv = sys.argv[2:] if sys.argv[1:2] == ["evaluate"] else ["--run", args.run]
    for path in evaluate_run(run_dir.root, cfg, "quadfdi evaluate " + shlex.join(argv)):
        print(f"wrote {path}")
    return 0
