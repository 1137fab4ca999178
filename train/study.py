"""The multi-seed study: train every model with several seeds, write seeds.json and a results
table side by side with the paper's Tables 3 and 4 (mean ± std over the seeds)."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Callable

import numpy as np

from core.atomic import write_text
from core.config import Config, replace_section
from core.contracts import CLASS_NAMES
from core.errors import QuadfdiError
from core.jsonio import to_jsonable, write_json
from core.rundir import RunDir
from sim.dataset import load_dataset
from train.figures import SHORT
from train.metrics import summarize_seeds

# The paper's Tables 3 and 4 (seed paper, Section IV-B).
PAPER_TABLE3 = {
    "Neural ODE (paper)": {"accuracy": 0.9818, "macro_f1": 0.9828, "weighted_f1": 0.9818, "mcc": 0.9743,
                           "any_fault_f1": 0.9846, "any_fault_roc_auc": 0.9976, "mean_detection_delay_s": 0.401,
                           "missed_faults": 0},
    "GRU (paper)": {"accuracy": 0.9667, "macro_f1": 0.9702, "weighted_f1": 0.9665, "mcc": 0.9528,
                    "any_fault_f1": 0.9705, "any_fault_roc_auc": 0.9918, "mean_detection_delay_s": 0.374,
                    "missed_faults": 0},
}
PAPER_TABLE4 = {"Neural ODE (paper)": (0.9799, 0.9909, 0.9819, 0.9786), "GRU (paper)": (0.9617, 0.9977, 0.9899, 0.9314)}
TABLE3_KEYS = ("accuracy", "macro_f1", "weighted_f1", "mcc", "any_fault_f1", "any_fault_roc_auc",
               "mean_detection_delay_s", "missed_faults", "false_alarm_rate")
OURS = {"cnode": "Neural ODE (quadfdi)", "gru": "GRU (quadfdi)", "baseline": "LogReg baseline (quadfdi)"}
README_START, README_END = "<!-- results:start -->", "<!-- results:end -->"


def _fmt(values: list, digits: int = 4) -> str:
    arr = np.array([np.nan if v is None else v for v in values], dtype=float)
    if np.all(np.isnan(arr)):
        return "n/a"
    finite = arr[~np.isnan(arr)]
    mean = finite.mean()
    std = finite.std(ddof=1) if len(finite) > 1 else 0.0  # sample std over seeds
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def results_table(seeds: dict, seed_list: list[int], command: str) -> str:
    head3 = "| Model | Accuracy | Macro F1 | Weighted F1 | MCC | Any-fault F1 | Any-fault ROC-AUC | Mean delay (s) | Missed faults | False-alarm rate |"
    lines = [f"Made by `{command}` (seeds {', '.join(map(str, seed_list))}; mean ± std over seeds).", "",
             "**Table 3 (test split)**", "", head3, "|" + "---|" * 10]
    for name, row in PAPER_TABLE3.items():
        cells = [f"{row[k]:.4f}" if k != "missed_faults" else str(row[k]) for k in TABLE3_KEYS[:-1]] + ["not reported"]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    for model, name in OURS.items():
        if model in seeds:
            cells = [_fmt(seeds[model][k], 2 if k == "missed_faults" else 4) for k in TABLE3_KEYS]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "**Table 4 (per-class F1, test split)**", "", "| Model | " + " | ".join(SHORT) + " |",
              "|---" * (len(SHORT) + 1) + "|"]
    for name, row in PAPER_TABLE4.items():
        lines.append(f"| {name} | " + " | ".join(f"{v:.4f}" for v in row) + " |")
    for model, name in OURS.items():
        if model in seeds:
            lines.append(f"| {name} | " + " | ".join(_fmt(seeds[model]["per_class"][c]["f1"]) for c in CLASS_NAMES) + " |")
    return "\n".join(lines) + "\n"


_RESULTS = re.compile(re.escape(README_START) + ".*?" + re.escape(README_END), re.S)


def check_readme(readme: Path) -> str:
    """The text of ``readme``; a one-line error when it is missing or has no results markers.

    Called before the study trains anything, so a wrong ``--readme`` costs seconds, not the study.
    """
    if not readme.is_file():
        raise QuadfdiError(f"{readme} does not exist: --readme needs a README with the results markers")
    text = readme.read_text()
    if not _RESULTS.search(text):
        raise QuadfdiError(f"{readme} has no results markers to replace ({README_START} ... {README_END})")
    return text


def update_readme(readme: Path, table: str) -> None:
    """Replace the text between the results markers of ``readme`` with ``table``; the rest is kept byte for byte."""
    text = check_readme(readme)
    write_text(readme, _RESULTS.sub(lambda _: f"{README_START}\n{table}{README_END}", text, count=1))


def run_study(run: RunDir, cfg: Config, seeds: list[int], command: str, log: Callable[[str], None] = print) -> dict:
    from core.stage import stage

    sections = cfg.to_dict()
    with stage(run.root, "study", {"sim": sections["sim"], "train": sections["train"]},
               targets=("seeds.json", "results.md")) as st:
        ds = load_dataset(st.consume("dataset.npz", ("sim",)))
        return _study_into(RunDir(st.out), ds, cfg, seeds, command, log)


def _study_into(out: RunDir, ds, cfg: Config, seeds: list[int], command: str, log: Callable[[str], None]) -> dict:
    from train.run import train_all

    per_seed, timings = [], []
    for seed in seeds:
        t0 = time.perf_counter()
        result = train_all(ds, replace_section(cfg, "train", seed=seed), ["cnode", "gru"], log)
        per_seed.append(result["metrics"])
        timings.append(time.perf_counter() - t0)
        log(f"seed {seed}: done in {timings[-1]:.0f} s")
    by_model = {model: summarize_seeds([m[model] for m in per_seed]) for model in per_seed[0]}
    seeds_json = to_jsonable(by_model)
    seeds_json["seeds"] = list(seeds)
    seeds_json["seconds_per_seed"] = timings
    write_json(out.root / "seeds.json", seeds_json, indent=2)
    table = results_table(by_model, seeds, command)
    write_text(out.root / "results.md", table)
    return {"seeds": seeds_json, "table": table}
