"""The datasets of the seed study's simulator seeds: the run's own ``dataset.npz`` for its seed, and
for every other seed S a run folder ``<run>/sims/seed<S>/`` whose sim stage publishes that seed's
dataset (sim.publish, sharded on the study's executor, its shards cached there). A seed whose
dataset is published with the same ``[sim]`` (seed aside) is not simulated again."""

from __future__ import annotations

from typing import Callable

from quadfdi.core.config import Config, replace_section
from quadfdi.core.executor import SERIAL, ExecSettings
from quadfdi.core.records import load_record
from quadfdi.core.rundir import RunDir
from quadfdi.train.study_jobs import StudyData


def sim_seed_folder(run: RunDir, sim_seed: int) -> RunDir:
    return RunDir(run.root / "sims" / f"seed{int(sim_seed)}")


def study_datasets(run: RunDir, cfg: Config, sim_seeds: list[int], settings: ExecSettings = SERIAL,
                   log: Callable[[str], None] = print) -> list[StudyData]:
    """One ``StudyData`` per simulator seed, in the order given; simulates the missing ones."""
    from quadfdi.sim.publish import publish_dataset

    out = []
    for s in sim_seeds:
        if s == cfg.sim.seed:
            out.append(StudyData(s, run.dataset, "dataset.npz"))
            continue
        sub, c = sim_seed_folder(run, s), replace_section(cfg, "sim", seed=s)
        rec = load_record(sub.root, "sim") if sub.root.is_dir() else None
        if rec is None or rec.get("config", {}).get("sim") != c.to_dict()["sim"] or not sub.dataset.is_file():
            log(f"study: simulating sim seed {s} into {sub.root}")
            publish_dataset(sub, c, show_progress=False, settings=settings)
        out.append(StudyData(s, sub.dataset, sub.dataset.relative_to(run.root).as_posix()))
    return out
