"""Realistic suite, unit level: every variability draw in its range, the Dryden spectrum, propeller
loss and vibration against cut size, the coulomb counter, the mixer and the thrust curve."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.signal import welch

from quadfdi.sim.config import SimConfig
from quadfdi.sim import mission, propeller, realistic_loop, telemetry, wind
from quadfdi.sim import realistic_dynamics as rd
from quadfdi.sim import realistic_params as P
from quadfdi.sim.variability import OOD_INCIPIENT, OOD_MISSION, OOD_VEHICLE, OOD_WIND, draw_flight

CFG = dataclasses.replace(SimConfig(), scenario="realistic", duration_s=75.0, onset_frac=(0.1, 0.5),
                          ramp_frac=(0.1, 0.3),
                          classes=("Healthy", "BatteryFault", "MotorFault", "OverheatFault", "PropellerFault"))


@pytest.fixture(scope="module")
def draws():
    return [draw_flight(CFG, i, 0) for i in range(300)]


def _arr(draws, key):
    return np.array([d[key] for d in draws])


def test_vehicle_draws_within_their_ranges(draws):
    m = _arr(draws, "mass")
    assert m.min() >= P.MASS_KG[0] and m.max() <= P.MASS_KG[1] and np.ptp(m) > 0.9 * np.ptp(P.MASS_KG)
    total = m + _arr(draws, "payload_kg")
    assert total.min() >= P.MASS_KG[0] - 1e-12 and total.max() <= P.MASS_KG[1] + 1e-12
    share = np.mean(_arr(draws, "payload_kg") != 0)
    assert 0.2 < share < 0.4  # PAYLOAD_P = 0.3
    cg = _arr(draws, "cg")
    assert np.abs(cg).max() <= P.CG_OFFSET_M and np.abs(cg).max() > 0.9 * P.CG_OFFSET_M
    for key, spread in (("kf", P.KF_SPREAD), ("cool", P.COOL_SPREAD)):
        dev = np.abs(_arr(draws, key) - 1.0)
        assert dev.max() <= spread and dev.max() > 0.9 * spread
    assert set(_arr(draws, "cells")) == set(P.CELLS) and set(_arr(draws, "frame")) == {0, 1}
    share = _arr(draws, "capacity") * 3.7 * _arr(draws, "cells") / (m * P.PACK_WH_PER_KG)
    assert share.min() >= P.PACK_MASS_SHARE[0] - 1e-12 and share.max() <= P.PACK_MASS_SHARE[1] + 1e-12
    for key, (lo, hi) in (("thrust_to_weight", P.THRUST_TO_WEIGHT), ("age", P.AGE), ("t_amb", P.T_AMB_C), ("soc0", P.SOC_BOOT),
                          ("motor_tau", P.MOTOR_TAU_S), ("vib_floor", P.VIB_FLOOR), ("wind_ms", P.WIND_MS),
                          ("flap", P.FLAP_PER_MS)):
        v = _arr(draws, key)
        assert v.min() >= lo and v.max() <= hi and np.ptp(v) > 0.9 * (hi - lo), key
    tw, lim = _arr(draws, "twist"), np.radians(P.MOUNT_TWIST_DEG)  # (300, 4), per rotor, independent
    assert tw.shape == (300, 4) and np.abs(tw).max() <= lim and np.ptp(tw, axis=0).min() > 1.8 * lim
    assert abs(np.corrcoef(tw[:, 0], tw[:, 2])[0, 1]) < 0.2
    assert set(_arr(draws, "motor")) == {0, 1, 2, 3}
    s = _arr(draws, "s_max")
    assert s.min() >= CFG.severity_max[0] and s.max() <= CFG.severity_max[1]
    assert {int(d["mission"]["kind"]) for d in draws} == {0, 1, 2}


def test_out_of_distribution_groups_change_only_their_factor():
    base = draw_flight(CFG, 7, 0)
    for g in (OOD_MISSION, OOD_VEHICLE, OOD_WIND, OOD_INCIPIENT):
        d = draw_flight(CFG, 7, g)
        assert d["mass"] == base["mass"] and np.array_equal(d["kf"], base["kf"]) and d["t_amb"] == base["t_amb"]
    assert int(draw_flight(CFG, 7, OOD_MISSION)["mission"]["kind"]) == 3
    v = draw_flight(CFG, 7, OOD_VEHICLE)
    assert (v["frame"], v["cells"], v["arm"]) == (1, P.OOD_CELLS, P.OOD_ARM_M)
    winds = [draw_flight(CFG, i, OOD_WIND)["wind_ms"] for i in range(50)]
    assert min(winds) >= P.OOD_WIND_MS[0] and max(winds) <= P.OOD_WIND_MS[1]
    sev = [draw_flight(CFG, i, OOD_INCIPIENT)["s_max"] for i in range(50)]
    assert min(sev) >= P.INCIPIENT_SMAX[0] and max(sev) < CFG.severity_max[0]


def test_dryden_turbulence_has_the_dryden_spectrum():
    dt = 0.02
    dr = wind.dryden(np.array([3.0, 8.0]), dt)
    rng = np.random.default_rng(0)
    n = 2**17
    noise = rng.standard_normal((n, 2, 3))
    z, out = np.zeros((2, 5)), np.empty((n, 2, 3))
    for k in range(n):
        z, out[k] = wind.turbulence_step(z, noise[k], dr, dt)
    f, Pxx = welch(out, fs=1.0 / dt, axis=0, nperseg=2**12)
    sel = (f > 0.05) & (f < 5.0)
    ratio = (Pxx[sel] / (2 * np.pi)).transpose(1, 0, 2) / wind.psd(dr, 2 * np.pi * f[sel])
    # Welch, 64 segments of 82 s: each bin's ratio scatters ~18 %; band medians must sit at 1
    for band in ((0.05, 0.5), (0.5, 5.0)):
        b = (f[sel] >= band[0]) & (f[sel] < band[1])
        med = np.median(ratio[:, b], axis=1)
        assert np.all(np.abs(med - 1.0) < 0.1), (band, med)
    # the airspeed floor: calm air still has a finite time constant
    assert np.all(np.isfinite(wind.dryden(np.array([0.0]), dt).tau))
    assert wind.dryden(np.array([0.0]), dt).tau[0, 0] == pytest.approx(wind.dryden(np.array([P.WIND_V_FLOOR]), dt).tau[0, 0])


def test_propeller_thrust_and_torque_loss_against_cut():
    cut = np.linspace(0.0, 0.3, 7)
    rT, rQ = propeller.thrust_factor(cut), propeller.torque_factor(cut)
    assert rT[0] == 1.0 and rQ[0] == 1.0
    assert np.all(np.diff(rT) < 0) and np.all(rQ[1:] < rT[1:])  # torque goes faster than thrust
    # blade-element integral, numerically: dT ~ r^2 dr, dQ ~ r^3 dr over the cut blade, plus the whole one
    r = np.linspace(0, 1, 200001)
    for l in (0.1, 0.3):
        keep = r <= 1 - l
        num_T = (np.trapezoid(r**2 * keep, r) + np.trapezoid(r**2, r)) / (2 * np.trapezoid(r**2, r))
        num_Q = (np.trapezoid(r**3 * keep, r) + np.trapezoid(r**3, r)) / (2 * np.trapezoid(r**3, r))
        assert propeller.thrust_factor(l) == pytest.approx(num_T, abs=1e-4)
        assert propeller.torque_factor(l) == pytest.approx(num_Q, abs=1e-4)
    assert propeller.thrust_factor(P.CUT_MAX) == pytest.approx(0.6715, abs=1e-4)


def test_vibration_metrics_grow_with_cut_and_match_both_algorithms():
    rng = np.random.default_rng(1)
    prev = (0.0, 0.0)
    for cut in (0.0, 0.05, 0.1, 0.2, 0.3):
        F = np.full(4, 3.7)
        cuts = np.array([cut, 0, 0, 0])
        A, f = propeller.accel_amplitude(F, propeller.thrust_factor(cuts), propeller.imbalance_kgm(cuts, np.full(4, 0.02)),
                                         np.array(1.5))
        px4, ap = propeller.metrics(A, f, 2.0)
        assert px4 > prev[0] and ap >= prev[1]
        prev = (px4, ap)
        a = propeller.synthesise(A, f, 2.0, 6.0, rng)
        px4_t = propeller.px4_metric_time_domain(a)[-400:].mean()
        ap_t = propeller.ap_vibe_time_domain(a)[-3000:, :2].mean()
        assert px4 == pytest.approx(px4_t, rel=0.13)  # RMS-for-mean-norm: <= 12 % high on pure noise
        assert ap == pytest.approx(ap_t, rel=0.06)
    assert prev[0] > 3 * 2.0 and prev[1] > 2.5 * 2.0  # a 30 % cut stands far above a 2 m/s^2 floor
    # different quantities: PX4's metric is blind at the integration rate, VIBE is not
    A = np.array([5.0, 0, 0, 0])
    assert propeller.metrics(A, np.full(4, P.IMU_INTEG_HZ), 0.0)[0] == pytest.approx(0.0, abs=1e-9)
    assert propeller.metrics(A, np.full(4, P.IMU_INTEG_HZ), 0.0)[1] == pytest.approx(5 / np.sqrt(2))


def test_coulomb_counter_ignores_capacity_fade():
    n, dt = 500, 0.02
    I = np.full((n, 2), 20.0)
    E = np.array([11.5, 11.5])
    soc = telemetry.coulomb_soc(I, E, np.array([3.0, 3.0]), np.array([5.0, 5.0]), dt)
    assert np.array_equal(soc[:, 0], soc[:, 1])  # same current, same label capacity: same count
    assert soc[0, 0] == pytest.approx(telemetry.soc_inverse(np.array(E[0] / 3.0)))
    assert soc[0, 0] - soc[-1, 0] == pytest.approx(20.0 * (n - 1) * dt / 3600 / 5.0)
    # the true SoC of a faded pack (capacity 3 Ah of a 5 Ah label) falls 5/3 as fast as the count
    veh_c = np.array([5.0, 3.0])
    true_drop = 20.0 * (n - 1) * dt / (3600 * veh_c)
    assert true_drop[1] / true_drop[0] == pytest.approx(5.0 / 3.0)


def test_mixer_inverts_the_moments_of_both_frames():
    B = 2
    frame, arm = np.array([0.0, 1.0]), np.array([0.225, 0.225])
    rx, ry = rd.rotor_positions(frame, arm)
    veh = rd.Vehicle(*(np.zeros(B) for _ in range(3)), np.ones((B, 3)), rx, ry, np.zeros((B, 2)), np.zeros(B),
                     np.zeros((B, 4)), *(np.ones((B, 4)) for _ in range(3)), np.full(B, 3.0), *(np.ones(B) for _ in range(3)),
                     np.zeros((B, 1)))
    T, tau = np.array([15.0, 15.0]), np.array([[0.1, -0.05, 0.02], [0.1, -0.05, 0.02]])
    F = rd.mix(T, tau, veh)
    assert np.allclose(F.sum(1), T)
    assert np.allclose((F * ry).sum(1), tau[:, 0]) and np.allclose(-(F * rx).sum(1), tau[:, 1])
    assert np.allclose(rd.NOM.gamma * (F * rd.SPIN).sum(1), tau[:, 2])
    # the plus frame is the paper's geometry
    assert np.allclose(rx[0], [0.225, 0, -0.225, 0], atol=1e-12) and np.allclose(ry[0], [0, 0.225, 0, -0.225], atol=1e-12)


def test_forward_flight_moment_lifts_the_leading_side():
    """sim/realistic_dynamics.py: M = -D T (e_z x v_air) in the body frame. Level flight forward (+x)
    pitches the nose up (My < 0 in FLU), flight to the left (+y) rolls the left side up (Mx > 0); a
    90 deg yaw turns a world-frame +y airspeed into body +x; the moment scales with D, T and the
    airspeed and vanishes in still air; with D = 0 the rotor moments are untouched."""
    B = 4
    frame, arm = np.ones(B), np.full(B, 0.225)
    rx, ry = rd.rotor_positions(frame, arm)
    D = np.array([0.002, 0.002, 0.004, 0.0])
    veh = rd.Vehicle(np.full(B, 1.5), np.zeros(B), np.full(B, np.inf), np.ones((B, 3)), rx, ry, np.zeros((B, 2)), D,
                     np.zeros((B, 4)), *(np.ones((B, 4)) for _ in range(3)), np.full(B, 3.0), *(np.ones(B) for _ in range(3)),
                     np.full((B, 1), 20.0))
    x = np.zeros((B, rd.N_X))
    x[:, 12], x[:, 13:17], x[:, 17:21] = 0.8, 20.0, 4.0  # SoC, motor temperatures, 16 N of equal thrusts
    x[0, 3] = 5.0  # 5 m/s forward
    x[1, 4] = 5.0  # 5 m/s to the left
    x[2, 3], x[2, 8] = 0.0, np.pi / 2  # heading +y ...
    x[2, 4] = 5.0  # ... flying along it: body +x airspeed
    x[3, 3] = 5.0  # D = 0
    u = rd.held_inputs(np.full((B, 4), 0.5), np.ones(B), np.zeros(B), np.zeros(B), _no_fault(B), veh,
                       np.zeros((B, 3)), 0.0)
    dx, _ = rd.deriv(x, u, veh)
    J = veh.J
    Mx, My = dx[:, 9] * J[:, 0], dx[:, 10] * J[:, 1]  # p = q = r = 0: J omega_dot = M
    T = 16.0
    assert np.allclose(My[0], -0.002 * T * 5.0) and abs(Mx[0]) < 1e-12
    assert np.allclose(Mx[1], 0.002 * T * 5.0) and abs(My[1]) < 1e-12
    assert np.allclose(My[2], -0.004 * T * 5.0) and abs(Mx[2]) < 1e-12
    assert abs(Mx[3]) < 1e-12 and abs(My[3]) < 1e-12
    # the same airspeed from wind alone (vehicle still, wind blowing backwards): the same moment
    u_w = u._replace(wind=np.array([[-5.0, 0, 0]] * B))
    x_w = x.copy()
    x_w[0, 3] = 0.0
    assert np.allclose(rd.deriv(x_w, u_w, veh)[0][0, 10] * J[0, 1], My[0])


def test_mount_twist_yaws_the_vehicle_and_the_trim_cancels_it():
    """A mount twisted by delta about its arm adds F arm delta of yaw moment (sim/realistic_dynamics.py),
    one rotor at a time, in proportion to its thrust; draws do it per rotor (variability: the AERO
    stream after flap, so flap keeps its value); the initial yaw integrator holds the trim."""
    B = 3
    frame, arm = np.ones(B), np.full(B, 0.225)
    rx, ry = rd.rotor_positions(frame, arm)
    twist = arm[:, None] * np.radians(np.array([[0.5, 0, 0, 0], [0.5, 0.5, 0.5, 0.5], [0.0, 0.0, 0.0, 0.0]]))
    veh = rd.Vehicle(np.full(B, 1.5), np.zeros(B), np.full(B, np.inf), np.ones((B, 3)), rx, ry, np.zeros((B, 2)),
                     np.zeros(B), twist, *(np.ones((B, 4)) for _ in range(3)), np.full(B, 3.0),
                     *(np.ones(B) for _ in range(3)), np.full((B, 1), 20.0))
    x = np.zeros((B, rd.N_X))
    x[:, 12], x[:, 13:17], x[:, 17:21] = 0.8, 20.0, 4.0
    u = rd.held_inputs(np.full((B, 4), 0.5), np.ones(B), np.zeros(B), np.zeros(B), _no_fault(B), veh,
                       np.zeros((B, 3)), 0.0)
    Mz = rd.deriv(x, u, veh)[0][:, 11] * veh.J[:, 2]
    one = 4.0 * 0.225 * np.radians(0.5)
    assert Mz[0] == pytest.approx(one, rel=1e-12) and Mz[1] == pytest.approx(4 * one, rel=1e-12)
    assert abs(Mz[2]) < 1e-12  # equal thrusts, no twist: the rotors' drag torques cancel
    # the draw: the AERO stream's first number is still flap
    d = draw_flight(CFG, 3, 0)
    aero = np.random.default_rng(np.random.SeedSequence(CFG.seed, spawn_key=(7, 3)))
    assert d["flap"] == aero.uniform(*P.FLAP_PER_MS) and np.array_equal(d["twist"], aero.uniform(-1, 1, 4) * np.radians(P.MOUNT_TWIST_DEG))
    # the trimmed start: the controller's yaw integrator (nominal Jzz) holds minus the twists' moment at hover
    draws = [dict(draw_flight(CFG, i, 0), frame=1.0, cg=np.zeros(2)) for i in range(4)]
    v = rd.vehicle(draws)
    _, cs = realistic_loop.initial(draws, v, mission.prepare([d["mission"] for d in draws]))
    W = v.m0 * rd.NOM.g
    assert np.allclose(cs.i_rate[:, 2] * rd.NOM.Jzz, -(W / 4.0) * v.twist.sum(axis=1))
    assert np.all(v.twist != 0.0)


def _no_fault(B: int):
    """A healthy batch's FaultPlan: kind one-hot on healthy, nothing else."""
    from quadfdi.sim.realistic_faults import FaultPlan

    kind = np.zeros((B, 5))
    kind[:, 0] = 1.0
    z = np.zeros(B)
    return FaultPlan(kind, np.zeros((B, 4)), z.astype(int), np.zeros((B, 3)), z, z, z, np.full((B, 1), np.inf),
                     np.zeros((B, 1)), z)


