"""What sets the simulated healthy tail an alarm threshold is fixed on? For one model of a fleet run, over
the healthy flights after the reference ones in the validation and test splits of every indexed prediction
set of that model, each flight's largest 1 - p(Healthy) over its decided windows (what a 1-of-1 rule reads),
grouped by mission type (sim/mission.py: 0 hover, 1 survey, 2 aggressive) and by whether one of the
vehicle's reference flights flew the same mission type; then Spearman's rank correlation of that maximum
with the vehicle's vibration floor (mean over the axes) and with the flight's mean wind.

    python lab/healthy_tail.py RUN MODEL        # e.g. a fleet run and gru
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.stats import mannwhitneyu, spearmanr

from quadfdi.evaluate.load import load_run

KEYS = ("mission_type", "vib_floor_ms2", "wind_ms", "vehicle_id", "fault_class", "reference_flight")
MISSIONS = ("hover", "survey", "aggressive")


def flight_maxima(run: Path, model: str, split: str) -> dict[str, np.ndarray]:
    """Per healthy non-reference flight of ``split`` over the model's sets: its largest decided 1 - p(Healthy),
    mission type, vibration floor, wind, and whether a reference flight of its vehicle flew its mission type."""
    sets, infos = load_run(run)
    out: dict[str, list] = {k: [] for k in ("p", "mission", "vib", "wind", "ref_mission")}
    for fl in (s for s in sets if s.model == model):
        with np.load(run / fl.dataset) as z:
            a = {k: z[k] for k in KEYS}
        part = fl.subset(fl.split == infos[fl.dataset].split_names.index(split))
        h = fl.class_names.index("Healthy")
        decided = part.decided if part.decided is not None else part.valid
        pf = np.where(decided, 1.0 - part.proba[..., h], -1.0)
        ref_rows = np.flatnonzero(a["reference_flight"])
        for i, row in enumerate(part.rows):
            if a["fault_class"][row] != h or a["reference_flight"][row]:
                continue
            own = ref_rows[a["vehicle_id"][ref_rows] == a["vehicle_id"][row]]
            out["p"].append(float(pf[i].max()))
            out["mission"].append(int(a["mission_type"][row]))
            out["vib"].append(float(np.mean(a["vib_floor_ms2"][row])))
            out["wind"].append(float(a["wind_ms"][row]))
            out["ref_mission"].append(bool(np.any(a["mission_type"][own] == a["mission_type"][row])))
    if not out["p"]:
        raise SystemExit(f"{run}: no {split} prediction set of model {model!r} with healthy flights")
    return {k: np.asarray(v) for k, v in out.items()}


def describe(p: np.ndarray) -> str:
    return (f"n {p.size:3d}, median {np.median(p):.3f}, 90th percentile {np.percentile(p, 90):.3f}, "
            f"above 0.95 {np.mean(p > 0.95):.0%}")


def main(run: Path, model: str) -> None:
    for split in ("validation", "test"):
        m = flight_maxima(run, model, split)
        print(f"{model}, {split}: healthy flights after the reference ones, largest decided 1 - p(Healthy)")
        for k, name in enumerate(MISSIONS):
            print(f"  {name:10s} {describe(m['p'][m['mission'] == k])}")
        same = m["ref_mission"]
        print(f"  mission flown by a reference flight     {describe(m['p'][same])}")
        print(f"  mission not flown by a reference flight {describe(m['p'][~same])}; Mann-Whitney p "
              f"{mannwhitneyu(m['p'][same], m['p'][~same]).pvalue:.2f}")
        for key, name in (("vib", "vibration floor"), ("wind", "mean wind")):
            r = spearmanr(m[key], m["p"])
            print(f"  Spearman with the {name}: {r.statistic:+.2f} (p {r.pvalue:.2g})")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]), sys.argv[2])
