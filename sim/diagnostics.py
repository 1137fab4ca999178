"""Flight-sanity diagnostics of a simulated dataset: a per-class summary of the telemetry.

``python -m quadfdi.sim.diagnostics [seed]`` times a paper-scale ``generate`` and prints ``summarize``
of it (docs/params.md quotes the table).
"""

from __future__ import annotations

import numpy as np

from quadfdi.sim.config import SimConfig
from quadfdi.sim.simulate import generate


def summarize(out: dict[str, np.ndarray]) -> str:
    """Per-class telemetry sanity summary of a ``generate`` output (text table).

    Changes are (mean of the last second) - (mean of the first second) of the noisy telemetry;
    "faulty motor" columns use the faulty/overheated motor, minus the mean of the other three.
    """
    names = list(out["channel_names"])
    tel = out["telemetry"].astype(np.float64)
    st = out["states"].astype(np.float64)
    sn = list(out["state_names"])
    cls, fm = out["fault_class"], out["fault_motor"]
    n_last = min(25, tel.shape[1] // 4)

    def change(a: np.ndarray) -> np.ndarray:  # (n, T, ...) -> (n, ...)
        return a[:, -n_last:].mean(axis=1) - a[:, :n_last].mean(axis=1)

    thr = tel[..., names.index("thr1"):names.index("thr1") + 4]
    temp = tel[..., names.index("T1"):names.index("T1") + 4]
    d_v, d_i = change(tel[..., names.index("V_b")]), change(tel[..., names.index("I_b")])
    d_thr, d_temp = change(thr), change(temp)
    head = ("dV_b [V]", "dI_b [A]", "d thr mean [-]", "d thr faulty-others", "d T faulty-others [K]")
    rows = [f"{'class':9s} {'n':>3s}  " + "".join(f"{h:22s}" for h in head) + "max T [degC]"]
    labels = ("Healthy", "Battery", "Motor", "Overheat")

    def fmt(x: np.ndarray) -> str:
        return f"{x.mean():+6.2f} [{x.min():+5.2f},{x.max():+5.2f}]" if x.size else "-"

    for k, label in enumerate(labels):
        m = cls == k
        if not m.any():
            continue
        own = (cls[m] >= 2)
        idx = np.flatnonzero(m)
        if own.all():
            sel = fm[idx].astype(np.int64)
            onehot = np.eye(4, dtype=bool)[sel]
            thr_rel = d_thr[idx][onehot] - d_thr[idx][~onehot].reshape(-1, 3).mean(axis=1)
            t_rel = d_temp[idx][onehot] - d_temp[idx][~onehot].reshape(-1, 3).mean(axis=1)
            extra = f"{fmt(thr_rel):22s}{fmt(t_rel):22s}"
        else:
            extra = f"{'-':22s}{'-':22s}"
        rows.append(f"{label:9s} {m.sum():3d}  {fmt(d_v[m]):22s}{fmt(d_i[m]):22s}{fmt(d_thr[m].mean(axis=1)):22s}"
                    f"{extra}{temp[m].max():6.1f}")
    tilt = np.degrees(np.arccos(np.cos(st[..., sn.index("roll")]) * np.cos(st[..., sn.index("pitch")])))
    err = np.linalg.norm(st[..., 0:3] - out["reference"][..., 0:3], axis=-1)[:, 50:]
    f = cls > 0
    rows.append(f"max tilt {tilt.max():.1f} deg; position error after 2 s: RMS {np.sqrt((err**2).mean()):.3f} m, "
                f"max {err.max():.3f} m; finite: {bool(np.isfinite(tel).all())}; battery clamp steps: "
                f"{int(out['battery_limited'].sum())}")
    if f.any():
        rows.append(f"latest detectable time {np.nanmax(out['detectable_s'][f]):.2f} s of {out['time'][-1]:.2f} s; "
                    f"undetectable fault trajectories: {int(np.isnan(out['detectable_s'][f]).sum())}; "
                    f"min effectiveness {out['effectiveness'].min():.3f}")
    return "\n".join(rows)


if __name__ == "__main__":  # python -m quadfdi.sim.diagnostics [seed]: paper-scale timing and summary
    import sys
    import time as _time

    _cfg = SimConfig(seed=int(sys.argv[1]) if len(sys.argv) > 1 else 0)
    generate(_cfg, indices=range(4))  # warm-up (imports, caches)
    _t0 = _time.perf_counter()
    _out = generate(_cfg)
    _dt = _time.perf_counter() - _t0
    print(f"generate: {_cfg.n_traj} trajectories x {_cfg.duration_s:g} s "
          f"({(_cfg.n_samples - 1) * _cfg.substeps} steps of {_cfg.sim_dt_s * 1e3:g} ms) in {_dt:.2f} s")
    print(summarize(_out))
