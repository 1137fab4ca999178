"""The multi-seed study: train every model with several seeds, write seeds.json and a results
table side by side with the paper's Tables 3 and 4 (mean ± std over the seeds)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Callable

import numpy as np

from quadfdi.core.atomic import write_text
from quadfdi.core.config import Config
from quadfdi.core.contracts import CLASS_NAMES
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import to_jsonable, write_json
from quadfdi.core.rundir import RunDir
from quadfdi.train.figures import short_names
from quadfdi.train.metrics import summarize_seeds

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


def results_table(seeds: dict, seed_list: list[int], command: str, sim_seeds: list[int] | None = None) -> str:
    """Tables 3 and 4 over the seeds; the per-class columns are the data's classes (the paper's
    rows are shown only beside the paper's four classes: another suite is another task)."""
    head3 = "| Model | Accuracy | Macro F1 | Weighted F1 | MCC | Any-fault F1 | Any-fault ROC-AUC | Mean delay (s) | Missed faults | False-alarm rate |"
    from quadfdi.core.machine import machine_line

    # The machine is part of the result: float kernels differ by CPU, and so do training trajectories.
    over = f"seeds {', '.join(map(str, seed_list))}" if not sim_seeds else \
        f"simulator seeds {', '.join(map(str, sim_seeds))} x training seeds {', '.join(map(str, seed_list))}"
    lines = [f"Made by `{command}` ({over}; mean ± std over seeds) on "
             f"{machine_line()}.", "",
             "**Table 3 (test split)**", "", head3, "|" + "---|" * 10]
    names = next((tuple(seeds[m]["per_class"]) for m in OURS if m in seeds), CLASS_NAMES)
    paper = {} if names != CLASS_NAMES else PAPER_TABLE3
    for name, row in paper.items():
        cells = [f"{row[k]:.4f}" if k != "missed_faults" else str(row[k]) for k in TABLE3_KEYS[:-1]] + ["not reported"]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    for model, name in OURS.items():
        if model in seeds:
            cells = [_fmt(seeds[model][k], 2 if k == "missed_faults" else 4) for k in TABLE3_KEYS]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "**Table 4 (per-class F1, test split)**", "", "| Model | " + " | ".join(short_names(names)) + " |",
              "|---" * (len(names) + 1) + "|"]
    for name, row in (PAPER_TABLE4 if paper else {}).items():
        lines.append(f"| {name} | " + " | ".join(f"{v:.4f}" for v in row) + " |")
    for model, name in OURS.items():
        if model in seeds:
            lines.append(f"| {name} | " + " | ".join(_fmt(seeds[model]["per_class"][c]["f1"]) for c in names) + " |")
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


def run_study(run: RunDir, cfg: Config, seeds: list[int], command: str, log: Callable[[str], None] = print,
              settings=None, sim_seeds: list[int] | None = None) -> dict:
    """The seed study, published as one stage (seeds.json, results.md, the prediction sets it made):
    one job per simulator seed x training seed x model on ``settings``' executor (``core.executor``;
    default: this process), cached in ``<run>/cache/study/``; a job that failed 3 times is listed
    under ``failed`` and left out of its model's summary. ``sim_seeds`` (default: the run's) other
    than the run's are simulated first into ``<run>/sims/seed<S>/`` (train.study_sims). The train
    stage's own networks are reused, not retrained (train.study_reuse). Every prediction set is
    listed in ``predictions/index.json`` once the stage is published."""
    from quadfdi.core.executor import SERIAL
    from quadfdi.formats.predictions import add_entries
    from quadfdi.core.stage import stage
    from quadfdi.train.predsets import drop_missing_entries
    from quadfdi.train.study_reuse import train_stage_results
    from quadfdi.train.study_sims import study_datasets

    sim_seeds = [cfg.sim.seed] if sim_seeds is None else list(sim_seeds)
    data = study_datasets(run, cfg, sim_seeds, settings or SERIAL, log)
    sections = cfg.to_dict()
    with stage(run.root, "study", {"sim": sections["sim"], "train": sections["train"]},
               targets=("seeds.json", "results.md")) as st:
        st.consume("dataset.npz", ("sim",))
        reused = train_stage_results(run, cfg, seeds)
        for got in reused.values():
            st.consume(got["predictions"])
        out = _study_into(run, RunDir(st.out), cfg, seeds, command, log, settings, data, reused)
    add_entries(run.root, out.pop("entries"))
    drop_missing_entries(run.root)
    return out


