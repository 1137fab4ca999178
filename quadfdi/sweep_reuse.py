"""``quadfdi sweep --dataset-from RUN``: every point reuses one run's published dataset instead of simulating.

A sweep over later stages' settings (``--stages train``) needs no simulation of its own: each point's
folder gets the run's ``dataset.npz`` as a hard link (a copy across file systems) published as that
point's sim stage with the point's own ``config.toml``, so the stages after it check their input as
in any run. Every point's [sim] must equal the run's (one line naming the first key that differs);
the dataset's sha256 is part of each point's job key, so another dataset is never mistaken for it.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from quadfdi.core.config import Config, dumps_toml, load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.records import first_difference
from quadfdi.core.rundir import RunDir


def source_dataset(run_path: str, points: list[tuple[dict, Config]]) -> Path:
    """The dataset of run folder ``run_path``, after checking every point's [sim] against the run's."""
    run = RunDir(Path(run_path))
    if not run.dataset.is_file() or not run.config.is_file():
        raise QuadfdiError(f"--dataset-from {run_path}: no dataset.npz and config.toml there (run quadfdi sim first)")
    recorded = load_config(run.config).to_dict()["sim"]
    for values, cfg in points:
        diff = first_difference(recorded, cfg.to_dict()["sim"])
        if diff is not None:
            key, was, now = diff
            raise QuadfdiError(f"--dataset-from {run_path}: its dataset was simulated with sim.{key}={was!r}, the point "
                               f"{values} has {now!r}; sweep [sim] keys with --stages sim,...")
    return run.dataset.resolve()


def publish_linked(run: RunDir, cfg: Config, dataset: Path) -> None:
    """Publish ``dataset`` in ``run`` as its sim stage (a hard link, else a copy) with ``cfg``'s config.toml."""
    from quadfdi.core.atomic import write_text
    from quadfdi.core.stage import stage

    with stage(run.root, "sim", {"sim": cfg.to_dict()["sim"]}, targets=("dataset.npz", "config.toml")) as st:
        target = st.path("dataset.npz")
        try:
            os.link(dataset, target)
        except OSError:
            shutil.copyfile(dataset, target)
        write_text(st.path("config.toml"), dumps_toml(cfg))
