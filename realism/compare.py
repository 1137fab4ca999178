"""Real flights against the simulator, channel by channel, on steady segments (see steady.py, stats.py).

Real side: each log through ``ingest`` (refused logs are listed with their reason), steady
segments of at least 20 s inside the airborne time (AIR_MARGIN_S trimmed at take-off and landing).
Simulated side: the run's healthy trajectories; each channel is first "logged" at the real logs'
median rate of that channel (``stats.log_like``) and put through the same resampler as real logs
(core.resample) before any statistic. A simulated trajectory is shorter than 20 s at paper scale
(16 s), so its steady segments need only last its duration minus SETTLE_S; the report says so.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.channels import ANGLE_CHANNELS
from quadfdi.core.resample import resample
from quadfdi.realism import stats, steady

COMPARED = ("x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r", "V_b", "I_b",
            "thr1", "thr2", "thr3", "thr4")
MIN_STEADY_S = 20.0
AIR_MARGIN_S = 3.0  # s: take-off and landing transients are not steady flight
SETTLE_S = 2.0  # s: the simulated controller's start-up transient
THR = ("thr1", "thr2", "thr3", "thr4")


def _unwrap(v: np.ndarray) -> np.ndarray:
    out = v.copy()
    ok = np.isfinite(v)
    out[ok] = np.unwrap(v[ok])
    return out


def _hover(ch: dict, segs: list[dict]) -> dict:
    """Mean motor command and current over the steady segments (hover, or slow constant velocity:
    the thrust of level unaccelerated flight is the hover thrust to within the drag's share)."""
    idx = np.concatenate([np.arange(s["i0"], s["i1"]) for s in segs] or [np.zeros(0, int)])
    out = {"steady_s": float(len(idx) * 0.04), "kinds": sorted({s["kind"] for s in segs})}
    if len(idx) and all(k in ch for k in THR):
        out["thr"] = float(np.nanmean([ch[k][idx] for k in THR]))
    if len(idx) and "I_b" in ch:
        out["current_a"] = float(np.nanmean(ch["I_b"][idx]))
    return out


def real_flight(log: str) -> dict:
    from quadfdi.ingest.flight import ingest

    name = Path(log).name
    try:
        lr, a = ingest(log)
    except QuadfdiError as exc:
        return {"log": name, "refused": str(exc), "segments": []}
    grid, tel = a["time"], a["telemetry"].astype(np.float64)
    names = [str(n) for n in a["channel_names"]]
    ch = {n: tel[:, j] for j, n in enumerate(names) if a["mask"][:, j].any()}
    base = np.zeros(len(grid), bool)
    for t0, t1 in lr.airborne:
        base |= (grid >= t0 + AIR_MARGIN_S) & (grid <= t1 - AIR_MARGIN_S)
    segs = steady.segments(grid, ch, base, MIN_STEADY_S)
    out = {"log": name, "segments": segs, "channels": {}, "hover": _hover(ch, segs)}
    windows = [(s["start_s"], s["end_s"]) for s in segs]
    runs = [(s["i0"], s["i1"]) for s in segs]
    for c in COMPARED:
        raw = lr.channels.get(c)
        if raw is None or not segs:
            continue
        v = _unwrap(raw.v) if c in ANGLE_CHANNELS else raw.v
        noise, n = stats.hp_noise(raw.t, v, windows)
        spec = stats.psd(_unwrap(ch[c]) if c in ANGLE_CHANNELS else ch[c], runs)
        dt = np.diff(raw.t)
        out["channels"][c] = {"rate_hz": raw.rate_hz, "noise": noise, "pairs": n, "hf_rms": stats.hf_rms(spec),
                              "dt_jitter_ms": float(np.std(dt) * 1e3), "psd": spec}
    return out


def _sim_channel(t: np.ndarray, tel: np.ndarray, j: int, rows_segs: list, rate: float, angle: bool) -> dict:
    sq, npairs, specs = 0.0, 0, []
    for row, segs in rows_segs:
        tl, vl = stats.log_like(t, tel[row, :, j].astype(np.float64), rate)
        noise, n = stats.hp_noise(tl, _unwrap(vl) if angle else vl, [(s["start_s"], s["end_s"]) for s in segs])  # as the real side
        if n and np.isfinite(noise):
            sq, npairs = sq + noise ** 2 * n, npairs + n
        g, _ = resample(tl, vl, t, angle=angle)
        spec = stats.psd(_unwrap(g) if angle else g, [(s["i0"], s["i1"]) for s in segs])
        if spec is not None:
            specs.append(spec)
    spec = (specs[0][0], np.mean([s[1] for s in specs], axis=0)) if specs else None
    return {"rate_hz": min(rate, 1.0 / float(t[1] - t[0])), "noise": float(np.sqrt(sq / npairs)) if npairs else float("nan"),
            "pairs": npairs, "hf_rms": stats.hf_rms(spec), "psd": spec}


def sim_side(dataset_path: Path, rates: dict[str, float]) -> dict:
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.sim.params import get_vehicle

    ds = load_dataset(dataset_path)
    t, tel = ds["time"], ds["telemetry"]
    names = ds.channel_names
    min_s = min(MIN_STEADY_S, float(t[-1] - SETTLE_S) - 0.1)
    rows_segs = []
    for row in np.flatnonzero(ds["fault_class"] == 0):
        ch = {n: tel[row, :, j].astype(np.float64) for j, n in enumerate(names)}
        segs = steady.segments(t, ch, t >= SETTLE_S, min_s)
        if segs:
            rows_segs.append((int(row), segs))
    if not rows_segs:
        raise QuadfdiError(f"{dataset_path}: no healthy simulated trajectory has a steady segment")
    out = {"trajectories": len(rows_segs), "min_steady_s": min_s, "channels": {}}
    for c in COMPARED:
        out["channels"][c] = _sim_channel(t, tel, names.index(c), rows_segs, rates.get(c, 25.0), c in ANGLE_CHANNELS)
    hov = [_hover({n: tel[r, :, j].astype(np.float64) for j, n in enumerate(names)}, s) for r, s in rows_segs]
    mass = float(get_vehicle(ds.config.sim.vehicle).m)
    thr = [h["thr"] for h in hov if "thr" in h]
    cur = [h["current_a"] for h in hov if "current_a" in h]
    out["hover"] = {"thr": float(np.mean(thr)) if thr else None, "current_a": float(np.mean(cur)) if cur else None,
                    "mass_kg": mass, "current_per_kg": float(np.mean(cur)) / mass if cur else None}
    return out


def compare(dataset_path: Path, logs: list[str], masses: dict[str, float] | None = None) -> dict:
    """``masses``: log file name -> take-off mass in kg (no log records it) for current per kg."""
    real = [real_flight(log) for log in logs]
    for r in real:
        m = (masses or {}).get(r["log"])
        cur = r.get("hover", {}).get("current_a")
        if m and r.get("hover") is not None:
            r["hover"]["mass_kg"] = m
            r["hover"]["current_per_kg"] = cur / m if cur is not None else None
    rates = {}
    for c in COMPARED:
        rs = [r["channels"][c]["rate_hz"] for r in real if c in r.get("channels", {})]
        if rs:
            rates[c] = float(np.median(rs))
    return {"real": real, "sim": sim_side(dataset_path, rates), "rates": rates}