def test_thrust_curve_inverse():
    f = np.linspace(0, 1, 11)
    u = rd.motor_output(f * rd.NOM.F_max)
    k = P.THR_MDL_FAC
    assert np.allclose((1 - k) * u + k * u * u, f) and u[-1] == pytest.approx(1.0)
    # the log holds the thrust fraction (docs/flight_format.md), not u: the curve of u, as the rotors get it
    assert np.allclose(rd.thrust_fraction(u), f) and not np.allclose(u[1:-1], f[1:-1], atol=0.01)


def test_intermittent_events_and_their_labels():
    from quadfdi.sim import realistic_faults as rf

    draws = [draw_flight(CFG, i, 0) for i in range(40)]
    cls = np.array([1, 2] * 20)  # battery (connector spikes) and motor (ESC desync)
    for d in draws:
        d["mode_u"] = 0.99  # the intermittent mode of both classes
    fp = rf.plan(draws, CFG.classes, cls, CFG.duration_s)
    assert np.all(fp.mode == rf.INTERMITTENT)
    dt = 0.01
    n = int(CFG.duration_s / dt)
    ev = rf.event_mask(fp, n, dt)
    t = np.arange(n + 1) * dt
    for b in range(40):
        on = ev[:, b].astype(int)
        starts, ends = np.flatnonzero(np.diff(on) == 1) + 1, np.flatnonzero(np.diff(on) == -1) + 1
        assert len(starts) > 0 and t[starts[0]] >= fp.onset[b] - dt
        lo, hi = (P.CONN_SPIKE_S if cls[b] == 1 else P.DESYNC_S)
        lengths = (ends[: len(starts)] - starts[: len(ends)]) * dt
        single = lengths[lengths < hi]  # overlapping events merge into longer ones
        assert np.all(single >= lo - 2 * dt)
    sev = rf.label_severity(fp, t)
    assert np.all(sev[t < fp.onset.min() - 1e-9] == 0)
    after = t[:, None] >= fp.onset[None, :]
    assert np.allclose(sev[after], np.broadcast_to(fp.s_max, sev.shape)[after])  # faulty between spikes too
    assert np.all(rf.physical_severity(fp, t) == 0.0)  # they act through the events only


def test_takeoff_faults_are_present_from_the_first_sample():
    from quadfdi.sim import realistic_faults as rf

    draws = [draw_flight(CFG, i, 0) for i in range(10)]
    for d in draws:
        d["mode_u"] = 0.6  # battery: takeoff (0.5..0.8); propeller: takeoff (0.5..1.0)
    cls = np.array([1, 4] * 5)
    fp = rf.plan(draws, CFG.classes, cls, CFG.duration_s)
    assert np.all(fp.mode == rf.TAKEOFF)
    assert np.allclose(rf.label_severity(fp, np.array([0.0]))[0], fp.s_max)


def test_paper_scenario_keeps_the_paper_classes():
    from quadfdi.core.config import load_config
    from quadfdi.core.errors import QuadfdiError

    with pytest.raises(QuadfdiError, match="scenario"):
        load_config(None, ['sim.classes=["Healthy", "PropellerFault"]'])
    with pytest.raises(QuadfdiError, match="sim.classes"):
        load_config(None, ["sim.scenario=realistic", 'sim.classes=["BatteryFault", "Healthy"]'])
