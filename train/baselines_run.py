"""``quadfdi train baselines``: the baselines' prediction sets for every dataset of a run folder.

The datasets are the run's ``dataset.npz`` and, with ``which="all"``, every other dataset the run's
prediction index already lists (other simulator seeds, e.g. ``sims/seed1/dataset.npz``). For each
dataset (simulator seed S, read from its embedded config) and baseline seed T, each model of
``train.baselines.MODELS`` gets a prediction set at ``formats.predictions.prediction_path(run, model, S,
T)`` -- every evaluation window (split >= 1) of the dataset, format of formats/predictions.py -- and
``predictions/baselines_sim{S}_train{T}.json`` records the grid, the validation macro F1 of every
configuration, the one chosen, fit times and the training-window cap. The index entries are added
last. The reference models (``train.baselines.REF_MODELS``, asked for with ``reference=True``: the
[train] key ``baselines_reference``) are fitted on the datasets whose vehicles have reference flights;
on any other dataset they are skipped, and the summary says so in one line.

Each dataset's fits are one job of ``core.executor`` (train/baselines_jobs.py: two simulator seeds fit on
two cores at once; a rerun reads finished fits from ``<run>/cache/baselines/``). Nothing else is written
until every dataset has been fitted: a bad dataset (missing, foreign, without validation flights, two
datasets with one simulator seed) stops the command with a one-line ``QuadfdiError`` before any
prediction set, record or index entry changes.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import write_json
from quadfdi.core.npzio import write_npz
from quadfdi.formats.predictions import add_entries, check_prediction_set, prediction_path, read_index
from quadfdi.formats.dataset import load_dataset
from quadfdi.train.baselines import MAX_TRAIN_WINDOWS, MODELS, REF_MODELS

DATASET = "dataset.npz"  # the run's own dataset, relative to the run folder


def record_path(run_root: str | Path, sim_seed: int, train_seed: int) -> Path:
    return Path(run_root) / "predictions" / f"baselines_sim{int(sim_seed)}_train{int(train_seed)}.json"


def run_datasets(run_root: str | Path, which: str = "all") -> list[tuple[str, set[int]]]:
    """(dataset path relative to the run, the sim seeds the index gives it) for every dataset to fit."""
    if which not in ("run", "all"):
        raise QuadfdiError(f"--datasets must be 'run' or 'all', found {which!r}")
    seen: dict[str, set[int]] = {DATASET: set()}
    for e in read_index(run_root) if which == "all" else []:
        seen.setdefault(os.path.normpath(e["dataset"]), set()).add(int(e["sim_seed"]))
    return list(seen.items())


def check_run(run_root: str | Path, which: str = "all") -> list[tuple[str, int]]:
    """(dataset path relative to the run, its simulator seed) for every dataset to fit, each one
    loaded and checked first, so that a bad one stops the command before any fit."""
    root = Path(run_root)
    out: list[tuple[str, int]] = []
    for rel, index_seeds in run_datasets(root, which):
        path = root / rel
        ds = load_dataset(path)
        sim_seed = int(ds.config.sim.seed)
        if index_seeds - {sim_seed}:
            raise QuadfdiError(f"{path}: the prediction index gives it sim seed(s) {sorted(index_seeds)}, "
                               f"its config says {sim_seed}")
        clash = [r for r, s in out if s == sim_seed]
        if clash:
            raise QuadfdiError(f"{rel} and {clash[0]} are both simulator seed {sim_seed}: their prediction sets "
                               f"would overwrite each other")
        codes = set(np.unique(ds["split"]).tolist())
        if not {0, 1} <= codes:
            raise QuadfdiError(f"{path}: the baselines need training (0) and validation (1) flights, "
                               f"found split codes {sorted(codes)}")
        out.append((rel, sim_seed))
    return out


def fit_run(run_root: str | Path, seed: int, which: str = "all", models: Sequence[str] = MODELS,
            cap: int = MAX_TRAIN_WINDOWS, logged: bool = False, settings=None) -> list[dict[str, Any]]:
    """Fit the baselines on every dataset of the run (nothing is written but the jobs' cache): one job per
    dataset on ``settings``' executor (train.baselines_jobs; default: in this process, one dataset in memory
    at a time). ``logged``: on the channels a log carries (train/baselines_channels.py), for a run whose
    networks read a flight-log profile. A dataset whose fit fails stops the command in one line."""
    from quadfdi.core.executor import SERIAL, run_jobs
    from quadfdi.core.jobcache import read_result
    from quadfdi.train.baselines_jobs import dataset_jobs, done_entry

    root = Path(run_root)
    jobs = dataset_jobs(root, check_run(root, which), seed, tuple(models), cap, logged)
    results = run_jobs(jobs, settings or SERIAL, desc="baselines", progress=len(jobs) > 1)
    for r in results:
        if not r.ok:
            raise QuadfdiError(f"baselines on {r.job.args[1]}: {r.error}")
    return [done_entry(read_result(r.job.out)) for r in results]


def write_run(run_root: str | Path, done: list[dict[str, Any]], seed: int, cap: int = MAX_TRAIN_WINDOWS) -> list[Path]:
    """Write the prediction sets and records of ``fit_run``'s results, then add the index entries."""
    root = Path(run_root)
    entries, written = [], []
    for d in done:
        ev, s = d["evals"], d["sim_seed"]
        tried = sorted({len(res.record["validation_macro_f1"]) for res in d["results"].values()})
        # the configurations each baseline fitted (one number: every grid has the same length)
        record = {"dataset": d["dataset"], "sim_seed": s, "train_seed": int(seed),
                  "n_configs": tried[0] if len(tried) == 1 else tried,
                  "max_train_windows": int(cap), "class_names": d["class_names"],
                  "split_names": d["split_names"], "selection": "validation macro F1 (split 1) only",
                  "models": {}}
        for model, res in d["results"].items():
            path = prediction_path(root, model, s, seed)
            arrays = {"proba": res.proba.astype(np.float32), "y_true": ev.y.astype(np.int64),
                      "traj": ev.traj.astype(np.int64), "t_end": ev.t_end.astype(np.float64),
                      "split": ev.split.astype(np.int8), "class_names": np.array(d["class_names"])}
            motor = d.get("motor_proba_ref" if model in REF_MODELS else "motor_proba")
            if motor is not None:
                arrays["motor_proba"] = motor
            check_prediction_set(arrays, str(path))
            path.parent.mkdir(parents=True, exist_ok=True)
            write_npz(path, arrays)
            rel = path.relative_to(root).as_posix()
            record["models"][model] = {**res.record, "predictions": rel}
            entries.append({"model": model, "sim_seed": s, "train_seed": int(seed), "dataset": d["dataset"],
                            "predictions": rel})
            written.append(path)
        write_json(record_path(root, s, seed), record)
        written.append(record_path(root, s, seed))
    written.append(add_entries(root, entries))
    return written


