"""Do the trailing rotors work harder in translation? Real flights against a simulated suite.

    python lab/forward_flight_shares.py [--dataset DATASET.npz] [FLIGHT.npz ...]

Shares ``s_k = thr_k / mean(thr)`` in the project's motor order (ingest/motors.py: on an X frame
rotor 1 front-left, 2 rear-left, 3 rear-right, 4 front-right). Each is smoothed over 1 s; then
``rear - front = (s2 + s3 - s1 - s4) / 4`` is regressed on the forward airspeed proxy ``vx_h``
(ground velocity in the heading frame) and ``right - left = (s3 + s4 - s1 - s2) / 4`` on ``vy_h``
(+y = left): the slope is the trailing rotors' thrust-share excess per m/s, the figure
sim/realistic_params.FLAP_PER_MS is drawn around. Printed per ingested flight (airborne samples,
collective above 0.05) and, for a dataset, the median over its healthy X-frame flights whose forward
speed spans more than 2 m/s (after the first 10 s). (The per-flight draw ``flap`` is not stored in
dataset.npz, so the simulated slope is read from the commands, as the real one is.)
"""

from __future__ import annotations

import numpy as np
from share_series import smooth, table_cli


def slopes(thr: np.ndarray, yaw: np.ndarray, vx: np.ndarray, vy: np.ndarray, ok: np.ndarray) -> tuple[float, ...]:
    """(rear-front slope, its r with vx_h, right-left slope, its r with vy_h) of one flight."""
    s = thr / thr.mean(axis=1, keepdims=True)
    vxh = np.cos(yaw) * vx + np.sin(yaw) * vy
    vyh = -np.sin(yaw) * vx + np.cos(yaw) * vy
    ok = ok & np.isfinite(s).all(axis=1) & np.isfinite(vxh) & np.isfinite(vyh)
    rf = smooth((s[:, 1] + s[:, 2] - s[:, 0] - s[:, 3]) / 4, ok)[ok]
    rl = smooth((s[:, 2] + s[:, 3] - s[:, 0] - s[:, 1]) / 4, ok)[ok]
    ax, ay = smooth(vxh, ok)[ok], smooth(vyh, ok)[ok]
    return (np.polyfit(ax, rf, 1)[0], np.corrcoef(ax, rf)[0, 1], np.polyfit(ay, rl, 1)[0], np.corrcoef(ay, rl)[0, 1])


def real_flight(path: str) -> str:
    d = np.load(path, allow_pickle=True)
    names = [str(n) for n in d["channel_names"]]
    x = d["telemetry"]
    col = {n: x[:, names.index(n)] for n in ("yaw", "vx", "vy")}
    thr = np.stack([x[:, names.index(f"thr{k}")] for k in range(1, 5)], axis=1)
    ok = d["airborne"].astype(bool) & (thr.mean(axis=1) > 0.05)
    a, ra, b, rb = slopes(thr, col["yaw"], col["vx"], col["vy"], ok)
    sp = np.hypot(col["vx"], col["vy"])[ok & np.isfinite(col["vx"])]
    return f"| {path} | {a:.4f} (r {ra:.2f}) | {b:.4f} (r {rb:.2f}) | {np.percentile(sp, 90):.1f} |"


def dataset_row(path: str) -> str:
    d = np.load(path, allow_pickle=True)
    names = list(map(str, d["channel_names"]))
    c = {n: names.index(n) for n in ("yaw", "vx", "vy")}
    cols = [names.index(f"thr{k}") for k in range(1, 5)]
    first = round(10.0 / float(d["time"][1] - d["time"][0]))
    x_frame = list(map(str, d["frame_names"])).index("x")
    rows = []
    for i in np.flatnonzero((d["fault_class"] == 0) & (d["frame"] == x_frame)):
        x = d["telemetry"][i].astype(np.float64)
        thr = x[:, cols]
        ok = thr.mean(axis=1) > 0.05
        ok[:first] = False
        if np.ptp(x[ok, c["vx"]]) <= 2.0 and np.ptp(x[ok, c["vy"]]) <= 2.0:
            continue
        rows.append(slopes(thr, x[:, c["yaw"]], x[:, c["vx"]], x[:, c["vy"]], ok))
    r = np.median(np.array(rows), axis=0)
    return (f"| {path}: median of {len(rows)} healthy X-frame flights | {r[0]:.4f} (r {r[1]:.2f}) | "
            f"{r[2]:.4f} (r {r[3]:.2f}) | |")


def main() -> None:
    header = "| flight | rear - front share per m/s forward | right - left per m/s to the left | speed p90 m/s |"
    table_cli(__doc__, header, real_flight, dataset_row)


if __name__ == "__main__":
    main()
