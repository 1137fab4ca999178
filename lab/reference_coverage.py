"""How much of a flight lies outside what its vehicle's reference flew (vehicle/coverage.py), over a fleet
run's dataset: a flight's ``outside`` (the largest share of its airborne samples past the reference's 5-95 %
forward speed or yaw rate range by more than matters to the share model) for the reference flights (against
the reference they are part of) and for every later flight; then, with a model, the largest p(fault) =
1 - p(Healthy) over the decided windows of each healthy validation and test flight (its prediction sets),
beyond vehicle/coverage.LIMIT against within it, and the rank correlation of the two.

    python lab/reference_coverage.py RUN [MODEL]      # e.g. a fleet run after `quadfdi train`, and gru

Two more views of real flights: ``logs VEHICLE_JSON PATH...`` prints each flight's ``outside`` against that
reference beside the share of its samples merely past a range (every excess counted, however small) and how
many pass LIMIT either way; ``split LOG...`` cuts each log as `quadfdi crazypad` cuts the shared PX4 flights
(quadfdi/crazypad_px4.py), learns the reference from the first part and prints the rest's coverage.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from quadfdi.evaluate.load import load_run
from quadfdi.formats.vehicle import load_vehicle
from quadfdi.train.vehicle_ref import dataset_flight, learn_references
from quadfdi.vehicle import quantities as q
from quadfdi.vehicle.coverage import LIMIT, coverage, regressor_values
from quadfdi.vehicle.flights import Flight, find_flights, read_flight
from quadfdi.vehicle.learn import learn


def outside(run: Path) -> tuple[np.ndarray, np.ndarray]:
    """(N,) each flight's coverage ``outside`` against its own vehicle's reference, (N,) reference flag."""
    with np.load(run / "dataset.npz") as z:
        arrays = {k: z[k] for k in z.files}
    refs = learn_references(arrays, "dataset.npz")
    vid = arrays["vehicle_id"]
    frac = np.array([coverage(dataset_flight(arrays, r, "dataset.npz"), refs[int(vid[r])])["outside"]
                     for r in range(len(vid))], float)
    return frac, arrays["reference_flight"].astype(bool)


def main(run: Path, model: str | None) -> None:
    frac, ref = outside(run)
    for name, m in (("reference flights", ref), ("later flights", ~ref)):
        pct = np.percentile(frac[m], [50, 90, 99, 100])
        print(f"{name:18s} {int(m.sum()):5d}: outside median {pct[0]:.2f}, 90 % {pct[1]:.2f}, 99 % {pct[2]:.2f}, "
              f"max {pct[3]:.2f}; beyond {LIMIT:g}: {int((frac[m] > LIMIT).sum())}")
    if model is None:
        return
    sets, infos = load_run(run)
    for fl, split in ((s, split) for s in sets if s.model == model for split in ("validation", "test")):
        info = infos[fl.dataset]
        test = fl.subset(fl.split == info.split_names.index(split))
        h = fl.class_names.index("Healthy")
        healthy = info.arrays["fault_class"][test.rows] == h
        pf = np.where(test.voting(), 1.0 - test.proba[..., h], -1.0).max(axis=1)[healthy]
        cov = frac[test.rows][healthy]
        rho = spearmanr(cov, pf)
        print(f"{model} sim {fl.sim_seed} train {fl.train_seed}: {int(healthy.sum())} healthy {split} flights; "
              f"largest p(fault) median {np.median(pf[cov > LIMIT]):.3f} beyond ({int((cov > LIMIT).sum())}), "
              f"{np.median(pf[cov <= LIMIT]):.3f} within ({int((cov <= LIMIT).sum())}); Spearman rho "
              f"{rho.statistic:.2f} (p {rho.pvalue:.1g})")


def past_range(fl: Flight, reference: dict) -> float:
    """The largest share of the flight's share samples past a regressor's 5-95 % range, by any amount."""
    model, sel, vals = reference["share_model"], q.share_samples(fl), regressor_values(fl)
    out = 0.0
    for name in model["regressors"]:
        lo, hi = model["range_5_95"][name]
        x = vals[name][sel]
        x = x[np.isfinite(x)]
        out = max(out, float(np.mean((x < lo) | (x > hi)))) if len(x) else out
    return out


def logs(vehicle: str, paths: list[str]) -> None:
    ref = load_vehicle(vehicle)
    counted, past = [], []
    for path, name in find_flights(paths):
        cov = coverage(read_flight(path, name), ref)
        if cov is None or cov["outside"] is None:
            continue
        counted.append(cov["outside"])
        past.append(past_range(read_flight(path, name), ref))
        print(f"{name}: outside {counted[-1]:.3f}, past the range by any amount {past[-1]:.3f}")
    c, p = np.array(counted), np.array(past)
    print(f"{len(c)} flights: outside median {np.median(c):.2f}, max {c.max():.2f}, beyond {LIMIT:g}: "
          f"{int((c > LIMIT).sum())}; past the range by any amount: median {np.median(p):.2f}, max {p.max():.2f}, "
          f"above {LIMIT:g}: {int((p > LIMIT).sum())}")


def split_logs(paths: list[str]) -> None:
    from quadfdi.crazypad_px4 import REFERENCE_FRACTION, split

    for path in map(Path, paths):
        fl = read_flight(path, path.stem)
        head, tail, info = split(fl.arrays, path.stem)
        ref = learn([Flight(f"{path.stem} (first part)", path, fl.sha256, head)])
        cov = coverage(Flight(f"{path.stem} (rest)", path, fl.sha256, tail), ref)
        ranges = "; ".join(f"{p['what']} {p['range_5_95'][0]:.2f} to {p['range_5_95'][1]:.2f} {p['unit']}: "
                           f"{p['outside']:.2f} of the rest outside" for p in cov["regressors"].values())
        print(f"{path.name}: cut at {info['cut_s']:.1f} s (the first {REFERENCE_FRACTION:.0%} airborne); {ranges}; "
              f"beyond {LIMIT:g}: {cov['beyond']}")


if __name__ == "__main__":
    if len(sys.argv) >= 4 and sys.argv[1] == "logs":
        logs(sys.argv[2], sys.argv[3:])
    elif len(sys.argv) >= 3 and sys.argv[1] == "split":
        split_logs(sys.argv[2:])
    elif len(sys.argv) in (2, 3):
        main(Path(sys.argv[1]), sys.argv[2] if len(sys.argv) == 3 else None)
    else:
        raise SystemExit(__doc__)