def run_baselines(run_root: str | Path, seed: int, which: str = "all", models: Sequence[str] = MODELS,
                  cap: int = MAX_TRAIN_WINDOWS, reference: bool = False,
                  logged: bool = False, settings=None) -> tuple[list[Path], list[str]]:
    """Fit, then write: the files written (prediction sets, records, the index) and a summary line per
    dataset x model (chosen configuration, macro F1 per split, tuning CPU time); with ``reference``, the
    reference models too (one line per dataset that has no vehicle references: skipped). ``settings``:
    the executor of the fits (``fit_run``)."""
    done = fit_run(run_root, seed, which, tuple(models) + (REF_MODELS if reference else ()), cap, logged, settings)
    written = write_run(run_root, done, seed, cap)
    lines = []
    for d in done:
        if d["skipped"]:
            lines.append(f"sim {d['sim_seed']}: {', '.join(d['skipped'])} skipped: {d['dataset']} has no vehicles "
                         "with reference flights")
        for model, res in d["results"].items():
            r = res.record
            f1 = " ".join(f"{k}={v:.3f}" for k, v in r["macro_f1_by_split"].items())
            lines.append(f"sim {d['sim_seed']} {model}: config {r['chosen']} {r['params']}; macro F1 {f1}; "
                         f"tuning {r['tuning_cpu_seconds']:.1f} s CPU; temperatures {r['temperatures']}")
    return written, lines
