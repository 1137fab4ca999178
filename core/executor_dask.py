"""The Dask side of ``core.executor``: the client from the flags, one thread per worker, the canary
check, and the loop that gathers results as they come. Imported only when jobs run on Dask, so a
stage that runs in one process never imports Dask."""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
from collections.abc import Callable, Iterator, Sequence

import dask
from distributed import Client, LocalCluster, as_completed
from distributed.diagnostics.plugin import WorkerPlugin

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jobs import ATTEMPTS, Job, JobResult, canary, check_canaries, describe, execute_job, one_line

# One job per worker process, one core per job: BLAS/OpenMP pools of one thread each, or two
# workers on two cores would each start two threads and fight (see train.threads in core.config).
THREAD_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


class OneThread(WorkerPlugin):
    """Pins every worker (local or started by hand with ``dask worker``) to one compute thread."""

    name = "quadfdi-one-thread"

    def setup(self, worker) -> None:  # noqa: ANN001 - a distributed.Worker
        os.environ.update(THREAD_ENV)  # read by torch/OpenBLAS when a job first imports them
        torch = sys.modules.get("torch")
        if torch is not None:
            torch.set_num_threads(1)


def _worker_env() -> dict[str, str]:
    # Spawned workers import quadfdi from the same environment as this process (the installed package).
    return dict(THREAD_ENV)


def _has_bokeh() -> bool:
    try:
        import bokeh  # noqa: F401
    except ImportError:
        return False
    return True


# Our jobs last seconds to minutes (a shard, a training). Dask's defaults poll for an interactive
# dashboard: a 20 ms event-loop tick in the scheduler and every worker, a statistical profiler
# every 10 ms, a system monitor every 0.5 s, a memory check every 0.1 s. On 2 cores that cost
# CPU the jobs cannot use (docs/distributed.md, "What the cluster itself costs", measured with
# ``quadfdi sweep bench`` and ``--dask-defaults``). The local cluster uses these settings; a
# cluster started by hand gets them from the YAML in that section.
COARSE_JOBS = {
    "distributed.admin.tick.interval": "500ms",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.admin.system-monitor.gil.enabled": False,
    "distributed.worker.profile.enabled": False,
    "distributed.worker.memory.monitor-interval": "1s",
}


# Dask's nannies export MALLOC_TRIM_THRESHOLD_=65536 before they spawn a worker (and leave it in this
# process's environment, so every later subprocess inherits it too): glibc then hands freed memory back
# to the system at every turn and page-faults it in again. Our jobs allocate and free large arrays all
# the time; with it a gradient-boosted fit of the baselines took 12.1 s against 7.1 s without
# (HistGradientBoostingClassifier, 24,000 x 150, one thread), and two fleet-suite baseline jobs on a
# local cluster 263-272 s of CPU for what takes 120 s in one process. None unsets it (Dask's rule).
NO_MALLOC_TRIM = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


