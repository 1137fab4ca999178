"""Replay a real flight's ESC currents through the simulator's ESC thermal model (sim/esc_thermal.py) and
compare with the temperatures its ESCs reported (docs/params.md "ESC temperature"):

    python lab/esc_thermal_replay.py FLIGHT.npz [--amb DEGC] [--vi M_S] [--step S]

FLIGHT.npz is ``quadfdi ingest``'s output with esc_cur1..4, esc_temp1..4, V_b. The model runs from the
first sample with every ESC at ``--amb`` (default: the four's mean first reading) and no warm-up, on
the logged ESC currents and V_b; the airflow is an induced velocity ``--vi`` (default 5 m/s, a
multirotor's disk loading of ~30-60 N/m^2; the log has no thrust) with the ground speed added (no
wind in the log). Three corners of the drawn ranges: "cool" (small losses, large C, large G), "mid"
(the ranges' middles), "hot" (large losses, small C, small G); no sensor offset, no quantisation.
"""

from __future__ import annotations

import argparse

import numpy as np

from quadfdi.sim import esc_thermal as E


def corner(which: str) -> dict[str, np.ndarray]:
    lo_hi = {"cool": 0, "mid": None, "hot": 1}[which]

    def pick(rng, hot_is_high=True):
        if lo_hi is None:
            return 0.5 * (rng[0] + rng[1])
        return rng[lo_hi] if hot_is_high else rng[1 - lo_hi]
    d = {"C": pick(E.C_J_PER_K, False), "S": pick(E.S_SW), "I_q": pick(E.I_Q_A), "G_still": pick(E.G_STILL, False)}
    d = {k: np.array([v]) for k, v in d.items()}
    d["R"] = np.full((1, 4), pick(E.R_OHM))
    d["G_flow"] = np.full((1, 4), pick(E.G_FLOW, False))
    return d


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("flight")
    ap.add_argument("--amb", type=float, default=None)
    ap.add_argument("--vi", type=float, default=5.0)
    ap.add_argument("--step", type=float, default=5.0)
    ap.add_argument("--C", type=float, default=None, help="a fourth column: 'mid' with this heat capacity [J/K]")
    a = ap.parse_args(argv)
    f = np.load(a.flight)
    names = [str(n) for n in f["channel_names"]]

    def col(n: str) -> np.ndarray:
        j = names.index(n)
        return np.where(f["mask"][:, j], f["telemetry"][:, j], np.nan).astype(np.float64)
    I = np.stack([col(f"esc_cur{k}") for k in range(1, 5)], 1)
    Tm = np.stack([col(f"esc_temp{k}") for k in range(1, 5)], 1)
    ok = np.isfinite(I).all(1) & np.isfinite(Tm).all(1) & np.isfinite(col("V_b"))
    t, I, Tm, V = f["time"][ok], I[ok], Tm[ok], col("V_b")[ok]
    vg = np.sqrt(np.nan_to_num(col("vx")[ok]) ** 2 + np.nan_to_num(col("vy")[ok]) ** 2 + np.nan_to_num(col("vz")[ok]) ** 2)
    amb = float(Tm[0].mean()) if a.amb is None else a.amb
    dt = float(t[1] - t[0])
    v = np.sqrt(a.vi * a.vi + vg * vg)
    print(f"{a.flight}: {t[-1] - t[0]:.1f} s, ambient {amb:.2f} degC, ESC current mean {I.mean():.2f} A, V_b {V.mean():.1f} V")
    pred = {}
    cols = ("cool", "mid", "hot") + (("C",) if a.C is not None else ())
    for c in cols:
        d = corner("mid" if c == "C" else c)
        d["C"] = np.array([a.C]) if c == "C" else d["C"]
        G = d["G_still"][:, None] + d["G_flow"] * np.sqrt(v)[:, None, None]
        d["t_pre"] = np.zeros(1)
        pred[c] = E.temperatures(E.losses(I[:, None], V[:, None], d), G, np.array([amb]), d, dt)[:, 0]
    print("  t [s] | logged mean | " + " | ".join(c if c != "C" else f"mid, C={a.C:g}" for c in cols)
          + "   (mean of the four ESCs, degC)")
    for s in np.arange(t[0], t[-1] + 1e-9, a.step):
        j = min(np.searchsorted(t, s), len(t) - 1)
        print(f"  {t[j] - t[0]:5.1f} | {Tm[j].mean():6.2f} | " + " | ".join(f"{pred[c][j].mean():6.2f}" for c in pred))
    end = slice(len(t) - int(round(5.0 / dt)), len(t))
    spread = lambda x: np.round(x[end].mean(0) - x[end].mean(), 2)  # noqa: E731
    print(f"  last 5 s, each ESC minus the four's mean: logged {spread(Tm)}; "
          + "; ".join(f"{c} {spread(pred[c])}" for c in cols))
    print(f"  last 5 s ESC current share: {np.round(I[end].mean(0) / I[end].mean(), 2)}; flight mean share {np.round(I.mean(0) / I.mean(), 2)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
