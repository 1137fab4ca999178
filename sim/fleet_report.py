"""Flights, vehicles and healthy flight time per split of fleet-suite datasets.

    python -m quadfdi.sim.fleet_report DATASET.npz [DATASET.npz ...]

Per split (and the sum over the files): vehicles, flights, reference flights and the healthy flights
after them, with their flight time in hours; then the healthy test exposure: the in-distribution test
split's healthy non-reference flights (what a false-alarm rate against a vehicle's reference is
scored on), and the same over every test set. A dataset without fleet keys reads as one vehicle per
flight (formats.dataset.vehicle_columns).
"""

from __future__ import annotations

import sys

import numpy as np

from quadfdi.formats.dataset import load_dataset, split_names, vehicle_columns


def split_table(arrays: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Split name -> vehicles, flights, reference flights, healthy non-reference flights and their hours."""
    v = vehicle_columns(arrays)
    seconds = float(arrays["telemetry"].shape[1] * (arrays["time"][1] - arrays["time"][0]))
    healthy = (arrays["fault_class"] == 0) & ~v["reference_flight"]
    out = {}
    for code, name in enumerate(split_names(arrays)):
        m = arrays["split"] == code
        out[name] = {"vehicles": len(np.unique(v["vehicle_id"][m])), "flights": int(m.sum()),
                     "reference": int((m & v["reference_flight"]).sum()), "healthy": int((m & healthy).sum()),
                     "healthy_h": float((m & healthy).sum() * seconds / 3600.0)}
    return out


def main(paths: list[str]) -> int:
    total: dict[str, dict[str, float]] = {}
    for path in paths:
        table = split_table(load_dataset(path).arrays)
        print(path)
        for name, row in table.items():
            print(f"  {name:18s} vehicles {row['vehicles']:4d}  flights {row['flights']:5d}  reference {row['reference']:4d}"
                  f"  healthy after them {row['healthy']:5d} ({row['healthy_h']:.2f} h)")
            acc = total.setdefault(name, {k: 0.0 for k in row})
            for k in row:
                acc[k] += row[k]
    test = total.get("test", {}).get("healthy_h", 0.0)
    every = sum(r["healthy_h"] for n, r in total.items() if n.startswith("test"))
    print(f"healthy test exposure over {len(paths)} dataset(s): {test:.2f} h in distribution "
          f"({int(total.get('test', {}).get('healthy', 0))} flights), {every:.2f} h over every test set")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
