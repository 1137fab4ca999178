"""The README's results block (``quadfdi readme --run R --block results``), from the seed study's files.

Rewrites ``<!-- results:start -->`` ... ``<!-- results:end -->`` with the headline of the paper's
Table 3 beside ours, narrow enough for the README's 100-character lines: from ``seeds.json``
(``quadfdi train study``) macro F1, any-fault F1, mean detection delay and false-alarm rate per model
(mean ± std over the seeds, three digits) and missed faults in one sentence; the study's own first
line of ``results.md`` (its command, seeds and machine) heads it. The full tables, Table 4's per-class
F1 too, are ``results.md`` itself. Nothing is typed in by hand.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfdi.core.contracts import CLASS_NAMES
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json
from quadfdi.core.tables import md_table
from quadfdi.readme_text import wrap
from quadfdi.train.study import PAPER_TABLE3

OURS = (("cnode", "CNODE"), ("gru", "GRU"), ("baseline", "LogReg"))
PAPER = {"Neural ODE (paper)": "CNODE (paper)", "GRU (paper)": "GRU (paper)"}
COLUMNS = (("macro_f1", "Macro F1"), ("any_fault_f1", "Any-fault F1"), ("mean_detection_delay_s", "Mean delay (s)"),
           ("false_alarm_rate", "False-alarm rate"))


def _ms(values: list) -> str:
    """Mean ± sample std over the seeds, three digits (n/a when no seed has a value)."""
    v = np.array([np.nan if x is None else x for x in values], dtype=float)
    v = v[~np.isnan(v)]
    if v.size == 0:
        return "n/a"
    return f"{v.mean():.3f} ± {v.std(ddof=1) if v.size > 1 else 0.0:.3f}"


def table3(seeds: dict, paper: bool) -> list[str]:
    rows = [[PAPER[name]] + [f"{row[k]:.3f}" if k in row else "not reported" for k, _ in COLUMNS]
            for name, row in (PAPER_TABLE3.items() if paper else ())]
    rows += [[label] + [_ms(seeds[m][k]) for k, _ in COLUMNS] for m, label in OURS if m in seeds]
    return md_table(["Model"] + [h for _, h in COLUMNS], rows)


def results_block(root: Path) -> str:
    path, table = root / "seeds.json", root / "results.md"
    if not path.is_file() or not table.is_file():
        raise QuadfdiError(f"{path} or {table} is missing: run `quadfdi train study --run {root}` first")
    seeds = read_json(path, "seeds.json")
    made = table.read_text().splitlines()[0]
    names = next((tuple(seeds[m]["per_class"]) for m, _ in OURS if m in seeds), CLASS_NAMES)
    paper = names == CLASS_NAMES  # the paper's four classes: its rows beside ours
    missed = ", ".join(f"{label} {np.mean(seeds[m]['missed_faults']):.2f}" for m, label in OURS if m in seeds)
    lines = [*wrap(f"Headline of `results.md`, by `quadfdi readme --run {root} --block results`. {made}"), "",
             "**Table 3 (test split)**", "", *table3(seeds, paper),
             *wrap(f"Missed fault trajectories, mean over seeds: {missed}" + ("; paper: 0 and 0." if paper else "."))]
    return "\n".join(lines)
