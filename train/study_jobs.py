"""The seed study as jobs of ``core.executor``: one per simulator seed x training seed x model, each
keyed by its config (both seeds included), the dataset's hash and the code of ``sim`` and ``train``,
its result cached as ``<run>/cache/study/<key>.npz``: the network's prediction set on every
evaluation window (formats.predictions's format) plus ``metrics_json``, its and the baseline's test
metrics as one JSON string. Training is deterministic on one thread (every worker has one), so a
study gives the same bytes serial or distributed, and a rerun takes them from the cache."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfdi.core.config import Config, replace_section
from quadfdi.core.executor import Job
from quadfdi.core.jobcache import cache_path, job_key
from quadfdi.core.jsonio import to_jsonable
from quadfdi.core.rundir import RunDir

KIND = "study"
MODELS = ("cnode", "gru")
METRICS_KEY = "metrics_json"
SET_SEP = "__"  # a job's further prediction sets (a reference profile's <kind>_noref): keys <model>__<key>


@dataclass(frozen=True)
class StudyData:
    """One simulator seed's dataset: its path, and that path relative to the run folder (the index's)."""

    sim_seed: int
    path: Path
    rel: str


def train_seed_model(dataset: str, cfg: Config, kind: str, baseline: bool = True) -> dict:
    """Train ``kind`` with ``cfg.train.seed`` on ``dataset`` (a job): its prediction set and, as
    ``metrics_json``, its test metrics and, with ``baseline``, the baseline's (the same fit for every
    network of one seed: ``seed_model_jobs`` asks the first job of a seed for it); a reference profile's
    network also its set without the vehicle record (``<kind>_noref``, keys ``<kind>_noref__<key>``)."""
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.train.run import train_all

    result = train_all(load_dataset(dataset), cfg, [kind], log=lambda _: None, patterns=False,  # metrics.json's alone
                       baseline=baseline)
    metrics = json.dumps(to_jsonable(result["metrics"]), sort_keys=True, allow_nan=False)
    extra = {f"{name}{SET_SEP}{k}": v for name, arrays in result["predsets"].items() if name != kind
             for k, v in arrays.items()}
    return {**result["predsets"][kind], **extra, METRICS_KEY: np.array(metrics)}


def split_result(arrays: dict) -> tuple[dict, dict, dict]:
    """A cached job result -> (prediction set arrays, metrics dict, further sets by model name)."""
    pred = {k: v for k, v in arrays.items() if k != METRICS_KEY and SET_SEP not in k}
    extra: dict[str, dict] = {}
    for k, v in arrays.items():
        if SET_SEP in k:
            name, key = k.split(SET_SEP, 1)
            extra.setdefault(name, {})[key] = v
    return pred, json.loads(str(arrays[METRICS_KEY])), extra


def seed_model_jobs(run: RunDir, cfg: Config, seeds: list[int], models: tuple[str, ...] = MODELS,
                    cache_root: Path | None = None, data: list[StudyData] | None = None,
                    skip: set[tuple[str, int, int]] = frozenset()) -> list[Job]:
    """Jobs in (sim seed, train seed, model) order; results under ``cache_root`` (default: the run
    folder). ``data``: the datasets by simulator seed (default: the run's own); ``skip``: the
    (model, sim seed, train seed) whose prediction set exists already (the train stage's)."""
    root = run.root if cache_root is None else Path(cache_root)
    data = data or [StudyData(cfg.sim.seed, run.dataset, "dataset.npz")]
    jobs = []
    for d in data:
        for seed in seeds:
            c = replace_section(replace_section(cfg, "sim", seed=d.sim_seed), "train", seed=seed)
            todo = [kind for kind in models if (kind, d.sim_seed, seed) not in skip]
            for kind in todo:
                base = kind == todo[0] and len(todo) == len(models)  # a reused network brings the baseline's metrics
                key = job_key(KIND, c.to_dict(), {"model": kind, "baseline": base}, {"dataset": d.path},
                              packages=("sim", "train"))
                jobs.append(Job(KIND, key, train_seed_model, (str(d.path), c, kind, base),
                                cache_path(root, KIND, key, "npz"), label=f"sim {d.sim_seed} seed {seed} {kind}",
                                torch=True))
    return jobs
