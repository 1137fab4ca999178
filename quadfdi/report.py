"""report.md: one markdown report of a whole run, assembled from every stage's own section.

    quadfdi report --run runs/<name> [--html]   redraw the bench figures, rewrite report.md (no
                                                measuring); with --html also report.html (report_html)

Each stage owns its section and reads only its own files: ``report_section(run_root) -> list[str]``
in sim.report, train.report, evaluate.report, quadfdi.comparison (the networks against the baselines,
from evaluation.json, the parity outputs and the export manifest), export.report, parity.report, bench.report, solverstudy.report,
realism.report and quadfdi.crazypad_report (RUN/crazypad, when ``quadfdi crazypad`` wrote there),
in that order, after a headline made of the bullets of ``headline(run_root)`` (train, export, bench
and solverstudy). A stage whose files are absent says "Not run" under its
heading; a file that is there but unreadable stops the report with a one-line QuadfdiError.
Figures that no section links come last, under "Other figures".
"""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path
from typing import Callable

from quadfdi.core.atomic import write_text
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.reportmd import figure_links

SECTIONS = ("quadfdi.sim.report", "quadfdi.train.report", "quadfdi.evaluate.report", "quadfdi.comparison",
            "quadfdi.export.report", "quadfdi.parity.report", "quadfdi.bench.report",
            "quadfdi.solverstudy.report", "quadfdi.realism.report", "quadfdi.crazypad_report")
HEADLINES = ("quadfdi.train.report", "quadfdi.evaluate.report", "quadfdi.export.report", "quadfdi.bench.report", "quadfdi.solverstudy.report")


def headline(root: Path) -> list[str]:
    out = []
    for name in HEADLINES:
        out += importlib.import_module(name).headline(root)
    return (["## Headline", ""] + out + [""]) if out else []


def sections(root: Path) -> list[str]:
    out = []
    for name in SECTIONS:
        out += importlib.import_module(name).report_section(root)
    return out


def run_report_markdown(run_root: str | Path) -> str:
    root = Path(run_root)
    if not root.is_dir():
        raise QuadfdiError(f"run folder {root} does not exist")
    lines = [f"# quadfdi run report: {root.name}", "",
             f"Assembled by `quadfdi report` from the files in `{root}` (regenerate with "
             f"`quadfdi report --run {root}`): one section per stage, written by that stage.", ""]
    lines += headline(root)
    lines += sections(root)
    text = "\n".join(lines)
    fig_dir = root / "figures"
    unlinked = sorted(p.name for p in fig_dir.glob("*.png") if f"figures/{p.name}" not in text) \
        if fig_dir.is_dir() else []
    if unlinked:
        lines += ["## Other figures", ""] + figure_links(root, unlinked)
    return "\n".join(lines).rstrip() + "\n"


def write_run_report(run_root: str | Path, log: Callable[[str], None] | None = None, html: bool = False) -> Path:
    """Write ``runs/<name>/report.md`` (atomically) from the run folder's files, and with ``html`` the
    page ``report.html`` and its ``plotly.min.js``; return report.md's path."""
    from quadfdi.core.stage import stage

    root = Path(run_root)
    text = run_report_markdown(root)
    path = root / "report.md"
    targets = ("report.md",) + (("report.html", "plotly.min.js") if html else ())
    with stage(root, "report", {}, targets=targets) as st:  # published like every stage's output
        write_text(st.path("report.md"), text)
        if html:
            from quadfdi.detect.html import write_plotly_js
            from quadfdi.report_html import report_html

            write_text(st.path("report.html"), report_html(root, text))
            write_plotly_js(st.out)
    if log:
        log(f"wrote {path}" + (f" and {root / 'report.html'}" if html else ""))
    return path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="rewrite a run's report.md (--html: and report.html) from its files",
                       description="Rewrite a run's report.md (and with --html report.html) from the files its "
                                   "stages wrote; no measuring.")
    p.add_argument("--run", required=True, help="run folder (e.g. runs/paper)")
    p.add_argument("--html", action="store_true",
                   help="also write report.html: the same report as one page with interactive figures")
    p.set_defaults(func=run_report)


def run_report(args: argparse.Namespace) -> int:
    from quadfdi.bench.report import redraw_figures

    root = Path(args.run)
    if not root.is_dir():
        raise QuadfdiError(f"run folder {root} does not exist")
    if (root / ".stages" / "bench.json").is_file():  # the figures are bench's outputs: republished as bench's
        from quadfdi.core.stage import stage

        with stage(root, "bench", {}) as st:
            st.redo_previous(("bench.json",))
            for f in redraw_figures(root, st.out):
                print(f"wrote {root / f.relative_to(st.out)}")
    write_run_report(root, log=print, html=args.html)
    return 0