def _gather(out: RunDir, results, reused: dict, data) -> tuple[dict, dict, list, list]:
    """Per (sim seed, train seed) metrics, job seconds per train seed, failures and index entries;
    the jobs' prediction sets written into the stage's folder ``out``."""
    from quadfdi.core.jobcache import read_result
    from quadfdi.train.predsets import index_entry, write_prediction_set
    from quadfdi.train.study_jobs import split_result

    rel = {d.sim_seed: d.rel for d in data}
    per_run: dict[tuple[int, int], dict] = {}
    seconds: dict[int, float] = {}
    failed, entries = [], []
    for (kind, sim_seed, seed), got in reused.items():
        per_run.setdefault((sim_seed, seed), {}).update(got["metrics"])
        entries.append(index_entry(kind, sim_seed, seed, rel[sim_seed]))
    for r in results:
        c, kind = r.job.args[1], r.job.args[2]
        sim_seed, seed = c.sim.seed, c.train.seed
        seconds[seed] = seconds.get(seed, 0.0) + r.seconds
        if not r.ok:
            failed.append({"seed": seed, "model": kind, "error": r.error, **({"sim_seed": sim_seed} if len(data) > 1 else {})})
            continue
        pred, metrics, extra = split_result(read_result(r.job.out))
        for name, arrays in {kind: pred, **extra}.items():
            entry = index_entry(name, sim_seed, seed, rel[sim_seed])
            write_prediction_set(out.root / entry["predictions"], arrays)
            entries.append(entry)
        mine = per_run.setdefault((sim_seed, seed), {})
        mine[kind] = metrics[kind]
        if "baseline" in metrics:  # one job of a (sim seed, seed) fits it (train.study_jobs.seed_model_jobs)
            mine.setdefault("baseline", metrics["baseline"])
    return per_run, seconds, failed, entries


def _study_into(run: RunDir, out: RunDir, cfg: Config, seeds: list[int], command: str,
                log: Callable[[str], None], settings, data, reused: dict) -> dict:
    from quadfdi.core.executor import SERIAL, run_jobs
    from quadfdi.train.study_jobs import MODELS, seed_model_jobs

    jobs = seed_model_jobs(run, cfg, seeds, data=data, skip=set(reused))
    results = run_jobs(jobs, settings or SERIAL, desc="study", log=log)
    per_run, seconds, failed, entries = _gather(out, results, reused, data)
    order = [(d.sim_seed, s) for d in data for s in seeds]
    by_model = {}
    for model in (*MODELS, "baseline"):
        ok = [per_run[k][model] for k in order if model in per_run.get(k, {})]
        if ok:
            by_model[model] = summarize_seeds(ok)
    seeds_json = to_jsonable(by_model)
    seeds_json["seeds"] = list(seeds)
    if [d.sim_seed for d in data] != [cfg.sim.seed]:  # the lists above run over sim seeds, then seeds
        seeds_json["sim_seeds"] = [d.sim_seed for d in data]
    seeds_json["seconds_per_seed"] = [seconds.get(s, 0.0) for s in seeds]  # job time; 0 for cached or reused jobs
    if failed:
        seeds_json["failed"] = failed
    write_json(out.root / "seeds.json", seeds_json, indent=2)
    table = results_table(by_model, seeds, command, seeds_json.get("sim_seeds"))
    write_text(out.root / "results.md", table)
    return {"seeds": seeds_json, "table": table, "entries": entries}