def start_local_cluster(n_workers: int, coarse: bool = True) -> LocalCluster:
    """``n_workers`` worker processes of one thread each on this machine (dashboard on a free port),
    configured for coarse jobs (``COARSE_JOBS``: read by the scheduler and the nannies at start);
    ``coarse=False`` keeps Dask's defaults (``quadfdi sweep bench --dask-defaults`` compares) but for
    ``NO_MALLOC_TRIM``, which is about our jobs' memory, not the cluster's cost."""
    # Ctrl-C reaches every process of the terminal's group: the workers start with SIGINT ignored (the
    # disposition survives their exec), so only this process handles it, closes the cluster and says
    # so in one line, instead of each worker printing its own traceback. Their logs show CRITICAL only:
    # a worker whose scheduler closed first logs its failed heartbeat as an ERROR with a traceback; a
    # job's own failure reaches the caller as its JobResult's one-line error, not through these logs.
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with dask.config.set({**NO_MALLOC_TRIM, **(COARSE_JOBS if coarse else {})}):
            return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                                silence_logs=logging.CRITICAL, env=_worker_env())
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def open_client(settings: "ExecSettings", log: Callable[[str], None]) -> Iterator[Client]:
    """A client on a new LocalCluster or on the scheduler named by ``--scheduler``; closed on exit."""
    cluster = None
    if settings.scheduler == "local":
        cluster = start_local_cluster(settings.n_local)
        client = Client(cluster)
    else:
        try:
            client = Client(settings.scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise QuadfdiError(f"cannot reach the Dask scheduler {settings.scheduler}: {one_line(exc)}") from None
    try:
        client.register_plugin(OneThread())
        n = len(client.scheduler_info()["workers"])
        if n == 0:
            client.wait_for_workers(1, timeout=60)
            n = len(client.scheduler_info()["workers"])
        where = "local cluster" if cluster is not None else settings.scheduler
        log(f"dask: {n} worker(s) on the {where}")
        # The scheduler's HTTP server runs without bokeh too, but its /status page needs bokeh.
        if "dashboard" in client.scheduler_info().get("services", {}) and (cluster is None or _has_bokeh()):
            log(f"dask dashboard: {client.dashboard_link}")
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def cluster_canary(client: Client, with_torch: bool, log: Callable[[str], None]) -> str:
    """The workers' common canary (error if they differ); a note when this machine differs."""
    # A worker that is restarting (killed, then its nanny starts a new one) does not answer; its
    # results carry its canary and are checked as they come.
    infos = {w: i for w, i in client.run(canary, with_torch, on_error="return").items() if isinstance(i, dict)}
    if not infos:
        raise QuadfdiError("no Dask worker answered the canary check: is the cluster up?")
    ref = check_canaries(infos)
    mine = canary(with_torch)
    if mine["canary"] != ref:
        log("note: " + describe("this machine's", mine) + f" differs from the cluster's {ref}: "
            "results made here serially would not be byte-identical to the cluster's")
    return ref


_HELD: list[Client] = []  # the client of an open ``core.executor.session``, if any


@contextlib.contextmanager
def held_client(settings: "ExecSettings", log: Callable[[str], None]) -> Iterator[Client]:
    """One client for several sweeps (``core.executor.session``): the cluster starts once."""
    with open_client(settings, log) as client:
        _HELD.append(client)
        try:
            yield client
        finally:
            _HELD.remove(client)


@contextlib.contextmanager
def _client(settings: "ExecSettings", log: Callable[[str], None]) -> Iterator[Client]:
    if _HELD:
        yield _HELD[-1]
    else:
        with open_client(settings, log) as client:
            yield client


def run_on_dask(todo: Sequence[Job], settings: "ExecSettings", done: Callable[[JobResult], None],
                log: Callable[[str], None]) -> None:
    """Submit every job (``ATTEMPTS`` tries each; a killed worker's jobs go to another) and report
    each as it completes. A result from a worker whose canary differs is deleted and failed."""
    with_torch = any(j.torch for j in todo)
    with _client(settings, log) as client:
        ref = cluster_canary(client, with_torch, log)
        futures = [client.submit(execute_job, j.fn, j.args, str(j.out), with_torch, key=f"{j.kind}-{j.key}",
                                 retries=ATTEMPTS - 1, pure=False) for j in todo]
        job_of = {f.key: j for f, j in zip(futures, todo)}
        # as_completed waits on the *default* client's loop unless told: with a second client in the
        # process (a test's, a notebook's) a result lost with a killed worker was then awaited on two
        # loops and failed with "Event ... bound to a different event loop".
        for fut in as_completed(futures, loop=client.loop):
            job = job_of[fut.key]
            if fut.status == "lost":
                # finished, then its worker died holding the (small) result before this loop read it: the
                # scheduler runs the job again, which finds its output cached and returns at once. Waited for
                # through the future (its own client's loop; distributed.wait would take the default client's)
                with contextlib.suppress(Exception):  # an error of the run again is read from the future below
                    fut.result()
            if fut.status != "finished":
                exc = fut.exception() if fut.status == "error" else None
                done(JobResult(job, "failed", error=one_line(exc) if exc else f"job {fut.status}"))
                continue
            rec = fut.result()
            if rec["canary"] != ref:
                job.out.unlink(missing_ok=True)
                done(JobResult(job, "failed", error=f"worker {rec['worker']} joined with canary {rec['canary']}, "
                                                    f"not the cluster's {ref}: its result was discarded"))
                continue
            if not job.out.is_file():
                raise QuadfdiError(f"worker {rec['worker']} wrote {job.out}, which this machine cannot see: the run "
                                   "folder must be the same shared path on every node (docs/distributed.md)")
            done(JobResult(job, "ran", seconds=rec["seconds"], worker=rec["worker"]))
