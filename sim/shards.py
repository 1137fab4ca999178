"""The dataset as shards: ``sim.chunk`` trajectories per job, run on ``core.executor``, then joined.

Trajectory i depends only on (seed, i) and the config (``sim.draws``), so a shard of rows
[start, stop) simulated anywhere has the same bits as those rows of a serial run, and the joined
file is byte-identical to ``generate(cfg.sim)`` written in one go.

Data movement: each worker writes its shard (``core.npzio``, atomically) into the run folder's
cache, ``<run>/cache/sim/<key>.npz``, and returns only a small record; the client then reads the
shards in index order and writes ``dataset.npz``. Writing rather than returning arrays is what makes
an interrupted run resumable (finished shards are on disk, keyed by their content) and keeps the
arrays (about 120 kB per trajectory at paper scale) out of the scheduler's memory. It needs the
run folder to be one shared path on every node; the client checks that it sees each shard.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from quadfdi.core.config import Config
from quadfdi.sim.config import SimConfig
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import SERIAL, ExecSettings, Job, failures, run_jobs
from quadfdi.core.jobcache import cache_path, job_key, read_result
from quadfdi.core.rundir import RunDir

KIND = "sim"
# Arrays of generate() that do not have one row per trajectory: taken once, from the first shard.
# The realistic suite adds its name tables (sim/realistic.py generate()).
GLOBAL_KEYS = ("time", "channel_names", "channel_units", "state_names", "state_units", "severity_threshold",
               "class_names", "split_names", "mission_names", "fault_mode_names", "battery_submode_names",
               "frame_names", "esc_channel_names", "esc_channel_units", "airframe_class_names")


def n_rows(sim: SimConfig) -> int:
    """Rows of the dataset: n_traj, plus the 4 x ood_traj out-of-distribution test flights of the
    realistic suite (sim/realistic.py n_flights), 6 x ood_traj of the fleet suite (sim/fleet.py)."""
    if sim.scenario == "realistic":
        from quadfdi.sim.realistic import n_flights

        return n_flights(sim)
    if sim.scenario == "fleet":
        from quadfdi.sim.fleet import n_flights as fleet_flights

        return fleet_flights(sim)
    return sim.n_traj


def shard_ranges(n_traj: int, chunk: int) -> list[tuple[int, int]]:
    """[start, stop) of every shard: ``chunk`` trajectories each, the last one shorter."""
    return [(s, min(s + chunk, n_traj)) for s in range(0, n_traj, chunk)]


def simulate_shard(cfg: SimConfig, start: int, stop: int) -> dict[str, np.ndarray]:
    """Rows [start, stop) of the dataset (a job: runs on a worker)."""
    from quadfdi.sim.simulate import generate

    return generate(cfg, indices=range(start, stop))


def shard_jobs(run: RunDir, cfg: Config, cache_root: Path | None = None) -> list[Job]:
    """One job per shard; results under ``cache_root`` (default: the run folder). A shard's key
    depends on the [sim] section only, so runs that share a cache share their shards."""
    sim = cfg.sim
    root = run.root if cache_root is None else Path(cache_root)
    conf = dataclasses.asdict(sim)
    jobs = []
    for start, stop in shard_ranges(n_rows(sim), sim.chunk):
        key = job_key(KIND, conf, {"start": start, "stop": stop}, packages=("sim",))
        jobs.append(Job(KIND, key, simulate_shard, (sim, start, stop), cache_path(root, KIND, key, "npz"),
                        label=f"trajectories {start}-{stop - 1}"))
    return jobs


def join_shards(paths: list[Path], rows: list[int] | None = None) -> dict[str, np.ndarray]:
    """The shards' rows in order, plus the per-dataset arrays of the first: generate()'s output. A
    cache file is trusted by its name only as far as its content agrees: the same arrays as the first
    shard, ``rows`` (when given) rows each; otherwise a one-line error names it."""
    parts = [read_result(p) for p in paths]
    keys = set(parts[0])
    for i, (p, part) in enumerate(zip(paths, parts)):
        per_row = [k for k in part if k not in GLOBAL_KEYS]
        n = {np.shape(part[k])[0] if np.ndim(part[k]) else -1 for k in per_row}
        if set(part) != keys or len(n) != 1 or (rows is not None and n != {rows[i]}):
            raise QuadfdiError(f"cached shard {p} is not a shard of this simulation (its arrays or rows differ): "
                               "delete it and run the same command again")
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k not in GLOBAL_KEYS}
    out.update({k: parts[0][k] for k in GLOBAL_KEYS if k in parts[0]})
    return out


def simulate_sharded(run: RunDir, cfg: Config, settings: ExecSettings = SERIAL, progress: bool = True,
                     cache_root: Path | None = None) -> dict[str, np.ndarray]:
    """Simulate ``cfg.sim`` shard by shard on ``settings``' executor; the joined arrays (generate()'s).
    ``cache_root``: where the shards are kept (default: the run folder)."""
    cfg.sim.validate()
    jobs = shard_jobs(run, cfg, cache_root)
    results = run_jobs(jobs, settings, desc="sim shards", progress=progress)
    bad = failures(results)
    if bad:
        first = bad[0]
        raise QuadfdiError(f"{len(bad)} of {len(jobs)} shards failed ({first.job.label}: {first.error}); "
                           "the others are cached: run the same command again to resume")
    return join_shards([j.out for j in jobs], [j.args[2] - j.args[1] for j in jobs])
