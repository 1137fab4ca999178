"""The closed loop of the realistic suite, one batch: wind, state estimate, controller, physics, record.

Per 5 ms step (sim.sim_dt_s): Dryden turbulence + gusts + mean wind; the state estimate
x_hat = x + e with first-order Gauss-Markov errors e (sim.realistic_params EST_*), which is what
the controller flies on (PX4's EKF2 output, not the truth); the nominal cascaded controller
(sim.controller.thrust_torque with realistic_params.NOMINAL) and the flight's own mixer; the motor
outputs u through the nominal thrust-curve inverse; then one RK4 step of sim.realistic_dynamics.

The in-flight noise (turbulence and estimate errors, 15 standard normals per step) comes from
each flight's own stream (sim.variability.noise_rng), drawn in blocks of BLOCK steps: a flight's
numbers never depend on its batch. Everything is recorded every RECORD_EVERY steps (50 Hz).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from quadfdi.core.rk4 import rk4_step
from quadfdi.sim import controller, mission, wind
from quadfdi.sim import realistic_dynamics as rd
from quadfdi.sim import realistic_faults as rf
from quadfdi.sim import realistic_params as P
from quadfdi.sim.controller import CtrlState
from quadfdi.sim.variability import noise_rng, stack

BLOCK = 128
N_NOISE = 15  # 3 turbulence inputs + 12 estimate-error inputs per step
EST = (P.EST_POS_XY, P.EST_POS_XY, P.EST_POS_Z, P.EST_VEL, P.EST_VEL, P.EST_VEL, P.EST_TILT, P.EST_TILT,
       P.EST_YAW, P.EST_RATE, P.EST_RATE, P.EST_RATE)


class Record(NamedTuple):
    """50 Hz record, time-major (n_rec, B, k) float32 (limited: (B,) int64)."""

    x: np.ndarray  # (n_rec, B, 21) true state
    est: np.ndarray  # (n_rec, B, 12) the estimate the controller used (what the FC logs)
    V: np.ndarray  # (n_rec, B)
    I: np.ndarray  # (n_rec, B)
    thr: np.ndarray  # (n_rec, B, 4) thrust fractions F_cmd / F_max (rd.thrust_fraction of the ESC outputs u)
    mass: np.ndarray  # (n_rec, B)
    limited: np.ndarray  # (B,) steps at the pack's maximum-power clamp


def record_every(dt: float) -> int:
    return int(round(1.0 / (P.RECORD_HZ * dt)))


def n_steps(duration: float, dt: float) -> int:
    """Internal steps: the flight plus MARGIN_S, a whole number of record intervals."""
    k = record_every(dt)
    return int(np.ceil((duration + P.MARGIN_S) / (dt * k))) * k


def initial(draws: list[dict], veh: rd.Vehicle, m: dict) -> tuple[np.ndarray, CtrlState]:
    """Trimmed hover at the mission start, integrators converged (the flight began at take-off)."""
    B = len(draws)
    p, _, _, psi, _ = mission.evaluate(m, np.zeros(1))
    x = np.zeros((B, rd.N_X))
    x[:, 0:3] = p[0]
    x[:, 8] = psi[0]
    x[:, 12] = stack(draws, ("soc0",))["soc0"]
    x[:, 13:17] = veh.T_amb + 8.0  # motors warmed by the climb to mission altitude
    W = veh.m0 * rd.NOM.g
    x[:, 17:21] = (W / 4.0)[:, None]
    # the nominal controller commands m_nom (g + i_z) of thrust, which the build turns into that times
    # F_max / F_max_nom: trimmed when m0 g = (F_max / F_max_nom) m_nom (g + i_z)
    gain = veh.fmax.mean(axis=1) / rd.NOM.F_max * (rd.NOM.m / veh.m0)
    i_z = np.clip(rd.NOM.g * (1.0 / gain - 1.0), -rd.NOM.iz_max, rd.NOM.iz_max)
    yaw_trim = -(W / 4.0) * veh.twist.sum(axis=1) / rd.NOM.Jzz  # the twisted mounts' yaw moment, cancelled
    i_rate = np.stack([veh.cg[:, 1] * W / rd.NOM.Jxx, -veh.cg[:, 0] * W / rd.NOM.Jyy, yaw_trim], -1) / veh.ctrl
    i_max = np.array([rd.NOM.irate_max_rp, rd.NOM.irate_max_rp, rd.NOM.irate_max_yaw])
    i_rate = np.clip(i_rate, -i_max, i_max)
    return x, CtrlState(i_z=i_z, i_rate=i_rate)


def _est_coeffs(dt: float) -> tuple[np.ndarray, np.ndarray]:
    sig = np.array([s for s, _ in EST])
    phi = np.exp(-dt / np.array([tau for _, tau in EST]))
    return phi, sig * np.sqrt(1.0 - phi * phi)


class _Exo(NamedTuple):
    ref: tuple
    gust: np.ndarray
    noise: np.ndarray
    s_phys: np.ndarray


def _block(n: int, dt: float, m: dict, wd: dict, gens: list, fp: rf.FaultPlan, total: int) -> _Exo:
    t = (n + np.arange(min(BLOCK, total + 1 - n))) * dt
    noise = np.stack([g.standard_normal((len(t), N_NOISE)) for g in gens], axis=1)
    return _Exo(mission.evaluate(m, t), wind.gusts(t, wd["gust_t"], wd["gust_T"], wd["gust_A"], wd["gust_dir"]),
                noise, rf.physical_severity(fp, t))


def integrate(draws: list[dict], fp: rf.FaultPlan, seed: int, idx: np.ndarray, duration: float,
              dt: float) -> Record:
    """Fly one batch (flights ``idx``) for ``duration`` + margin; the 50 Hz record."""
    veh = rd.vehicle(draws)
    m = mission.prepare([d["mission"] for d in draws])
    wd = stack(draws, ("wind_ms", "wind_dir", "gust_t", "gust_T", "gust_A", "gust_dir"))
    dr = wind.dryden(wd["wind_ms"], dt)
    w_mean = np.stack([np.cos(wd["wind_dir"]), np.sin(wd["wind_dir"]), np.zeros(len(draws))], -1) \
        * wd["wind_ms"][:, None]
    gens = [noise_rng(seed, int(i)) for i in idx]
    total = n_steps(duration, dt)
    every = record_every(dt)
    ev = rf.event_mask(fp, total, dt).astype(np.float64)
    phi_e, q_e = _est_coeffs(dt)
    x, cs = initial(draws, veh, m)
    B, n_rec = len(draws), total // every + 1
    rec = Record(np.empty((n_rec, B, rd.N_X), np.float32), np.empty((n_rec, B, 12), np.float32),
                 np.empty((n_rec, B), np.float32), np.empty((n_rec, B), np.float32),
                 np.empty((n_rec, B, 4), np.float32), np.empty((n_rec, B), np.float32), np.zeros(B, np.int64))
    zt, e = np.zeros((B, 5)), np.zeros((B, 12))
    V_prev = rd.terminal(x[:, 12], np.full(B, 160.0), veh, veh.R, np.zeros(B))[0]
    ones = np.ones(B)
    for n in range(total + 1):
        j = n % BLOCK
        if j == 0:
            exo = _block(n, dt, m, wd, gens, fp, total)
        t = n * dt
        zt, turb = wind.turbulence_step(zt, exo.noise[j, :, 0:3], dr, dt)
        w = w_mean + wind.to_inertial(turb, wd["wind_dir"]) + exo.gust[j]
        e = wind.markov_step(e, exo.noise[j, :, 3:], phi_e, q_e)
        xh = x[:, :12] + e
        r = tuple(a[j] for a in exo.ref)
        T, tau, cs = controller.thrust_torque(xh, r, cs, ones, rd.NOM, dt)
        thr = rd.motor_output(rd.mix(T, tau * veh.ctrl, veh))  # ctrl: the airframe class's tuning
        u = rd.held_inputs(thr, rd.kappa_v(V_prev, veh), exo.s_phys[j], ev[n], fp, veh, w, t)
        k1, (V_prev, I, lim, _) = rd.deriv(x, u, veh)
        rec.limited[:] += lim
        if n % every == 0:
            k = n // every
            rec.x[k], rec.est[k], rec.V[k], rec.I[k], rec.mass[k] = x, xh, V_prev, I, u.phys.m
            rec.thr[k] = rd.thrust_fraction(thr)  # the log's thrust fraction, as a flight controller's
        if n == total:
            break
        x = rk4_step(lambda ts, xs: rd.deriv(xs, u, veh)[0], t, x, dt, k1)
    return rec
