"""Sweeps on a real Dask LocalCluster of 2 worker processes (and a cluster started with the `dask`
command): the same bytes as a serial run, a worker SIGKILLed mid-sweep, failed rows, resume after
an interrupted sweep. Small configs: 2 cores are shared; timings belong to the bench command."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import cloudpickle
import pytest

from quadfdi.core.config import load_config
from quadfdi.core.executor import ATTEMPTS, ExecSettings, Job, run_jobs
from quadfdi.core.jobcache import cache_path, job_key
from quadfdi.core.rundir import create_run
from quadfdi.formats.dataset import dataset_arrays, write_npz
from quadfdi.sim.publish import generate_sharded
from quadfdi.sim.shards import KIND, shard_jobs
from quadfdi.sim.simulate import generate
from tests.conftest import ROOT, copy_run, quadfdi
from tests.faultkit import sigint_as_in_a_terminal

pytest.importorskip("distributed")
# Jobs defined in this file travel by value: the workers cannot import a test module by name.
cloudpickle.register_pickle_by_value(sys.modules[__name__])

# 12 trajectories of 2 s in shards of 2: six jobs of well under a second each.
TINY = ["sim.n_traj=12", "sim.duration_s=2.0", "sim.onset_frac=[0.1, 0.3]", "sim.ramp_frac=[0.2, 0.4]",
        "sim.window=40", "sim.stride=5", "sim.chunk=2"]
CLI_TINY = [a for kv in TINY for a in ("--set", kv)]
# The interrupt tests' sweep: 48 one-trajectory shards, so that after the first shard lands the others still take
# seconds of the cluster's per-job round trips (with TINY's six shards a fast machine finished the whole sweep
# before the SIGINT was handled, and there was nothing to resume).
LONG = [kv for kv in TINY if not kv.startswith(("sim.n_traj=", "sim.chunk="))] + ["sim.n_traj=48", "sim.chunk=1"]
CLI_LONG = [a for kv in LONG for a in ("--set", kv)]


@pytest.fixture(scope="module")
def cluster():
    from distributed import Client

    from quadfdi.core.executor_dask import start_local_cluster

    with start_local_cluster(2) as lc, Client(lc) as client:
        yield lc.scheduler_address, client


@pytest.fixture(scope="module")
def cfg():
    return load_config(ROOT / "configs/paper.toml", TINY)


def _serial(overrides: list[str], folder: Path) -> bytes:
    """The dataset as the serial simulator writes it in one go (no shards, no executor)."""
    cfg = load_config(ROOT / "configs/paper.toml", overrides)
    write_npz(folder / "dataset.npz", dataset_arrays(generate(cfg.sim), cfg.sim))
    return (folder / "dataset.npz").read_bytes()


@pytest.fixture(scope="module")
def serial_bytes(tmp_path_factory) -> bytes:
    return _serial(TINY, tmp_path_factory.mktemp("serial"))


@pytest.fixture(scope="module")
def long_serial_bytes(tmp_path_factory) -> bytes:
    return _serial(LONG, tmp_path_factory.mktemp("serial_long"))


def test_local_workers_and_this_process_keep_glibc_memory_trimming_off(cluster):
    """Dask's nannies would export MALLOC_TRIM_THRESHOLD_=65536 to the workers and to this process (then
    to every later subprocess): the local cluster unsets it (core.executor_dask.NO_MALLOC_TRIM)."""
    import os

    _, client = cluster
    got = client.run(lambda: __import__("os").environ.get("MALLOC_TRIM_THRESHOLD_"))
    assert len(got) == 2 and set(got.values()) == {None}
    assert "MALLOC_TRIM_THRESHOLD_" not in os.environ


def _tmp_files(root: Path) -> list[str]:
    return sorted(p.name for p in root.rglob("*.tmp"))


def test_two_workers_give_the_serial_bytes(cluster, cfg, serial_bytes, tmp_path):
    run = create_run(tmp_path / "run", cfg)
    generate_sharded(run, cfg, ExecSettings(cluster[0]), progress=False)
    assert run.dataset.read_bytes() == serial_bytes
    assert len(list((run.root / "cache" / KIND).glob("*.npz"))) == 6


def test_cli_local_cluster_of_two_workers(serial_bytes, tmp_path):
    res = quadfdi("sim", "--out", str(tmp_path / "r"), "--scheduler", "local", "--workers", "2", *CLI_TINY)
    assert res.returncode == 0, res.stderr
    assert "dask: 2 worker(s) on the local cluster" in res.stdout
    assert (tmp_path / "r" / "dataset.npz").read_bytes() == serial_bytes


def test_worker_killed_mid_sweep(cluster, cfg, serial_bytes, tmp_path):
    address, client = cluster
    run = create_run(tmp_path / "run", cfg)
    pids = client.run(os.getpid)
    victim = sorted(pids.values())[0]
    cache = run.root / "cache" / KIND

    def kill_after_first_shard():
        deadline = time.time() + 120
        while time.time() < deadline and not list(cache.glob("*.npz")):
            time.sleep(0.02)
        os.kill(victim, signal.SIGKILL)

    killer = threading.Thread(target=kill_after_first_shard)
    killer.start()
    generate_sharded(run, cfg, ExecSettings(address), progress=False)
    killer.join()
    assert victim not in client.run(os.getpid, on_error="ignore").values()  # it died (its nanny starts another)
    assert run.dataset.read_bytes() == serial_bytes  # every shard once, in place, with its bytes
    assert len(list(cache.glob("*.npz"))) == 6 and _tmp_files(run.root) == []
    client.wait_for_workers(2, timeout=60)


def worker_pid(i: int, slow: str) -> dict:
    if Path(slow).exists():  # the run again after a loss: slow, so that the loop reads the future while it is lost
        time.sleep(3.0)
    return {"job": i, "pid": os.getpid()}


def test_a_result_lost_with_its_worker_after_the_job_ran_is_not_a_failure(cluster, tmp_path):
    """A job finishes, then its worker dies holding the result before the loop reads it (the future turns
    "lost"): the scheduler runs it again and it is a row that ran. (Its output is removed and the run again
    made slow here, so that the loop surely reads the future while it is lost.)"""
    from quadfdi.core.executor_dask import run_on_dask

    address, client = cluster
    slow = tmp_path / "slow"
    jobs = [Job("t", job_key("t", {"i": i}), worker_pid, (i, str(slow)),
                cache_path(tmp_path / "run", "t", job_key("t", {"i": i}), "json")) for i in range(2)]
    results = []

    def done(res) -> None:
        if not results:  # the first result read: kill the worker that holds the other's before it is read
            other = next(j for j in jobs if j is not res.job)
            deadline = time.time() + 60
            while not other.out.is_file() and time.time() < deadline:
                time.sleep(0.02)
            time.sleep(0.5)  # its future finishes on this client
            victim = json.loads(other.out.read_text())["pid"]
            slow.write_text("")
            other.out.unlink()
            os.kill(victim, signal.SIGKILL)
            deadline = time.time() + 30
            while victim in client.run(os.getpid, on_error="ignore").values() and time.time() < deadline:
                time.sleep(0.1)
            time.sleep(1.0)  # the scheduler has told this client the result is lost
        results.append(res)

    run_on_dask(jobs, ExecSettings(address), done, log=lambda s: None)
    assert [r.status for r in results] == ["ran", "ran"], [r.error for r in results]
    client.wait_for_workers(2, timeout=60)


def always_fails(counter: str) -> dict:
    with open(counter, "a") as fh:
        fh.write("x\n")
    raise RuntimeError("this job cannot succeed\n(traceback detail)")


def test_failing_job_is_a_row_and_the_sweep_goes_on(cluster, cfg, tmp_path):
    counter = tmp_path / "attempts"
    good = shard_jobs(create_run(tmp_path / "run", cfg), cfg)[:2]
    key = job_key("t", {"bad": 1})
    bad = Job("t", key, always_fails, (str(counter),), cache_path(tmp_path / "run", "t", key, "json"))
    res = run_jobs([good[0], bad, good[1]], ExecSettings(cluster[0]), progress=False)
    assert [r.status for r in res] == ["ran", "failed", "ran"]
    assert res[1].error == "RuntimeError: this job cannot succeed"
    assert counter.read_text().count("x") == ATTEMPTS


def test_resume_runs_only_what_is_missing(cluster, cfg, serial_bytes, tmp_path):
    run = create_run(tmp_path / "run", cfg)
    jobs = shard_jobs(run, cfg)
    run_jobs(jobs[:4], ExecSettings(cluster[0]), progress=False)  # a sweep stopped after 4 of 6 shards
    before = {j.out: (j.out.stat().st_ino, j.out.stat().st_mtime_ns) for j in jobs[:4]}
    res = run_jobs(jobs, ExecSettings(cluster[0]), progress=False)
    assert [r.status for r in res] == ["cached"] * 4 + ["ran"] * 2
    assert {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in before} == before
    generate_sharded(run, cfg, ExecSettings(cluster[0]), progress=False)
    assert run.dataset.read_bytes() == serial_bytes


def test_interrupted_cli_sweep_resumes(cluster, long_serial_bytes, tmp_path):
    """SIGINT to `quadfdi sim` mid-sweep: exit 130, no dataset; the rerun keeps the finished shards."""
    out = tmp_path / "r"
    cache = out / "cache" / KIND
    env = dict(os.environ)
    args = [sys.executable, "-m", "quadfdi.cli", "sim", "--out", str(out), "--scheduler", cluster[0], *CLI_LONG]
    proc = subprocess.Popen(args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=sigint_as_in_a_terminal)
    deadline = time.time() + 300
    while time.time() < deadline and not list(cache.glob("*.npz")) and proc.poll() is None:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert not (out / "dataset.npz").exists()
    # The cluster outlives the interrupted client: a worker already running a shard finishes it and
    # writes its file atomically (temp file, then rename), maybe after the CLI's own clean-up. What
    # must hold is that no temp file stays: wait for such a write to land (under load one can still be
    # in flight at the moment of the check).
    settle = time.time() + 60
    while _tmp_files(out) and time.time() < settle:
        time.sleep(0.1)
    assert _tmp_files(out) == []
    done = {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in cache.glob("*.npz")}
    assert 1 <= len(done)
    assert len(done) < 48  # interrupted: shards were left to run
    res = quadfdi("sim", "--out", str(out), "--scheduler", cluster[0], *CLI_LONG)
    assert res.returncode == 0, res.stderr
    assert all((p.stat().st_ino, p.stat().st_mtime_ns) == s for p, s in done.items())
    assert (out / "dataset.npz").read_bytes() == long_serial_bytes


@pytest.mark.slow
def test_cluster_started_with_the_dask_command(serial_bytes, tmp_path):
    """`dask scheduler` + two `dask worker` processes, as docs/distributed.md starts them by hand."""
    dask = shutil.which("dask", path=str(Path(sys.executable).parent)) or shutil.which("dask")
    if dask is None:
        pytest.skip("the dask command is not installed")
    sched_file = tmp_path / "scheduler.json"
    env = dict(os.environ)
    procs = [subprocess.Popen([dask, "scheduler", "--port", "0", "--dashboard-address", ":0", "--scheduler-file",
                               str(sched_file)], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.time() + 120
        while not sched_file.exists() and time.time() < deadline:
            time.sleep(0.1)
        import json

        address = json.loads(sched_file.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--nworkers", "1"], env=env,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout="60s") as c:
            c.wait_for_workers(2, timeout=120)
        res = quadfdi("sim", "--out", str(tmp_path / "r"), "--scheduler", address, *CLI_TINY)
        assert res.returncode == 0, res.stderr
        assert "dask: 2 worker(s)" in res.stdout
        assert (tmp_path / "r" / "dataset.npz").read_bytes() == serial_bytes
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            p.wait(timeout=60)


# A study that trains in seconds: 2 seeds x 2 models, one epoch of small models.
STUDY = ["train.epochs=1", "train.batch_size=48", "train.latent=8", "train.hidden=16", "train.gru_hidden=16"]


def test_study_metrics_serial_equal_distributed(cluster, small_run, tmp_path):
    import json

    from quadfdi.core.executor import SERIAL
    from quadfdi.core.rundir import open_run
    from quadfdi.train.study import run_study

    out = {}
    for name, settings in (("serial", SERIAL), ("dask", ExecSettings(cluster[0]))):
        run, cfg = open_run(copy_run(small_run, tmp_path / name), STUDY)
        run_study(run, cfg, [0, 1], "quadfdi train study", log=lambda _: None, settings=settings)
        seeds = json.loads((run.root / "seeds.json").read_text())
        seeds.pop("seconds_per_seed")  # timing: not part of the comparison
        out[name] = (seeds, (run.root / "results.md").read_text())
        assert len(list((run.root / "cache" / "study").glob("*.npz"))) == 4
    assert out["serial"] == out["dask"]
    assert "failed" not in out["serial"][0] and len(out["serial"][0]["cnode"]["macro_f1"]) == 2


def test_sweep_writes_its_table_and_figure_and_resumes(cluster, tmp_path):
    import json

    out = tmp_path / "sweep"
    args = ["sweep", "--config", str(ROOT / "configs/paper.toml"), *CLI_TINY, "--set", "sim.n_traj=16",
            *[a for kv in STUDY for a in ("--set", kv)], "--grid", "train.latent=4,8", "--grid", "train.seed=0,1",
            "--stages", "sim,train", "--metrics", "train.cnode.macro_f1,train.gru.accuracy", "--out", str(out),
            "--scheduler", cluster[0]]
    res = quadfdi(*args)
    assert res.returncode == 0, res.stderr
    table = json.loads((out / "sweep.json").read_text())
    assert [r["values"] for r in table["rows"]] == [{"train.latent": a, "train.seed": b}
                                                     for a in ("4", "8") for b in ("0", "1")]
    assert all(r["status"] == "done" and r["metrics"]["train.cnode.macro_f1"] is not None for r in table["rows"])
    assert (out / "figures" / "sweep.png").stat().st_size > 1000
    assert "| train.latent | train.seed | train.cnode.macro_f1 |" in (out / "sweep.md").read_text()
    assert len(list((out / "cache" / "sim").glob("*.npz"))) == 8  # one simulation shared by the 4 points
    stamps = {p: p.stat().st_mtime_ns for p in (out / "cache").rglob("*.json")}
    res = quadfdi(*args)  # everything cached: nothing runs again, the same table
    assert res.returncode == 0, res.stderr
    assert {p: p.stat().st_mtime_ns for p in (out / "cache").rglob("*.json")} == stamps
    assert json.loads((out / "sweep.json").read_text()) == table


MATRIX = [*STUDY, 'solvers.matrix_train=["rk4:1", "rk4:2:avg"]', 'solvers.matrix_deploy=["rk4:1", "rk4:2"]',
          "solvers.matrix_epochs=1", "solvers.matrix_max_train_windows=96"]
TIMING = {"seconds", "train_seconds", "epoch_seconds", "reused", "command"}


def _no_timing(d, also=frozenset()):
    if isinstance(d, dict):
        return {k: _no_timing(v, also) for k, v in d.items() if k not in TIMING and k not in also}
    if isinstance(d, list):
        return [_no_timing(v, also) for v in d]
    return d


def test_solver_matrix_cells_on_two_workers_equal_in_process(cluster, small_run, tmp_path):
    """One job per model, reference and cell on the cluster: the in-process matrix's numbers."""
    from quadfdi.core.rundir import open_run
    from quadfdi.solverstudy.run import matrix_run

    out = {}
    for name, settings in (("here", None), ("dask", ExecSettings(cluster[0]))):
        run, cfg = open_run(copy_run(small_run, tmp_path / name), MATRIX)
        out[name] = matrix_run(run, cfg, log=lambda _: None, settings=settings)
    assert _no_timing(out["here"]) == _no_timing(out["dask"])
    assert len(out["dask"]["cells"]) == 2 * 3  # 2 models x (2 deploys + the reference)
    cache = tmp_path / "dask" / "cache"
    assert [len(list((cache / k).iterdir())) for k in ("matrix-train", "matrix-ref", "matrix-cell")] == [2, 2, 6]
    assert sorted(p.name for p in (tmp_path / "dask" / "solvers" / "matrix_models").iterdir()) == \
        sorted(p.name for p in (tmp_path / "here" / "solvers" / "matrix_models").iterdir())


