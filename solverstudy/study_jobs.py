"""The solver study's tasks (``study.study_tasks``: the reference, its check, every setting) as
jobs of ``core.executor``, one job per task, cached in ``<run>/cache/solvers-task/``.

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
from dataclasses import asdict
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


def solve_task(checkpoint: str, windows: str, idx: np.ndarray, task, threads: int) -> dict:
    """One job: ``task`` (a ``study.Task``) on the windows in folder ``windows``; arrays for the cache."""
    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.solverstudy.study import run_task

    model, _ = load_checkpoint(checkpoint, "cnode")
    x = np.load(Path(windows) / "x.npy", mmap_mode="c")  # copy-on-write: torch wants writable arrays
    y = np.load(Path(windows) / "y.npy")
    with torch_threads(threads):
        solves, split = run_task(model, task, x, y, idx)
    return {"logits": solves.logits, "nfe": solves.nfe, "seconds": solves.seconds,
            "split_macro_f1": np.array([] if split is None else [split], dtype=np.float64)}


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
    """A ``study.RunTasks`` that runs each task as a job on ``settings``' executor."""
    from quadfdi.solverstudy.study import Solves

    def run_all(tasks: list, idx: np.ndarray, x: np.ndarray, y: np.ndarray) -> list:
        # hashed once here, not once per job: a fleet's dataset is gigabytes
        inputs = {"dataset_sha256": file_sha256(run.dataset), "checkpoint_sha256": file_sha256(checkpoint)}
        folder = windows_folder(run, inputs, x, y)
        threads = int(cfg.solvers.threads)
        jobs = []
        for t in tasks:
            args = {"task": asdict(t), "sample": [int(i) for i in idx], "threads": threads, **inputs}
            k = job_key(KIND, {}, args, packages=PACKAGES)
            jobs.append(Job(KIND, k, solve_task, (str(checkpoint), str(folder), idx, t, threads),
                            cache_path(run.root, KIND, k, "npz"), label=t.setting.label, torch=True))
        with session(settings, log):
            results = run_jobs(jobs, settings, desc="solver settings", log=log)
        bad = failures(results)
        if bad:
            raise QuadfdiError(f"{len(bad)} of {len(jobs)} solver-study jobs failed ({bad[0].job.label}: "
                               f"{bad[0].error}); the others are cached: run the same command again to resume")
        out = []
        for j in jobs:
            r = read_result(j.out)
            split = r["split_macro_f1"]
            out.append((Solves(r["logits"], r["nfe"], r["seconds"]), float(split[0]) if len(split) else None))
        shutil.rmtree(folder, ignore_errors=True)  # the results hold what the study needs
        return out
    return run_all
