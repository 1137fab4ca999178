"""The simulation's section of report.md, from ``dataset.npz`` and ``figures/sim_traj*.png``."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.reportmd import figure_links, not_run
from quadfdi.core.tables import md_table

HEADING = "## Simulation"


def report_section(run_root: Path) -> list[str]:
    """Trajectories and windows per split and class, and the trajectory figures."""
    import numpy as np

    from quadfdi.formats.dataset import class_names, load_dataset, split_names, window_starts

    root = Path(run_root)
    path = root / "dataset.npz"
    if not path.is_file():
        return not_run(HEADING, f"no dataset.npz in this run (`quadfdi sim --out {root}` writes it)")
    ds = load_dataset(path)
    s = ds.config.sim
    n, t, c = ds["telemetry"].shape
    per_traj = len(window_starts(t, s.window, s.stride))
    names = class_names(ds.arrays)  # the paper's four, or the dataset's own (realistic suite)
    rows = []
    for code, split in enumerate(split_names(ds.arrays)):
        fc = ds["fault_class"][ds["split"] == code]
        rows.append([split, str(len(fc))] + [str(int(np.sum(fc == k))) for k in range(len(names))]
                    + [str(len(fc) * per_traj)])
    out = [HEADING, "",
           f"Made by `quadfdi sim` (config: `config.toml`): {n} trajectories of {s.duration_s:g} s at "
           f"{1 / s.sample_dt_s:g} Hz ({t} samples, {c} channels, vehicle {s.vehicle}, seed {s.seed}); windows of "
           f"{s.window} samples every {s.stride} ({per_traj} per trajectory), labelled by the severity at their last "
           f"sample (threshold {s.severity_threshold:g}).", ""]
    out += md_table(["split", "trajectories"] + [f"{k}" for k in names] + ["windows"], rows)
    figs = sorted(p.name for p in (root / "figures").glob("sim_traj*.png"))
    return out + figure_links(root, figs)
