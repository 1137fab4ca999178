"""One executor for every sweep: jobs keyed by content, cached in the run folder, run here or on Dask.

A stage turns its work into ``Job``s (a module-level function, its arguments, the cache file named
by ``core.jobcache.job_key``) and calls ``run_jobs(jobs, settings)``. Jobs whose result file is
already there are not run again (resume); the others run

- in this process, one after the other, when there is one worker (``--workers 1``) or one job: no
  Dask import, no cluster start, the same files;
- on Dask otherwise (``core.executor_dask``): a LocalCluster of one single-threaded worker process
  per core (``--scheduler local``), or an existing cluster (``--scheduler tcp://HOST:8786``).

A job is attempted ``ATTEMPTS`` times; one that still fails becomes a failed ``JobResult`` with a
one-line error instead of stopping the others. The scheduler and the number of workers are
execution settings: command-line flags, never part of a config, a key or a result file.

Every worker computes ``core.jobs.canary()``, a fixed small numpy (and torch) computation hashed to 12 hex
digits. Results are promised byte-identical for one numpy/torch build and CPU instruction set; a
cluster whose workers disagree on the canary is refused with each worker named.
"""

from __future__ import annotations

import argparse
import contextlib
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jobcache import is_cached, remove_partial
from quadfdi.core.jobs import ATTEMPTS, Job, JobResult, canary, check_canaries, execute_job, one_line  # noqa: F401 (API)


def add_executor_args(p: argparse.ArgumentParser) -> None:
    """``--scheduler`` and ``--workers``: where the jobs of a sweep run (never part of a result)."""
    p.add_argument("--scheduler", default="local", metavar="local|tcp://HOST:8786",
                   help="'local': a cluster of single-threaded worker processes on this machine (default); "
                        "tcp://HOST:PORT: an existing Dask cluster (see docs/distributed.md)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per core; 1 runs the jobs in "
                        "this process without Dask)")


def strip_executor_args(argv: list[str]) -> list[str]:
    """``argv`` without ``--scheduler``/``--workers``: a command line fit to be written into a result."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a in ("--scheduler", "--workers"):
            skip = True
        elif not a.startswith(("--scheduler=", "--workers=")):
            out.append(a)
    return out


@dataclass(frozen=True)
class ExecSettings:
    scheduler: str = "local"
    workers: int | None = None  # local only; None: one per core

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> "ExecSettings":
        s = cls(getattr(args, "scheduler", "local"), getattr(args, "workers", None))
        s.validate()
        return s

    def validate(self) -> None:
        if self.scheduler != "local" and not self.scheduler.startswith(("tcp://", "tls://")):
            raise QuadfdiError(f"--scheduler must be 'local' or tcp://HOST:PORT (or tls://), not {self.scheduler!r}")
        if self.workers is not None and self.workers < 1:
            raise QuadfdiError(f"--workers must be at least 1, found {self.workers}")
        if self.workers is not None and self.scheduler != "local":
            raise QuadfdiError("--workers sets the size of the local cluster; an existing cluster has its own")

    @property
    def n_local(self) -> int:
        return self.workers or len(os.sched_getaffinity(0))

    def in_process(self, n_jobs: int) -> bool:
        """Run here without Dask: a single local worker, or a single job on the local cluster."""
        return self.scheduler == "local" and (self.n_local == 1 or n_jobs <= 1)


SERIAL = ExecSettings(workers=1)


def _run_here(todo: Sequence[Job], done: Callable[[JobResult], None]) -> None:
    for job in todo:
        err: BaseException | None = None
        for _ in range(ATTEMPTS):  # as Dask's retries: every error is tried again
            try:
                rec = execute_job(job.fn, job.args, str(job.out), job.torch)
            except Exception as exc:  # noqa: BLE001 - any job error becomes a failed row
                err = exc
                continue
            done(JobResult(job, "ran", seconds=rec["seconds"], worker=rec["worker"]))
            break
        else:
            done(JobResult(job, "failed", error=one_line(err) if err else "failed"))


def run_jobs(jobs: Sequence[Job], settings: ExecSettings = SERIAL, desc: str = "jobs", progress: bool = True,
             log: Callable[[str], None] = print) -> list[JobResult]:
    """Run every job not yet cached; one ``JobResult`` per job, in the order of ``jobs``.

    Failed jobs are rows with ``status == 'failed'`` (the caller decides what a failure means);
    nothing is raised for them. Temp files of writers killed mid-write are removed at the end."""
    from tqdm import tqdm

    settings.validate()
    results: dict[int, JobResult] = {}
    todo: list[Job] = []
    first: dict[Path, int] = {}  # a grid may name one job twice: run it once
    for i, job in enumerate(jobs):
        if is_cached(job.out):
            results[i] = JobResult(job, "cached")
        elif job.out not in first:
            todo.append(job)
        first.setdefault(job.out, i)
    index = {id(j): first[j.out] for j in todo}
    n_failed = 0
    with tqdm(total=len(results) + len(todo), initial=len(results), desc=desc, unit="job", disable=not progress) as bar:
        def done(r: JobResult) -> None:
            nonlocal n_failed
            results[index[id(r.job)]] = r
            n_failed += not r.ok
            bar.set_postfix(failed=n_failed, refresh=False)
            bar.update(1)

        try:
            if todo and settings.in_process(len(todo)):
                _run_here(todo, done)
            elif todo:
                from quadfdi.core.executor_dask import run_on_dask

                run_on_dask(todo, settings, done, log)
        finally:  # also when interrupted: the local workers are gone, their temp files go too
            for folder in {j.out.parent for j in jobs}:
                remove_partial(folder)
    return [results.get(i) or _same(results[first[j.out]], j) for i, j in enumerate(jobs)]


def _same(r: JobResult, job: Job) -> JobResult:
    return JobResult(job, r.status, r.error, r.seconds, r.worker, dict(r.info))


@contextlib.contextmanager
def session(settings: ExecSettings, log: Callable[[str], None] = print) -> Iterator[None]:
    """Keep one Dask client (and local cluster) open across the ``run_jobs`` calls inside, so a
    sweep of several steps starts its cluster once. Opens nothing when the jobs run in-process."""
    settings.validate()
    if settings.scheduler == "local" and settings.n_local == 1:
        yield
        return
    from quadfdi.core.executor_dask import held_client

    with held_client(settings, log):
        yield


def failures(results: Sequence[JobResult]) -> list[JobResult]:
    return [r for r in results if not r.ok]