SOLVERS = ["solvers.sample=2", "solvers.ref_rtol=1e-6", "solvers.steps=[1, 4]",
           'solvers.fixed_methods=["euler", "rk4"]', 'solvers.adaptive_methods=["dopri5"]', "solvers.rtols=[1e-2]",
           'solvers.jump="on"']


def test_solver_study_on_two_workers_equals_in_process(cluster, small_run, tmp_path, monkeypatch):
    """One job per setting (and the reference, and its check, the reference's split solve in parts) on the
    cluster: the in-process study's logits-derived numbers; only timings and the latency note differ; the
    windows file is removed."""
    from quadfdi.core.config import load_config
    from quadfdi.core.rundir import open_run
    from quadfdi.solverstudy import study, study_jobs
    from quadfdi.solverstudy.run import study_run
    from tests.conftest import random_weight_run

    monkeypatch.setattr(study, "SPLIT_BATCH", 16)  # small batches and parts: the reference in several jobs
    monkeypatch.setattr(study_jobs, "PART_BATCHES", 2)
    out = {}
    for name, settings in (("here", None), ("dask", ExecSettings(cluster[0]))):  # the same seed-0 weights
        cfg = load_config(small_run / "config.toml").to_dict()
        src = random_weight_run(small_run, tmp_path / name, ("cnode",), cfg)
        run, cfg = open_run(src, SOLVERS)
        out[name] = study_run(run, cfg, log=lambda _: None, settings=settings)
    assert "cluster at tcp://" in out["dask"]["meta"]["latency_note"]
    untimed = lambda d: _no_timing(d, {"latency_us", "latency_note", "checkpoint"})  # noqa: E731
    assert untimed(out["here"]) == untimed(out["dask"])
    assert len(out["dask"]["solvers"]) == 1 + 2 * 2 * 2 + 1  # reference, fixed x (point, average), dopri5
    cache = tmp_path / "dask" / "cache"
    assert len(list((cache / "solvers-task").glob("*.npz"))) == 2 + 2 * 2 * 2 + 1  # + the reference's check
    n = out["dask"]["reference"]["split_n_windows"]
    assert n > 32 and len(list((cache / "solvers-split").glob("*.npz"))) == -(-n // 32)
    assert not list((cache / "solvers-windows").iterdir())


def test_sweep_bench_measures_three_ways_and_the_cluster_cpu(tmp_path):
    # The bench at toy size: its timings are not under test, its bookkeeping is.
    res = quadfdi("sweep", "bench", "--workloads", "sim", "--n-traj", "4", "--noop-jobs", "2",
                  "--out", str(tmp_path / "b"), *CLI_TINY)
    assert res.returncode == 0, res.stderr
    r = json.loads((tmp_path / "b" / "sweep_bench.json").read_text())
    w = r["workloads"]["sim"]
    assert w["jobs"] == 2 and w["bytes_identical"] is True and r["dask_config"] == "coarse"
    assert w["cpu_serial_s"] > 0 and w["cpu_dask_s"] > 0
    assert w["dask_overhead_cpu_s"] == pytest.approx(w["cpu_dask_s"] - w["cpu_serial_s"])
    assert "CPU of the Dask way beyond the jobs' own (sim)" in (tmp_path / "b" / "sweep_bench.md").read_text()


def test_ctrl_c_on_a_local_cluster_sweep_is_one_line(tmp_path):
    """Ctrl-C reaches the whole process group (the CLI and its local Dask workers): one line, exit 130,
    no worker traceback."""
    out = tmp_path / "r"
    args = [sys.executable, "-m", "quadfdi.cli", "sim", "--out", str(out), "--workers", "2", *CLI_LONG]
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=sigint_as_in_a_terminal)
    cache = out / "cache" / KIND
    deadline = time.time() + 300
    while time.time() < deadline and not list(cache.glob("*.npz")) and proc.poll() is None:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err[-3000:]
    lines = [ln for ln in err.splitlines() if ln.strip() and "shards" not in ln and "dask:" not in ln]
    assert lines == ["quadfdi sim: interrupted"], err[-3000:]
