"""The rows of docs/realistic.md "Measured", from one or more realistic-suite dataset.npz files.

    python lab/realistic_measured.py SEED0/dataset.npz [SEED1/dataset.npz ...]

Prints a markdown table, one column per file (its sha256 prefix and suffix on top). Definitions:
- "faulty − others": over a flight's last 8 s, the faulty rotor's channel minus the mean of the
  other three, averaged over the flights of the class (rotor-side classes; ``fault_motor`` >= 0);
- healthy spread between motors: per healthy flight, the largest minus the smallest of the four
  motors' mean command over the flight, then the mean over those flights;
- vibration and voltage: means of ``telemetry`` over every sample of the flights of a class;
- true altitude, tilt and speed from ``states`` of the healthy flights (tilt = acos(cos roll cos pitch));
  a faulty flight may fall.
"""

from __future__ import annotations

import sys

import numpy as np

from quadfdi.core.jobcache import file_sha256 as sha256

LAST_S = 8.0


def _sha(path: str) -> str:
    d = sha256(path)
    return f"`{d[:8]}…{d[-4:]}`"


def _faulty_minus_others(x: np.ndarray, motor: np.ndarray) -> float:
    """(n, T, 4) channel of the class's flights, (n,) faulty rotor: mean over flights."""
    m = motor.astype(int)
    faulty = x[np.arange(len(m)), :, m]
    others = (x.sum(axis=2) - faulty) / 3.0
    return float(np.mean(faulty - others))


def measure(path: str) -> dict[str, str]:
    d = np.load(path, allow_pickle=False)
    ch = [str(c) for c in d["channel_names"]]
    st = [str(c) for c in d["state_names"]]
    splits = [str(s) for s in d["split_names"]]
    tel, states = d["telemetry"], d["states"]
    cls, split, motor = d["fault_class"].astype(int), d["split"].astype(int), d["fault_motor"].astype(int)
    last = d["time"] >= d["time"][-1] - LAST_S + 1e-9
    thr = tel[:, :, [ch.index(f"thr{i}") for i in range(1, 5)]]
    temp = tel[:, :, [ch.index(f"T{i}") for i in range(1, 5)]]
    healthy = cls == 0
    test_sets = np.array([s.startswith("test") for s in splits])[split]
    out = {"flights per split (" + ", ".join(splits) + ")": ", ".join(str(int((split == i).sum()))
                                                                      for i in range(len(splits)))}
    out["healthy test flights (in distribution / all)"] = (
        f"{int((healthy & (split == splits.index('test'))).sum())} / {int((healthy & test_sets).sum())}")
    roll, pitch = states[:, :, st.index("roll")], states[:, :, st.index("pitch")]
    tilt = np.degrees(np.arccos(np.clip(np.cos(roll) * np.cos(pitch), -1, 1)))
    speed = np.linalg.norm(states[:, :, [st.index(v) for v in ("vx", "vy", "vz")]], axis=2)
    out["healthy flights: lowest true altitude, max tilt, max speed"] = (
        f"{states[healthy, :, st.index('z')].min():.1f} m, {tilt[healthy].max():.1f}°, {speed[healthy].max():.1f} m/s")
    prop = cls == 4
    for v in ("vib_px4", "vib_ap"):
        out[f"{v} mean, healthy vs propeller"] = (f"{tel[healthy, :, ch.index(v)].mean():.2f} vs "
                                                  f"{tel[prop, :, ch.index(v)].mean():.2f} m/s²")
    cells = d["pack_cells"].astype(np.float64)
    out["pack voltage per cell, healthy flights"] = f"{(tel[:, :, ch.index('V_b')] / cells[:, None])[healthy].mean():.3f} V"
    rows = []
    for c in (2, 3, 4):  # MotorFault, OverheatFault, PropellerFault
        sel = (cls == c) & (motor >= 0)
        rows.append(f"{_faulty_minus_others(thr[sel][:, last], motor[sel]):+.3f}")
    out[f"throttle faulty − others, last {LAST_S:g} s: motor, overheat, propeller"] = ", ".join(rows)
    sel = (cls == 3) & (motor >= 0)
    out[f"temperature faulty − others, last {LAST_S:g} s: overheat"] = f"{_faulty_minus_others(temp[sel][:, last], motor[sel]):+.1f} K"
    means = thr[healthy].mean(axis=1)
    out["healthy throttle spread between motors (max − min of the four flight means)"] = (
        f"{float(np.mean(means.max(axis=1) - means.min(axis=1))):.3f}")
    out["flights touching the pack's maximum-power clamp"] = str(int((d["battery_limited"] > 0).sum()))
    kf, cool, cg = d["thrust_coef_factor"], d["cooling_factor"], d["cg_offset_m"]
    out["spreads: mass (with payload), flights dropping or picking up a payload, CG, k_F, cooling"] = (
        f"{d['mass_kg'].min():.2f}–{d['mass_kg'].max():.2f} kg, {100 * np.mean(d['payload_kg'] != 0):.0f} %, "
        f"±{100 * np.abs(cg).max():.1f} cm, ±{100 * np.abs(kf - 1).max():.1f} %, ±{100 * np.abs(cool - 1).max():.0f} %")
    frames = np.bincount(d["frame"].astype(int), minlength=2)
    tau = d["motor_tau_s"]
    out["capacity, age, cells, ambient, motor lag, frames plus/X"] = (
        f"{d['pack_capacity_ah'].min():.1f}–{d['pack_capacity_ah'].max():.1f} Ah, {d['pack_age'].min():.0f}–"
        f"{d['pack_age'].max():.0f}, {cells.min():.0f}–{cells.max():.0f}S, {d['t_amb'].min():.0f}–"
        f"{d['t_amb'].max():.0f} °C, {1e3 * tau.min():.0f}–{1e3 * tau.max():.0f} ms, {frames[0]}/{frames[1]}")
    wind, held = d["wind_ms"], split == splits.index("test_ood_wind")
    out["mean wind: in distribution, held-out set"] = (f"{wind[~held].min():.2f}–{wind[~held].max():.2f}, "
                                                       f"{wind[held].min():.2f}–{wind[held].max():.2f} m/s")
    return out


def main(paths: list[str]) -> None:
    cols = [measure(p) for p in paths]
    print("| | " + " | ".join(_sha(p) for p in paths) + " |")
    print("|---|" + "---|" * len(paths))
    for key in cols[0]:
        print(f"| {key} | " + " | ".join(c[key] for c in cols) + " |")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
