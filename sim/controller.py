"""Cascaded multirotor flight controller (PX4-style structure), vectorised over a batch.

    position PD + altitude integral -> desired acceleration (+ reference feed-forward)
    -> thrust vector (tilt-limited) -> collective thrust (projected on the current body z, as
       PX4 does) and desired roll/pitch for the reference yaw
    -> attitude P on Euler errors, mapped to body-rate setpoints with E(eta)^-1
    -> body-rate PI -> torques J alpha -> Eq. (3) mixer with yaw-first desaturation
    -> F_cmd clipped to [0, F_max].

It runs at every internal step (200 Hz) and its output is held over the step (zero-order hold).
It sees the true state (perfect state estimation): Eq. (9)'s noise and bias model the logged
telemetry, not the estimator. Its integrators are what make faults visible the way they are on a
real vehicle: the altitude integrator raises the collective when thrust is lost (battery sag,
derating), the rate integrators re-balance the rotors when one of them loses effectiveness, so
the faulty motor's command (throttle channel) rises.

Controller state (``CtrlState``): i_z (batch,) [m/s^2], i_rate (batch, 3) [rad/s^2].
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from quadfdi.sim.params import VehicleParams

_EPS = 1e-9


class CtrlState(NamedTuple):
    i_z: np.ndarray  # (batch,) m/s^2, altitude integrator (output units)
    i_rate: np.ndarray  # (batch, 3) rad/s^2, body-rate integrators (output units)


def init_state(kappa0: np.ndarray, vp: VehicleParams) -> CtrlState:
    """Integrators of a vehicle already in trimmed hover at t = 0 (the flight started earlier):
    the altitude integrator holds the hover-thrust correction g (1/kappa_V - 1) that the bus
    voltage calls for (zero with voltage compensation), the rate integrators are zero.
    kappa0: (batch,) voltage sensitivity at t = 0."""
    if vp.v_comp:
        i_z = np.zeros_like(kappa0)
    else:
        i_z = np.clip(vp.g * (1.0 / kappa0 - 1.0), -vp.iz_max, vp.iz_max)
    return CtrlState(i_z=i_z, i_rate=np.zeros((kappa0.shape[0], 3)))


_GAINS: dict[int, tuple[VehicleParams, tuple[np.ndarray, ...]]] = {}


def _gains(vp: VehicleParams) -> tuple[np.ndarray, ...]:
    """Per-axis rate-loop gains and limits as arrays, built once per vehicle (not once per step;
    keyed by identity because hashing an 80-field dataclass would cost more than the build)."""
    hit = _GAINS.get(id(vp))
    if hit is None or hit[0] is not vp:
        k_p = np.array([vp.k_rate_rp, vp.k_rate_rp, vp.k_rate_yaw])  # 1/s
        k_i = np.array([vp.ki_rate_rp, vp.ki_rate_rp, vp.ki_rate_yaw])  # 1/s^2
        i_max = np.array([vp.irate_max_rp, vp.irate_max_rp, vp.irate_max_yaw])  # rad/s^2
        w_max = np.array([vp.rate_max_rp, vp.rate_max_rp, vp.rate_max_yaw])  # rad/s
        hit = (vp, (k_p, k_i, i_max, w_max, vp.J))
        _GAINS[id(vp)] = hit
    return hit[1]


def _clip(a: np.ndarray, lo: float | np.ndarray, hi: float | np.ndarray) -> np.ndarray:
    # np.clip costs ~4 us of dispatch per call on small arrays; min(max()) is the same numbers.
    return np.minimum(np.maximum(a, lo), hi)


def command(
    x: np.ndarray, ref: tuple[np.ndarray, ...], cs: CtrlState, kappa: np.ndarray, vp: VehicleParams, dt: float
) -> tuple[np.ndarray, CtrlState]:
    """One controller update.

    x: (batch, >=12) state [p, v, eta, omega, ...]; ref: ``reference.evaluate`` output
    (p, v, a (batch, 3); psi, psi_dot (batch,)); cs: integrators; kappa: (batch,) voltage
    sensitivity (used only with ``vp.v_comp``); dt: controller period [s].
    Returns F_cmd (batch, 4) [N] in [0, F_max], and the new CtrlState.
    """
    T, tau, cs_new = thrust_torque(x, ref, cs, kappa, vp, dt)
    return mix_desaturate(T, tau, vp), cs_new


def thrust_torque(
    x: np.ndarray, ref: tuple[np.ndarray, ...], cs: CtrlState, kappa: np.ndarray, vp: VehicleParams, dt: float
) -> tuple[np.ndarray, np.ndarray, CtrlState]:
    """``command`` before the mixer: collective thrust T (batch,) [N], torques tau (batch, 3) [N m]
    and the new CtrlState (the realistic suite mixes them for its own frame, sim/realistic_control.py)."""
    p_ref, v_ref, a_ref, psi_ref, psi_dot_ref = ref
    g = vp.g
    e_p = p_ref - x[:, 0:3]  # (batch, 3)
    e_v = v_ref - x[:, 3:6]  # (batch, 3)

    # --- position loop: desired acceleration (z up) ---
    i_z = _clip(cs.i_z + (vp.ki_z * dt) * e_p[:, 2], -vp.iz_max, vp.iz_max)
    ax = a_ref[:, 0] + vp.kp_xy * e_p[:, 0] + vp.kd_xy * e_v[:, 0]
    ay = a_ref[:, 1] + vp.kp_xy * e_p[:, 1] + vp.kd_xy * e_v[:, 1]
    fz = np.maximum(a_ref[:, 2] + vp.kp_z * e_p[:, 2] + vp.kd_z * e_v[:, 2] + (i_z + g), 0.3 * g)
    # tilt limit: scale the horizontal part so that its angle to e3 stays <= tilt_max
    fh2 = ax * ax + ay * ay
    scale = np.minimum(1.0, (np.tan(vp.tilt_max) * fz) / np.sqrt(np.maximum(fh2, _EPS)))
    fx, fy = ax * scale, ay * scale

    # --- desired attitude from the thrust direction and the reference yaw (ZYX) ---
    cy, sy = np.cos(psi_ref), np.sin(psi_ref)
    fxb = cy * fx + sy * fy  # thrust vector in the yaw-rotated frame
    fyb = cy * fy - sy * fx
    fn = np.sqrt(fh2 * (scale * scale) + fz * fz)
    theta_d = np.arctan2(fxb, fz)
    phi_d = np.arcsin(-fyb / fn)

    # --- current attitude trig, collective thrust projected on the body z axis ---
    sn = np.sin(x[:, 6:9])
    cn = np.cos(x[:, 6:9])
    sp, st, ss = sn[:, 0], sn[:, 1], sn[:, 2]
    cp, ct, cs_ = cn[:, 0], cn[:, 1], cn[:, 2]
    cp_st = cp * st
    b3z = ct * cp
    T = vp.m * np.maximum(fx * (cs_ * cp_st + ss * sp) + fy * (ss * cp_st - cs_ * sp) + fz * b3z, 0.0)

    # --- attitude P on Euler errors -> Euler-rate setpoint -> body-rate setpoint (E^-1) ---
    d_psi = psi_ref - x[:, 8]
    e_psi = d_psi - (2.0 * np.pi) * np.rint(d_psi * (0.5 / np.pi))  # wrapped to [-pi, pi]
    dphi = vp.k_att_rp * (phi_d - x[:, 6])
    dtheta = vp.k_att_rp * (theta_d - x[:, 7])
    dpsi = vp.k_att_yaw * e_psi + psi_dot_ref
    w_d = np.empty((x.shape[0], 3))
    w_d[:, 0] = dphi - st * dpsi
    w_d[:, 1] = cp * dtheta + (sp * ct) * dpsi
    w_d[:, 2] = b3z * dpsi - sp * dtheta
    k_p, k_i, i_max, w_max, J = _gains(vp)
    w_d = _clip(w_d, -w_max, w_max)  # (batch, 3)

    # --- body-rate PI -> angular acceleration -> torque ---
    e_w = w_d - x[:, 9:12]
    i_rate = _clip(cs.i_rate + (k_i * dt) * e_w, -i_max, i_max)
    tau = J * (k_p * e_w + i_rate)  # (batch, 3) N m

    if vp.v_comp:  # PX4 MC_BAT_SCALE_EN: scale thrust and torques by 1 / kappa_V
        inv = 1.0 / kappa
        T = T * inv
        tau = tau * inv[:, None]
    return T, tau, CtrlState(i_z=i_z, i_rate=i_rate)


def mix_desaturate(T: np.ndarray, tau: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """Eq. (3) mixer with PX4-like priorities: roll/pitch first, then yaw, then collective.

    T (batch,) [N], tau (batch, 3) [N m] -> F_cmd (batch, 4) [N] in [0, F_max].
    1. the yaw part is scaled by the largest alpha in [0, 1] that keeps every rotor in range;
    2. the collective is shifted down (or up) so the largest (smallest) rotor fits;
    3. anything still outside [0, F_max] is clipped.
    """
    Fmax = vp.F_max
    base = 0.25 * T
    r = tau[:, 0] * (0.5 / vp.L)
    p = tau[:, 1] * (0.5 / vp.L)
    y = _clip(tau[:, 2], -vp.tau_yaw_max, vp.tau_yaw_max) * (0.25 / vp.gamma)
    F1, F2, F3, F4 = base - p, base + r, base + p, base - r  # roll/pitch part, (batch,) each
    # yaw adds +y to rotors 1, 3 and -y to rotors 2, 4: room left in the direction it pushes
    hi13, lo13 = np.maximum(F1, F3), np.minimum(F1, F3)
    hi24, lo24 = np.maximum(F2, F4), np.minimum(F2, F4)
    room = np.where(y >= 0.0, np.minimum(Fmax - hi13, lo24), np.minimum(lo13, Fmax - hi24))
    y = y * _clip(room / np.maximum(np.abs(y), _EPS), 0.0, 1.0)
    # after the yaw part: largest and smallest rotor, then shift the collective to fit
    hi = np.maximum(hi13 + y, hi24 - y)
    lo = np.minimum(lo13 + y, lo24 - y)
    shift = np.maximum(hi - Fmax, 0.0) - np.maximum(-lo, 0.0)
    F = np.empty((T.shape[0], 4))
    F[:, 0] = F1 + y
    F[:, 1] = F2 - y
    F[:, 2] = F3 + y
    F[:, 3] = F4 - y
    return _clip(F - shift[:, None], 0.0, Fmax)
