"""What each temperature shows of an overheating motor: per fault class, the faulted motor's (motor 1's on a
healthy flight) offset from the four's mean over the flight's last 2 s, from the windings (T1..T4, the
simulator's) and from the ESC boards (esc_temp1..4, what a log carries); mean over the class's flights.

    python lab/overheat_channels.py DATASET.npz
"""

from __future__ import annotations

import sys

import numpy as np


def main(path: str) -> None:
    d = np.load(path, allow_pickle=True)
    names = [str(c) for c in d["channel_names"]]
    esc_names = [str(c) for c in d["esc_channel_names"]]
    tel, esc, fc, fm = d["telemetry"], d["esc_telemetry"], d["fault_class"], d["fault_motor"]
    classes = [str(c) for c in d["class_names"]] if "class_names" in d else None
    wind = [names.index(f"T{k}") for k in range(1, 5)]
    board = [esc_names.index(f"esc_temp{k}") for k in range(1, 5)]
    for c in np.unique(fc):
        rows = np.flatnonzero(fc == c)
        dw, db = [], []
        for i in rows:
            m = max(int(fm[i]), 0)
            w, b = tel[i, -50:][:, wind].astype(np.float64), esc[i, -50:][:, board].astype(np.float64)
            dw.append((w[:, m] - w.mean(axis=1)).mean())
            db.append((b[:, m] - b.mean(axis=1)).mean())
        label = classes[int(c)] if classes else f"class {int(c)}"
        print(f"{label}: {len(rows)} flights, winding {np.mean(dw):+.2f} K, ESC board {np.mean(db):+.2f} K")


if __name__ == "__main__":
    main(sys.argv[1])
