"""The seed study as jobs of ``core.executor``: one per seed x model, each keyed by its config
(the seed included), the dataset's hash and the code of ``sim`` and ``train``, its metrics cached
as ``<run>/cache/study/<key>.json``. Training is deterministic on one thread (every worker has
one), so a study gives the same metrics serial or distributed, and a rerun takes them from the cache."""

from __future__ import annotations

from pathlib import Path

from core.config import Config, replace_section
from core.executor import Job
from core.jobcache import cache_path, job_key
from core.jsonio import to_jsonable
from core.rundir import RunDir

KIND = "study"
MODELS = ("cnode", "gru")


def train_seed_model(dataset: str, cfg: Config, kind: str) -> dict:
    """Train ``kind`` with ``cfg.train.seed`` on ``dataset`` (a job); its and the baseline's test metrics."""
    from sim.dataset import load_dataset
    from train.run import train_all

    result = train_all(load_dataset(dataset), cfg, [kind], log=lambda _: None)
    return to_jsonable(result["metrics"])


def seed_model_jobs(run: RunDir, cfg: Config, seeds: list[int], models: tuple[str, ...] = MODELS,
                    cache_root: Path | None = None) -> list[Job]:
    """Jobs in (seed, model) order; results under ``cache_root`` (default: the run folder)."""
    root = run.root if cache_root is None else Path(cache_root)
    jobs = []
    for seed in seeds:
        c = replace_section(cfg, "train", seed=seed)
        for kind in models:
            key = job_key(KIND, c.to_dict(), {"model": kind}, {"dataset": run.dataset}, packages=("sim", "train"))
            jobs.append(Job(KIND, key, train_seed_model, (str(run.dataset), c, kind), cache_path(root, KIND, key, "json"),
                            label=f"seed {seed} {kind}", torch=True))
    return jobs
