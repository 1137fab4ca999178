"""``quadfdi check --run R``: recover an interrupted publish and verify every published stage.

Every file a stage record lists must have its recorded sha256, and every stage's inputs must
still be the published ones; the first disagreement is a one-line error (exit 2). This is also
"the next command" of the fault-injection tests: it brings a killed run to a published state.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from quadfdi.core import records
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.stage import recover_run


def check_run(root: Path) -> list[str]:
    """Recover ``root`` and verify it; the lines to print (what recovery did, one per stage)."""
    if not root.is_dir():
        raise QuadfdiError(f"run folder {root} does not exist")
    lines = [f"recovered: {what}" for what in recover_run(root)]
    recs, damaged = records.scan_records(root)
    if not recs and not damaged:
        raise QuadfdiError(f"{root} has no published stage ({root / records.STAGES} is empty): run quadfdi sim first")
    for stage, rec in recs.items():
        for entry in rec["outputs"]:
            path = records.confined(root, entry["path"], f".stages/{stage}.json")
            if not path.is_file() or path.is_symlink() or records.sha256_file(path) != entry["sha256"]:
                raise QuadfdiError(f"{path} is missing or differs from the sha256 recorded in .stages/{stage}.json: "
                                   f"re-run quadfdi {stage}")
        try:  # stale is a consistent state (a stage upstream was re-run): the next stage refuses it
            records.check_upstream(root, stage, rec)
            note = ""
        except QuadfdiError as exc:
            note = f"; stale: {exc}"
        lines.append(f"{stage}: {len(rec['outputs'])} files match .stages/{stage}.json "
                     f"(published {rec.get('published_utc', '?')}){note}")
    if damaged:
        stage, why = next(iter(damaged.items()))
        raise QuadfdiError(f"{'; '.join(lines)}; but {why} (re-run quadfdi {stage}; the other stages are intact)")
    return lines


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("check", help="recover an interrupted run folder and verify every published file")
    p.add_argument("--run", required=True, help="run folder (e.g. runs/paper)")
    p.set_defaults(func=run_check)


def run_check(args: argparse.Namespace) -> int:
    for line in check_run(Path(args.run)):
        print(line)
    return 0
