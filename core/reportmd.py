"""Pieces every stage's section of report.md is made of (each stage owns its section's content).

A stage's ``report_section(run_root) -> list[str]`` returns markdown lines: its heading and body
when its files are there, ``not_run(heading, reason)`` when they are not; a file that is there but
unreadable is a one-line QuadfdiError (core.jsonio.read_json, core.npzio.read_npz), never skipped.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

from quadfdi.core.jsonio import read_json


def num(x: float | None, nd: int = 1) -> str:
    return "—" if x is None else f"{x:,.{nd}f}"


def pct(x: float | None, nd: int = 2) -> str:
    return "—" if x is None else f"{100 * x:.{nd}f} %"


def over_bound_clause(check: dict, unit: str = "window") -> str:
    """How many windows (or other ``unit``s: a replayed flight's steps) an fp32 check had past its bound and
    how they were judged against float32 rounding (runtimes.pytorch.rounding_judgement), as a clause for a
    message or a report ("" when none or not counted)."""
    n, allowed = check.get("windows_over_bound"), check.get("over_bound_allowed")
    if not n:
        return ""
    if n > allowed:
        return f"; on {n} {unit}s (at most {allowed} may be, each within float32 rounding)"
    ratio = format(check["over_bound_rounding_ratio"], ".3g")
    which = f"1 {unit}, {ratio} x its" if n == 1 else f"{n} {unit}s, {ratio} x their"
    return f"; on {which} float32 rounding spread (at most {check['rounding_factor']:g})"


def demote(markdown: str, levels: int = 1) -> list[str]:
    """Headings ``levels`` down (outside code fences), so an included report nests under a section."""
    out = []
    fence = False
    for line in markdown.splitlines():
        if line.startswith("```"):
            fence = not fence
        out.append(("#" * levels + line) if line.startswith("#") and not fence else line)
    return out + [""]


def figure_links(run_root: Path, names: Sequence[str], rel: str = "figures") -> list[str]:
    """Image links to those of ``names`` that exist in ``run_root/rel``, then a blank line."""
    return [f"![{n}]({rel}/{n})" for n in names if (Path(run_root) / rel / n).is_file()] + ([""] if names else [])


def not_run(heading: str, reason: str) -> list[str]:
    """The section of a stage whose files are not in the run folder: its heading and one line."""
    return [heading, "", f"Not run: {reason}.", ""]


def optional_json(path: Path, what: str) -> Any | None:
    """A stage's JSON file: None when it is absent (the stage has not run), its content when it reads,
    a one-line QuadfdiError when it is there but truncated or foreign."""
    return read_json(path, what) if Path(path).is_file() else None
