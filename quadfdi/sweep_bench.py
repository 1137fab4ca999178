"""``quadfdi sweep bench``: what the executor costs and how it scales, measured side by side in one run.

For each workload (``sim``: the dataset in shards of ``sim.chunk``, 2,400 trajectories by default;
``study``: the 3-seed study, one job per seed x model) the same jobs run, each time into a fresh
cache folder:

1. serially in this process (1 worker);
2. by hand: two independent ``python`` processes started together, each running its share of the
   jobs in-process; the shares are balanced on the serial run's job times (longest first, to the
   less loaded). Its wall time is the machine's own parallel limit for these jobs;
3. on a Dask LocalCluster of 2 single-threaded workers (its start-up timed apart).

The goal: throughput of 3 >= 90 % of 2 (``efficiency`` = wall of 2 / wall of 3). The scheduler's
cost per job is measured with ``--noop-jobs`` jobs that do nothing but write a small JSON file:
wall time x workers / jobs on the cluster, against the same jobs in-process. Every result file of
2 and 3 is compared with 1's, byte for byte. Writes ``<out>/sweep_bench.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import os
import pickle
import shutil
import subprocess
import sys
import time
from pathlib import Path

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.config import Config, load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import SERIAL, ExecSettings, Job, run_jobs
from quadfdi.core.jobcache import cache_path, job_key


def add_bench_parser(acts: argparse._SubParsersAction) -> None:
    pb = acts.add_parser("bench", help="measure the executor's scaling (1 worker, 2 processes by hand, 2 Dask workers)")
    add_config_args(pb)
    pb.add_argument("--out", default="runs/sweep-bench", help="bench folder (default: %(default)s)")
    pb.add_argument("--workloads", default="sim,study", help="comma-separated: sim, study (default: %(default)s)")
    pb.add_argument("--n-traj", type=int, default=2400, help="trajectories of the sim workload (default: %(default)s)")
    pb.add_argument("--noop-jobs", type=int, default=200, help="empty jobs timing the scheduler (default: %(default)s)")
    pb.add_argument("--dask-defaults", action="store_true",
                    help="start the cluster with Dask's default intervals instead of quadfdi's (core.executor_dask.COARSE_JOBS)")
    pb.add_argument("--part", default=None, help=argparse.SUPPRESS)  # internal: run these job indices here
    pb.add_argument("--cache", default=None, help=argparse.SUPPRESS)
    pb.set_defaults(func=run_bench_cmd)


def noop(i: int) -> dict:
    """An empty job: what the scheduler, the result file and the record cost by themselves."""
    return {"i": i}


def noop_jobs(root: Path, n: int) -> list[Job]:
    return [Job("noop", k, noop, (i,), cache_path(root, "noop", k, "json"))
            for i in range(n) for k in [job_key("noop", {"i": i})]]


def sim_jobs(cfg: Config, root: Path, n_traj: int) -> list[Job]:
    from quadfdi.core.config import replace_section
    from quadfdi.core.rundir import RunDir
    from quadfdi.sim.shards import shard_jobs

    big = replace_section(cfg, "sim", n_traj=n_traj)
    return shard_jobs(RunDir(root), big)


def study_jobs(cfg: Config, root: Path) -> list[Job]:
    """The seed x model jobs of the study on the bench's paper-scale dataset (made once, cached)."""
    from quadfdi.core.rundir import RunDir, create_run
    from quadfdi.sim.publish import generate_sharded
    from quadfdi.train.study_jobs import seed_model_jobs

    data = RunDir(Path(root).parent / "data")
    if not data.dataset.is_file():
        generate_sharded(create_run(data.root, cfg), cfg, SERIAL, progress=False)
    return seed_model_jobs(data, cfg, list(cfg.train.seeds), cache_root=root)


def workload_jobs(name: str, cfg: Config, root: Path, n_traj: int) -> list[Job]:
    if name == "sim":
        return sim_jobs(cfg, root, n_traj)
    if name == "study":
        return study_jobs(cfg, root)
    if name == "noop":
        return noop_jobs(root, n_traj)
    raise QuadfdiError(f"--workloads: unknown workload {name!r}; valid: sim, study")


def balance(seconds: list[float], parts: int = 2) -> list[list[int]]:
    """Job indices per process: longest first, each to the least loaded (what one would do by hand)."""
    load, out = [0.0] * parts, [[] for _ in range(parts)]
    for i in sorted(range(len(seconds)), key=lambda i: -seconds[i]):
        k = load.index(min(load))
        out[k].append(i)
        load[k] += seconds[i]
    return [sorted(o) for o in out]


def _fresh(path: Path) -> Path:
    shutil.rmtree(path, ignore_errors=True)
    path.mkdir(parents=True)
    return path


def _cpu_s(tree: bool) -> float:
    """CPU seconds used so far by this process (the client, and the local cluster's scheduler) and,
    with ``tree``, by its children (the cluster's nannies and workers)."""
    import psutil

    me = psutil.Process()
    procs = [me, *me.children(recursive=True)] if tree else [me]
    total = 0.0
    for p in procs:
        try:
            t = p.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += t.user + t.system
    return total


