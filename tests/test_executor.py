"""core.executor and core.jobcache without a cluster: keys, canary, in-process runs, failed rows, resume."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.config import load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import ATTEMPTS, SERIAL, ExecSettings, Job, canary, check_canaries, run_jobs
from quadfdi.core.jobcache import cache_path, job_key, read_result

ROOT = Path(__file__).resolve().parents[1]


def square(x: int) -> dict:
    return {"x": x, "square": x * x}


def arrays(n: int) -> dict:
    return {"a": np.arange(n, dtype=np.float32)}


def fails_counting(counter: str, x: int) -> dict:
    with open(counter, "a") as fh:
        fh.write("attempt\n")
    raise ValueError(f"job {x} is broken\nsecond line of detail")


def _jobs(root: Path, fn=square, n: int = 4) -> list[Job]:
    out = []
    for x in range(n):
        key = job_key("t", {"x": x}, packages=())
        out.append(Job("t", key, fn, (x,), cache_path(root, "t", key, "json"), label=f"x={x}"))
    return out


def test_job_key_follows_config_args_inputs_and_not_settings(tmp_path):
    f = tmp_path / "in.bin"
    f.write_bytes(b"one")
    k = job_key("k", {"a": 1}, {"i": 0}, {"data": f})
    assert k == job_key("k", {"a": 1}, {"i": 0}, {"data": f})  # deterministic
    assert len(k) == 64
    assert k != job_key("k", {"a": 2}, {"i": 0}, {"data": f})
    assert k != job_key("k", {"a": 1}, {"i": 1}, {"data": f})
    assert k != job_key("k2", {"a": 1}, {"i": 0}, {"data": f})
    assert k != job_key("k", {"a": 1}, {"i": 0}, {"data": f}, packages=("sim",))  # more source hashed
    f.write_bytes(b"two")
    assert k != job_key("k", {"a": 1}, {"i": 0}, {"data": f})


def test_settings_are_checked():
    with pytest.raises(QuadfdiError, match="--scheduler"):
        ExecSettings("mycluster").validate()
    with pytest.raises(QuadfdiError, match="at least 1"):
        ExecSettings(workers=0).validate()
    with pytest.raises(QuadfdiError, match="local cluster"):
        ExecSettings("tcp://h:8786", workers=2).validate()
    assert ExecSettings(workers=1).in_process(10) and ExecSettings(workers=2).in_process(1)
    assert not ExecSettings(workers=2).in_process(2) and not ExecSettings("tcp://h:1").in_process(1)


def test_canary_is_fixed_and_a_mixed_cluster_is_named():
    a = canary(False)
    assert a == canary(False) and len(a["canary"]) == 12
    other = dict(a, canary="0" * 12, numpy="1.0.0")
    assert check_canaries({"w1": a, "w2": dict(a)}) == a["canary"]
    with pytest.raises(QuadfdiError, match=r"mixed cluster.*w3.*numpy 1\.0\.0"):
        check_canaries({"w1": a, "w2": a, "w3": other})


def test_in_process_run_caches_and_resumes(tmp_path):
    jobs = _jobs(tmp_path)
    res = run_jobs(jobs, SERIAL, progress=False)
    assert [r.status for r in res] == ["ran"] * 4
    assert read_result(jobs[2].out) == {"x": 2, "square": 4}
    jobs[1].out.unlink()
    stamps = {j.out: j.out.stat().st_mtime_ns for j in jobs if j.out.exists()}
    res = run_jobs(_jobs(tmp_path), SERIAL, progress=False)
    assert [r.status for r in res] == ["cached", "ran", "cached", "cached"]
    assert all(p.stat().st_mtime_ns == t for p, t in stamps.items())  # nothing done twice


def test_duplicate_jobs_run_once(tmp_path):
    jobs = _jobs(tmp_path, n=2)
    res = run_jobs(jobs + jobs[:1], SERIAL, progress=False)
    assert [r.status for r in res] == ["ran", "ran", "ran"] and res[2].job is jobs[0]


def test_failing_job_is_a_failed_row_after_three_attempts(tmp_path):
    counter = tmp_path / "attempts.txt"
    jobs = _jobs(tmp_path, n=2)
    key = job_key("t", {"bad": True})
    bad = Job("t", key, fails_counting, (str(counter), 7), cache_path(tmp_path, "t", key, "json"), label="bad")
    res = run_jobs([jobs[0], bad, jobs[1]], SERIAL, progress=False)
    assert [r.status for r in res] == ["ran", "failed", "ran"]
    assert res[1].error == "ValueError: job 7 is broken"  # one line
    assert counter.read_text().count("attempt") == ATTEMPTS
    assert not bad.out.exists()


def test_npz_results_and_no_partial_files(tmp_path):
    key = job_key("a", {"n": 5})
    job = Job("a", key, arrays, (5,), cache_path(tmp_path, "a", key, "npz"))
    (job.out.parent).mkdir(parents=True)
    (job.out.parent / f".{job.out.name}.x1.tmp").write_bytes(b"half")  # a writer killed mid-write
    run_jobs([job], SERIAL, progress=False)
    np.testing.assert_array_equal(read_result(job.out)["a"], np.arange(5, dtype=np.float32))
    assert [p.name for p in job.out.parent.iterdir()] == [job.out.name]


def test_sim_shard_keys_follow_the_sim_section_only(tmp_path):
    from quadfdi.core.rundir import RunDir
    from quadfdi.sim.shards import shard_jobs, shard_ranges

    assert shard_ranges(10, 4) == [(0, 4), (4, 8), (8, 10)]
    cfg = load_config(ROOT / "configs/paper.toml", ["sim.n_traj=10", "sim.chunk=4"])
    keys = [j.key for j in shard_jobs(RunDir(tmp_path), cfg)]
    assert len(set(keys)) == 3
    other_train = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, latent=8))
    assert keys == [j.key for j in shard_jobs(RunDir(tmp_path), other_train)]
    other_seed = load_config(ROOT / "configs/paper.toml", ["sim.n_traj=10", "sim.chunk=4", "sim.seed=1"])
    assert not set(keys) & {j.key for j in shard_jobs(RunDir(tmp_path), other_seed)}


def test_executor_flags_never_reach_a_result_command_line():
    from quadfdi.core.executor import strip_executor_args

    argv = ["train", "study", "--run", "r", "--workers", "2", "--scheduler=tcp://h:1", "--seeds", "0,1"]
    assert strip_executor_args(argv) == ["train", "study", "--run", "r", "--seeds", "0,1"]
