"""``quadfdi sweep --dataset-from RUN``: every point reuses one run's published dataset instead of simulating.

A sweep over later stages' settings (``--stages train``) needs no simulation of its own: each point's
folder gets the run's ``dataset.npz`` as a hard link (a copy across file systems) published as that
point's sim stage with the point's own ``config.toml``, so the stages after it check their input as
in any run. Every point's [sim] must equal the run's (one line naming the first key that differs);
the dataset's sha256 is part of each point's job key, so another dataset is never mistaken for it.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from quadfdi.core.config import Config, dumps_toml, load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.npzio import read_npz, write_npz
from quadfdi.core.records import first_difference
from quadfdi.core.rundir import RunDir


WINDOWING = ("window", "stride")  # [sim] keys that cut windows from the stored flights, nothing simulated


def source_datasets(run_path: str, points: list[tuple[dict, Config]], out: Path) -> list[Path]:
    """Each point's dataset: run ``run_path``'s, or its copy with the point's windowing (written once
    per windowing under ``out``/datasets), after checking every other [sim] key against the run's."""
    run = RunDir(Path(run_path))
    if not run.dataset.is_file() or not run.config.is_file():
        raise QuadfdiError(f"--dataset-from {run_path}: no dataset.npz and config.toml there (run quadfdi sim first)")
    recorded = load_config(run.config).to_dict()["sim"]
    paths = []
    for values, cfg in points:
        sim = cfg.to_dict()["sim"]
        diff = first_difference({k: v for k, v in recorded.items() if k not in WINDOWING},
                                {k: v for k, v in sim.items() if k not in WINDOWING})
        if diff is not None:
            key, was, now = diff
            raise QuadfdiError(f"--dataset-from {run_path}: its dataset was simulated with sim.{key}={was!r}, the point "
                               f"{values} has {now!r}; sweep [sim] keys with --stages sim,...")
        same = all(sim[k] == recorded[k] for k in WINDOWING)
        paths.append(run.dataset.resolve() if same else rewindowed(run.dataset, sim, out))
    return paths


def rewindowed(dataset: Path, sim: dict, out: Path) -> Path:
    """``dataset`` with its embedded [sim] windowing set to ``sim``'s (the flights unchanged), under
    ``out``/datasets; written once (atomically), then reused."""
    if sim["window"] > 0 and sim["window"] > np.load(dataset, mmap_mode="r")["time"].shape[0]:
        raise QuadfdiError(f"sim.window={sim['window']} is longer than the flights of {dataset}")
    target = out / "datasets" / f"window{sim['window']}_stride{sim['stride']}" / "dataset.npz"
    if not target.is_file():
        arrays = read_npz(dataset, "dataset")
        embedded = json.loads(str(arrays["config"]))
        embedded["sim"].update({k: sim[k] for k in WINDOWING})
        arrays["config"] = np.array(json.dumps(embedded, sort_keys=True))
        target.parent.mkdir(parents=True, exist_ok=True)
        write_npz(target, arrays)
    return target


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
