"""The yaw trim in the motor commands: real flights against a simulated suite.

    python lab/yaw_trim_shares.py [--dataset DATASET.npz] [FLIGHT.npz ...]

Shares ``s_k = thr_k / mean(thr)`` in the project's motor order (ingest/motors.py; rotors 1 and 3 spin
one way, 2 and 4 the other on both frames). The diagonal offset ``(s1 + s3 - s2 - s4) / 4`` is the
yaw moment the attitude loop asks of the rotors' drag torques: it follows the yaw acceleration in a
turn and, in steady flight, holds whatever constant yaw moment the airframe has (twisted motor
mounts: sim/realistic_params.MOUNT_TWIST_DEG). Printed per ingested flight (airborne samples,
collective above 0.05, 1 s means): the offset's 5th/50th/95th percentiles and its slope on the yaw
acceleration (rad/s^2, from the 1 s mean of r); for a dataset, the percentiles of the per-flight mean
offset over its healthy X-frame flights (after the first 10 s) and the median per-flight slope.
"""

from __future__ import annotations

import numpy as np
from share_series import smooth, table_cli


def diagonal(thr: np.ndarray, r: np.ndarray, ok: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(1 s mean of the diagonal offset, yaw acceleration) at the samples ``ok``."""
    s = thr / thr.mean(axis=1, keepdims=True)
    d = smooth((s[:, 0] + s[:, 2] - s[:, 1] - s[:, 3]) / 4, ok)
    r_dot = np.gradient(smooth(np.nan_to_num(r), ok), dt)
    return d[ok], r_dot[ok]


def real_flight(path: str) -> str:
    f = np.load(path, allow_pickle=True)
    names = [str(n) for n in f["channel_names"]]
    x = f["telemetry"]
    thr = np.stack([x[:, names.index(f"thr{k}")] for k in range(1, 5)], axis=1)
    r = x[:, names.index("r")]
    ok = f["airborne"].astype(bool) & (thr.mean(axis=1) > 0.05) & np.isfinite(thr).all(axis=1) & np.isfinite(r)
    d, rd = diagonal(thr, r, ok, float(f["time"][1] - f["time"][0]))
    p = np.percentile(d, [5, 50, 95])
    return f"| {path} | {p[0]:+.3f} / {p[1]:+.3f} / {p[2]:+.3f} | {np.polyfit(rd, d, 1)[0]:.3f} (r {np.corrcoef(rd, d)[0, 1]:.2f}) |"


def dataset_row(path: str) -> str:
    ds = np.load(path, allow_pickle=True)
    names = list(map(str, ds["channel_names"]))
    cols = [names.index(f"thr{k}") for k in range(1, 5)]
    dt = float(ds["time"][1] - ds["time"][0])
    first = round(10.0 / dt)
    x_frame = list(map(str, ds["frame_names"])).index("x")
    means, slopes = [], []
    for i in np.flatnonzero((ds["fault_class"] == 0) & (ds["frame"] == x_frame)):
        x = ds["telemetry"][i].astype(np.float64)
        thr = x[:, cols]
        ok = thr.mean(axis=1) > 0.05
        ok[:first] = False
        d, rd = diagonal(thr, x[:, names.index("r")], ok, dt)
        means.append(d.mean())
        if np.ptp(rd) > 0.5:
            slopes.append(np.polyfit(rd, d, 1)[0])
    p = np.percentile(means, [1, 5, 50, 95, 99])
    return (f"| {path}: {len(means)} healthy X-frame flights, per-flight mean, 1/5/50/95/99 % | "
            f"{' / '.join(f'{v:+.3f}' for v in p)} | {np.median(slopes):.3f} (median of {len(slopes)}) |")


def main() -> None:
    table_cli(__doc__, "| flight | diagonal offset (s1 + s3 - s2 - s4) / 4 | per rad/s^2 of yaw acceleration |", real_flight, dataset_row)


if __name__ == "__main__":
    main()
