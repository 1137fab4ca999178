"""The simulated ESC temperatures of a realistic-suite dataset, per class (docs/params.md "ESC temperature"):

    PYTHONPATH=. python scripts/esc_temp_summary.py DATASET.npz [LAST_S]

Per flight: the rise of the four ESCs' mean over the flight, the mean above the flight's ambient at
the end, and ``esck_t_rel`` (each ESC minus the four's mean, the flightlog-esc channel) averaged over
the last LAST_S seconds (default 5); for rotor faults the faulty motor's value and the largest |value|
of the other three. Medians (p10-p90) per class.
"""

from __future__ import annotations

import sys

import numpy as np


def _q(x: np.ndarray) -> str:
    if x.size == 0:
        return "-"
    p10, p50, p90 = np.percentile(x, [10, 50, 90])
    return f"{p50:+.2f} ({p10:+.2f} .. {p90:+.2f})"


def main(argv: list[str]) -> int:
    d = np.load(argv[0])
    last = float(argv[1]) if len(argv) > 1 else 5.0
    names = [str(n) for n in d["esc_channel_names"]]
    T = d["esc_telemetry"][..., [names.index(f"esc_temp{k}") for k in range(1, 5)]].astype(np.float64)
    n_last = int(round(last / float(d["time"][1] - d["time"][0])))
    common = T.mean(axis=2)
    rel = (T - common[..., None])[:, -n_last:].mean(axis=1)  # (N, 4)
    cls, motor, classes = d["fault_class"], d["fault_motor"], [str(c) for c in d["class_names"]]
    print(f"{len(cls)} flights of {d['time'][-1] + d['time'][1]:.0f} s; t_rel over the last {last:g} s")
    print("class | n | rise of the mean | end mean - ambient | faulty ESC t_rel | max |t_rel| of the others (healthy: of all 4)")
    for c, name in enumerate(classes):
        sel = cls == c
        rise = common[sel, -n_last:].mean(1) - common[sel, :n_last].mean(1)
        above = common[sel, -n_last:].mean(1) - d["t_amb"][sel]
        if motor[sel].min() >= 0:
            idx = np.flatnonzero(sel)
            own = rel[idx, motor[idx]]
            others = np.array([np.abs(np.delete(rel[i], motor[i])).max() for i in idx])
        else:
            own, others = np.array([]), np.abs(rel[sel]).max(axis=1)
        print(f"{name} | {sel.sum()} | {_q(rise)} K | {_q(above)} K | {_q(own)} K | {_q(others)} K")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
