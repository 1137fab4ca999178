"""Each autopilot's vibration metric, as the simulator writes it, against the autopilot's own filter
chain run on a simulated flight's accelerometer: not the closed form compared with itself.

A realistic-suite flight with a cut propeller is simulated; over a steady stretch after the cut has
reached its final severity, its rotors' thrusts, the cut, the residual imbalance, the mass and the
vibration floor give the 1 kHz accelerometer (sim.propeller.synthesise); PX4's VehicleIMU chain and
ArduPilot's calc_vibration run on it; the ArduPilot value is then taken as ingest takes it from a
log's VIBE message ((VibeX + VibeY) / 2). Both must match the flight's logged channels vib_px4 and
vib_ap within the logged sample scatter and the closed forms' stated error."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from quadfdi.core.config import load_config
from quadfdi.sim import propeller, realistic, telemetry
from quadfdi.sim import realistic_faults as rf
from quadfdi.sim import realistic_loop as rl
from quadfdi.sim import realistic_params as P
from quadfdi.sim.variability import draw_flight
from tests.conftest import ROOT


def _propeller_flight():
    cfg = load_config(ROOT / "configs" / "realistic.toml").sim
    cfg = dataclasses.replace(cfg, n_traj=40, ood_traj=0, duration_s=20.0, chunk=40)
    cls, _, group = realistic.labels(cfg)
    props = np.flatnonzero(cls == cfg.classes.index("PropellerFault"))
    plans = [rf.plan([draw_flight(cfg, int(j), int(group[j]))], cfg.classes, cls[[j]], cfg.duration_s) for j in props]
    i = int(props[int(np.argmax([p.s_max[0] for p in plans]))])  # the deepest cut: its rotor term dominates
    draws = [draw_flight(cfg, i, int(group[i]))]
    fp = rf.plan(draws, cfg.classes, cls[[i]], cfg.duration_s)
    rec = rl.integrate(draws, fp, cfg.seed, np.array([i]), cfg.duration_s, cfg.sim_dt_s)
    return cfg, i, draws[0], fp, rec


@pytest.mark.slow
def test_logged_vibration_channels_follow_each_autopilots_filter_chain():
    cfg, i, draw, fp, rec = _propeller_flight()
    t_rec = np.arange(rec.x.shape[0]) / P.RECORD_HZ
    s = rf.physical_severity(fp, t_rec)[:, 0]  # (n_rec,)
    full = np.flatnonzero(s >= 0.999 * s.max())
    assert s.max() > 0.3 and len(full) > 3 * P.RECORD_HZ, "the flight's cut must settle for 3 s"
    k0, k1 = full[-1] - int(2.5 * P.RECORD_HZ), full[-1]  # the last 2.5 s at the final cut
    cut = propeller.cut_of_severity(s[k0:k1] * fp.kind[0, 4])[:, None] * fp.onehot[0]
    F = rec.x[k0:k1, 0, 17:21].astype(np.float64)
    A, f = propeller.accel_amplitude(F, propeller.thrust_factor(cut), propeller.imbalance_kgm(cut, draw["imbalance_g"]),
                                     rec.mass[k0:k1, 0, None])
    load = np.clip(F.mean(-1) / (rec.mass[k0:k1, 0] * P.NOMINAL.g / 4.0), 0.0, None)
    floor = float(draw["vib_floor"] * load.mean())
    rng = np.random.default_rng(0)
    accel = propeller.synthesise(A.mean(0), f.mean(0), floor, 6.0, rng)  # the stretch's mean rotor state
    px4_chain = propeller.px4_metric_time_domain(accel)[-400:].mean()
    vibe = propeller.ap_vibe_time_domain(accel)[-3000:]
    ap_chain = float(((vibe[:, 0] + vibe[:, 1]) / 2.0).mean())  # ingest's vib_ap from VibeX, VibeY

    ds = realistic.generate(cfg, [i])
    names = [str(n) for n in ds["channel_names"]]
    t = ds["time"]
    sel = (t >= t_rec[k0] + 1.0) & (t <= t_rec[k1 - 1])  # past the metrics' own lag
    logged_px4 = float(ds["telemetry"][0, sel, names.index("vib_px4")].mean())
    logged_ap = float(ds["telemetry"][0, sel, names.index("vib_ap")].mean())
    # closed forms' stated error (sim.propeller: RMS for mean norm, <= 12 % on pure noise) plus the
    # logged samples' scatter (VIB_REL_NOISE per sample, a handful of samples at 1 Hz for PX4)
    assert logged_px4 == pytest.approx(px4_chain, rel=0.13 + 2 * P.VIB_REL_NOISE)
    assert logged_ap == pytest.approx(ap_chain, rel=0.06 + P.VIB_REL_NOISE)
    rotor_share = float((A.mean(0) ** 2).sum() / 2.0) / ap_chain**2
    assert rotor_share > 0.2, "the cut's rotor term must carry the check, not the floor alone"
