"""Publishing the dataset: ``dataset.npz`` and the ``config.toml`` that made it, as one stage.

Serial in this process, or in shards on an executor (sim.shards); both give the same bytes.
"""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.config import Config
from quadfdi.core.executor import SERIAL, ExecSettings
from quadfdi.core.rundir import RunDir


def publish_dataset(run: RunDir, cfg: Config, show_progress: bool = True, settings: ExecSettings = SERIAL,
                  cache_root: Path | None = None) -> Path:
    """Simulate ``cfg.sim`` and publish ``dataset.npz`` with ``config.toml`` as one stage (core.stage:
    the config is written only after the simulation succeeded); return the dataset's path.

    In this process by default; on ``settings``' executor in shards of ``sim.chunk`` trajectories
    (sim.shards), whose finished shards stay cached in ``<run>/cache/sim/`` so an interrupted run
    resumes (``cache_root``: shards kept elsewhere, e.g. shared by a sweep). Both give the same bytes."""
    from quadfdi.core.atomic import write_text
    from quadfdi.core.config import dumps_toml
    from quadfdi.core.stage import stage
    from quadfdi.formats.dataset import dataset_arrays, write_npz
    from quadfdi.sim.params import get_vehicle

    get_vehicle(cfg.sim.vehicle)  # an unknown vehicle is refused before anything is staged
    with stage(run.root, "sim", {"sim": cfg.to_dict()["sim"]}, targets=("dataset.npz", "config.toml"),
               need_bytes=cfg.sim.estimated_bytes) as st:
        if settings.workers == 1 and settings.scheduler == "local" and cache_root is None:
            from tqdm import tqdm

            from quadfdi.sim.shards import n_rows
            from quadfdi.sim.simulate import generate

            with tqdm(total=n_rows(cfg.sim), unit="traj", desc="sim", disable=not show_progress) as bar:
                arrays = generate(cfg.sim, progress=bar.update)
        else:
            from quadfdi.sim.shards import simulate_sharded

            arrays = simulate_sharded(run, cfg, settings, progress=show_progress, cache_root=cache_root)
        write_npz(st.path("dataset.npz"), dataset_arrays(arrays, cfg.sim))
        write_text(st.path("config.toml"), dumps_toml(cfg))
    return run.dataset


def generate_sharded(run: RunDir, cfg: Config, settings: ExecSettings = SERIAL, progress: bool = True,
                     cache_root: Path | None = None) -> Path:
    """``publish_dataset`` on ``settings``' executor, shards cached under ``cache_root`` (default: the run)."""
    return publish_dataset(run, cfg, progress, settings, cache_root)
