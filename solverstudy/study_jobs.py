"""The solver study's tasks (``study.study_tasks``: the reference, its check, every setting) as
jobs of ``core.executor``, one job per task, cached in ``<run>/cache/solvers-task/``. An adaptive
setting's batched solve of the whole split (the reference's: the study's longest job by far) is cut
into parts of ``PART_BATCHES`` batches, a job each (``<run>/cache/solvers-split/``):
the parts' batches are the whole solve's, so the logits and the split macro F1 are the same.

The parent writes the test windows once, as plain ``.npy`` files that every job maps copy-on-write
(``<run>/cache/solvers-windows/<key>/``; the key hashes the dataset and the checkpoint, whose
channel profile made them); they are deleted when the study is written, since the jobs' results
hold everything the study needs. A job's key hashes the task, the sample, the thread count, the
dataset and the checkpoint, so an interrupted study resumes where it stopped. Each job solves with
``solvers.threads`` torch threads, as the in-process study does: the same logits and NFE either way;
only the timings differ, and the study says where they were taken (``meta.latency_note``).
"""

from __future__ import annotations

import shutil
from dataclasses import asdict, replace
from pathlib import Path
from typing import Callable

import numpy as np

from quadfdi.core.atomic import atomic_path
from quadfdi.core.config import Config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import ExecSettings, Job, failures, run_jobs, session
from quadfdi.core.jobcache import CACHE_DIR, cache_path, file_sha256, job_key, read_result
from quadfdi.core.rundir import RunDir
from quadfdi.models.threads import torch_threads

PACKAGES = ("sim", "train", "solverstudy")
WINDOWS = "solvers-windows"
KIND = "solvers-task"
PART_KIND = "solvers-split"
PART_BATCHES = 16  # an adaptive setting's split solve in parts of 16 batches of study.SPLIT_BATCH windows, a job each


def solve_task(checkpoint: str, windows: str, idx: np.ndarray, task, batch: int, threads: int) -> dict:
    """One job: ``task`` (a ``study.Task``) on the windows in folder ``windows``; arrays for the cache."""
    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.solverstudy.study import run_task

    model, _ = load_checkpoint(checkpoint, "cnode")
    x = np.load(Path(windows) / "x.npy", mmap_mode="c")  # copy-on-write: torch wants writable arrays
    y = np.load(Path(windows) / "y.npy")
    with torch_threads(threads):
        solves, split = run_task(model, task, x, y, idx, batch)
    return {"logits": solves.logits, "nfe": solves.nfe, "seconds": solves.seconds,
            "split_macro_f1": np.array([] if split is None else [split], dtype=np.float64)}


def solve_split_part(checkpoint: str, windows: str, setting, start: int, stop: int, batch: int, threads: int) -> dict:
    """One job: ``setting``'s batched solve of windows [start, stop) of the split (``start`` a multiple of
    ``batch``: the batches of the whole split's solve, so the same logits)."""
    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.solverstudy.study import solve_batched

    model, _ = load_checkpoint(checkpoint, "cnode")
    x = np.load(Path(windows) / "x.npy", mmap_mode="c")[start:stop]
    with torch_threads(threads):
        logits, _ = solve_batched(model, setting, x, batch=batch)
    return {"logits": logits}


def windows_folder(run: RunDir, inputs: dict, x: np.ndarray, y: np.ndarray) -> Path:
    """The test windows as ``x.npy``/``y.npy`` in the run's cache (written once; renamed into place whole)."""
    key = job_key(WINDOWS, {}, inputs, packages=PACKAGES)
    folder = run.root / CACHE_DIR / WINDOWS / key
    if not (folder / "y.npy").is_file():  # y is written last: its presence means both are whole
        for name, arr in (("x.npy", x), ("y.npy", y)):
            with atomic_path(folder / name) as fh:
                np.save(fh, np.ascontiguousarray(arr), allow_pickle=False)
    return folder


def executor_tasks(run: RunDir, cfg: Config, checkpoint: Path, settings: ExecSettings,
                   log: Callable[[str], None]) -> Callable:
    """A ``study.RunTasks`` that runs each task as a job on ``settings``' executor; an adaptive setting's
    solve of the whole split (the reference's: the study's longest) as parts of ``PART_BATCHES`` batches."""
    def run_all(tasks: list, idx: np.ndarray, x: np.ndarray, y: np.ndarray) -> list:
        from quadfdi.solverstudy import study

        # hashed once here, not once per job: a fleet's dataset is gigabytes
        inputs = {"dataset_sha256": file_sha256(run.dataset), "checkpoint_sha256": file_sha256(checkpoint)}
        folder = windows_folder(run, inputs, x, y)
        common = {"threads": int(cfg.solvers.threads), **inputs}
        jobs, parts = [], {}
        for i, t in enumerate(tasks):
            if t.split and not t.setting.is_fixed:
                parts[i] = _part_jobs(run, checkpoint, folder, t.setting, len(y), study.SPLIT_BATCH, common)
                t = replace(t, split=False)
            args = {"task": asdict(t), "sample": [int(j) for j in idx], "batch": study.SPLIT_BATCH, **common}
            k = job_key(KIND, {}, args, packages=PACKAGES)
            jobs.append(Job(KIND, k, solve_task, (str(checkpoint), str(folder), idx, t, study.SPLIT_BATCH,
                                                  common["threads"]),
                            cache_path(run.root, KIND, k, "npz"), label=t.setting.label, torch=True))
        every = [j for js in parts.values() for j in js] + jobs  # the longest first
        with session(settings, log):
            results = run_jobs(every, settings, desc="solver settings", log=log)
        bad = failures(results)
        if bad:
            raise QuadfdiError(f"{len(bad)} of {len(every)} solver-study jobs failed ({bad[0].job.label}: "
                               f"{bad[0].error}); the others are cached: run the same command again to resume")
        out = []
        for i, j in enumerate(jobs):
            r = read_result(j.out)
            split = r["split_macro_f1"]
            f1 = float(split[0]) if len(split) else None
            if i in parts:
                f1 = study.macro_f1(y, np.concatenate([read_result(p.out)["logits"] for p in parts[i]]))
            out.append((study.Solves(r["logits"], r["nfe"], r["seconds"]), f1))
        shutil.rmtree(folder, ignore_errors=True)  # the results hold what the study needs
        return out
    return run_all


def _part_jobs(run: RunDir, checkpoint: Path, folder: Path, setting, n: int, batch: int, common: dict) -> list[Job]:
    """The jobs of ``setting``'s batched solve of the n windows of the split, ``PART_BATCHES`` batches each."""
    size = PART_BATCHES * batch
    jobs = []
    for start in range(0, n, size):
        stop = min(n, start + size)
        args = {"setting": asdict(setting), "part": [start, stop], "batch": batch, **common}
        k = job_key(PART_KIND, {}, args, packages=PACKAGES)
        jobs.append(Job(PART_KIND, k, solve_split_part,
                        (str(checkpoint), str(folder), setting, start, stop, batch, common["threads"]),
                        cache_path(run.root, PART_KIND, k, "npz"), label=f"{setting.label} [{start}, {stop})",
                        torch=True))
    return jobs