def _timed(jobs: list[Job], settings: ExecSettings) -> tuple[float, list[float]]:
    t0 = time.perf_counter()
    res = run_jobs(jobs, settings, progress=False, log=lambda s: None)
    wall = time.perf_counter() - t0
    bad = [r for r in res if not r.ok]
    if bad:
        raise QuadfdiError(f"bench: job {bad[0].job.label or bad[0].job.key[:12]} failed: {bad[0].error}")
    return wall, [r.seconds for r in res]


def by_hand(jobs: list[Job], root: Path, parts: list[list[int]]) -> float:
    """Two independent processes, started together, each running its share in-process. They get
    the jobs pickled, not rebuilt: a key rebuilt after an edit or a commit would name other files."""
    with open(root / "jobs.pkl", "wb") as fh:
        pickle.dump(jobs, fh)
    cmd = [sys.executable, "-m", "quadfdi.cli", "sweep", "bench", "--cache", str(root / "jobs.pkl")]
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    t0 = time.perf_counter()
    procs = [subprocess.Popen([*cmd, "--part", ",".join(map(str, p))], env=env, cwd=root) for p in parts if p]
    codes = [p.wait() for p in procs]
    if any(codes):
        raise QuadfdiError(f"bench: a hand-started process failed (exit codes {codes})")
    return time.perf_counter() - t0


def _same_bytes(a: list[Job], b: list[Job]) -> bool:
    return all(x.out.read_bytes() == y.out.read_bytes() for x, y in zip(a, b))


def measure(args: argparse.Namespace, name: str, cfg: Config, out: Path, client_address: str) -> dict:
    roots = {k: _fresh(out / name / k) for k in ("serial", "hand", "dask")}
    jobs = {k: workload_jobs(name, cfg, r, args.n_traj) for k, r in roots.items()}
    c0 = _cpu_s(tree=False)
    t1, secs = _timed(jobs["serial"], SERIAL)
    cpu_serial = _cpu_s(tree=False) - c0
    parts = balance(secs)
    t_hand = by_hand(jobs["hand"], roots["hand"], parts)
    c0 = _cpu_s(tree=True)
    t2, secs2 = _timed(jobs["dask"], ExecSettings(client_address))
    cpu_dask = _cpu_s(tree=True) - c0
    return {"jobs": len(secs), "serial_s": t1, "hand_2proc_s": t_hand, "dask_2workers_s": t2,
            "job_seconds_serial": sum(secs), "job_seconds_dask": sum(secs2),
            "speedup_hand": t1 / t_hand, "speedup_dask": t1 / t2, "efficiency_vs_hand": t_hand / t2,
            "hand_shares": [len(p) for p in parts],
            # CPU the cluster spends beyond the jobs' own (the serial run's CPU): scheduler, client,
            # workers' event loops and monitors, result handling
            "cpu_serial_s": cpu_serial, "cpu_dask_s": cpu_dask, "dask_overhead_cpu_s": cpu_dask - cpu_serial,
            "bytes_identical": _same_bytes(jobs["serial"], jobs["hand"]) and _same_bytes(jobs["serial"], jobs["dask"])}


def scheduler_cost(out: Path, n: int, client_address: str) -> dict:
    t_here, _ = _timed(noop_jobs(_fresh(out / "noop" / "serial"), n), SERIAL)
    t_dask, _ = _timed(noop_jobs(_fresh(out / "noop" / "dask"), n), ExecSettings(client_address))
    return {"jobs": n, "in_process_ms_per_job": 1e3 * t_here / n, "dask_ms_per_job": 1e3 * t_dask * 2 / n,
            "dask_wall_ms_per_job": 1e3 * t_dask / n}


def run_bench_cmd(args: argparse.Namespace) -> int:
    from quadfdi.sweep_bench_report import write_bench

    if args.part is not None:  # one of the hand-started processes
        with open(args.cache, "rb") as fh:
            jobs = pickle.load(fh)
        _timed([jobs[int(i)] for i in args.part.split(",")], SERIAL)
        return 0
    cfg = load_config(args.config, args.overrides)
    names = [w.strip() for w in args.workloads.split(",") if w.strip()]
    from distributed import Client

    from quadfdi.core.executor_dask import OneThread, start_local_cluster

    out = Path(args.out)
    t0 = time.perf_counter()
    with start_local_cluster(2, coarse=not args.dask_defaults) as cluster, Client(cluster) as client:
        client.register_plugin(OneThread())
        start_s = time.perf_counter() - t0
        result = {"cluster_start_s": start_s, "dask_config": "defaults" if args.dask_defaults else "coarse",
                  "cores": len(os.sched_getaffinity(0)),
                  "load_avg_before": os.getloadavg()[0],
                  "workloads": {n: measure(args, n, cfg, out, cluster.scheduler_address) for n in names},
                  "scheduler": scheduler_cost(out, args.noop_jobs, cluster.scheduler_address),
                  "load_avg_after": os.getloadavg()[0]}
    result["command"] = "quadfdi sweep bench " + " ".join(sys.argv[3:])
    for p in write_bench(out, result):
        print(f"wrote {p}")
    return 0
