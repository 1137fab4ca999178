"""The simulation's section of report.md, from ``dataset.npz`` and ``figures/sim_traj*.png``."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.reportmd import figure_links, not_run
from quadfdi.core.tables import md_table
from quadfdi.sim.fleet_report import split_table

HEADING = "## Simulation"
VEHICLES = {"paper": "vehicle {s.vehicle}",
            "realistic": "a vehicle drawn per flight (sim/variability.py)",
            "fleet": "vehicles drawn once, each flying {s.flights_per_vehicle} flights, the first "
                     "{s.reference_flights} healthy reference flights (sim/fleet.py)"}


def report_section(run_root: Path) -> list[str]:
    """Trajectories and windows per split and class (a fleet also: vehicles, reference flights, the healthy
    flights after them and their hours, what false alarms are scored on), and the trajectory figures."""
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
    fleet = s.scenario == "fleet"
    per_split = split_table(ds.arrays) if fleet else {}
    rows = []
    for code, split in enumerate(split_names(ds.arrays)):
        fc = ds["fault_class"][ds["split"] == code]
        extra = []
        if fleet:
            r = per_split[split]
            extra = [str(r["vehicles"]), str(r["reference"]), f"{r['healthy']} ({r['healthy_h']:.2f} h)"]
        rows.append([split, str(len(fc))] + extra + [str(int(np.sum(fc == k))) for k in range(len(names))]
                    + [str(len(fc) * per_traj)])
    out = [HEADING, "",
           f"Made by `quadfdi sim` (config: `config.toml`): {n} trajectories of {s.duration_s:g} s at "
           f"{1 / s.sample_dt_s:g} Hz ({t} samples, {c} channels, {VEHICLES[s.scenario].format(s=s)}, seed {s.seed}); "
           f"windows of {s.window} samples every {s.stride} ({per_traj} per trajectory), labelled by the severity at "
           f"their last sample (threshold {s.severity_threshold:g}).", ""]
    head = ["vehicles", "reference flights", "healthy after them"] if fleet else []
    out += md_table(["split", "trajectories"] + head + [f"{k}" for k in names] + ["windows"], rows)
    figs = sorted(p.name for p in (root / "figures").glob("sim_traj*.png"))
    return out + figure_links(root, figs)
