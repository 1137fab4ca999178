"""Physics of the realistic suite: per-flight vehicle truth, motor lag, wind, shunt-visible battery.

Integrated state (batch, 21): p, v, eta, omega (0:12), SoC (12), T_m (13:17), rotor thrusts F (17:21).
Per evaluation, with the motor outputs u held over the 5 ms step (zero-order hold):

  F_tgt,i = F_max kf_i c_i rho_T,i kappa_V d_i curve(u_i)     thrust the rotor settles to
  dF_i/dt = (F_tgt,i - F_i) / tau_m,i                        motor + ESC lag, 20-40 ms
  d_i     = max(1 - lambda_T max(T_i - T_der, 0), d_min)      derating by temperature only
  P       = sum_i c_P (rho_Q / rho_T^1.5)_i F_i^1.5 + P_av    power at the thrust actually produced
  E       = n_s V_cell(SoC) - (V_cell(SoC) - V_cell(SoC - delta))   one weak cell (imbalance)
  V_b     = (E + sqrt(E^2 - 4 R P)) / 2,  I_b = (E - V_b) / R  the shunt sees all of I_b (no hidden k_I)
  dSoC/dt = -I_b / (3600 C_true)                              true capacity: age and fade
  thermal: Eq. 5 with h_i = h_nom cool_i (1 - a_h s_h), driven by the produced F_i
  rigid body: Eq. 2 with the flight's m(t) (payload step), J, and moments about the shifted CG
              Mx = sum F_i (y_i - c_y), My = -sum F_i (x_i - c_x), Mz = gamma sum s_i (rho_Q/rho_T)_i F_i;
              drag on the airspeed: -k_L (v - w)
              forward-flight rotor moment (blade flapping, wake on the trailing rotors) about the
              body axes: Mx += D T v_air,y,  My -= D T v_air,x  (v_air in the body frame, T = sum F_i)
              motor mount twist delta_i (about the arm): Mz += sum F_i arm delta_i (small angle; the
              discs' sideways force, < 1.3 % of thrust and nearly cancelling around the frame, left out)

The paper's equations (sim/dynamics.py) stay as published for ``scenario = "paper"``; the differences
are listed in docs/realistic.md. Elementwise numpy over the batch, as there.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import NamedTuple

import numpy as np

from quadfdi.sim import battery, faults, propeller, rigid_body, thermal
from quadfdi.sim import realistic_params as P
from quadfdi.sim.realistic_faults import FaultPlan
from quadfdi.sim.variability import stack

NOM = P.NOMINAL
N_X = 21
SPIN = np.array([1.0, -1.0, 1.0, -1.0])  # rotors 1, 3 one way, 2, 4 the other (paper Eq. 3)


class Vehicle(NamedTuple):
    """Per-flight truth, (B,) or (B, k) float64."""

    m0: np.ndarray
    dm: np.ndarray
    t_pay: np.ndarray
    J: np.ndarray  # (B, 3)
    rx: np.ndarray  # (B, 4) rotor x positions [m]
    ry: np.ndarray  # (B, 4)
    cg: np.ndarray  # (B, 2)
    flap: np.ndarray  # (B,) D [m per m/s]: forward-flight rotor moment arm (realistic_params.FLAP_PER_MS)
    twist: np.ndarray  # (B, 4) arm delta_i [m]: yaw moment per newton of the twisted mounts (MOUNT_TWIST_DEG)
    fmax: np.ndarray  # (B, 4) F_max kf_i: the build's full thrust (thrust-to-weight draw) x the motor's spread
    h: np.ndarray  # (B, 4) healthy cooling h_nom cool_i
    tau_m: np.ndarray  # (B, 4)
    cells: np.ndarray  # (B,)
    R: np.ndarray  # (B,) aged pack + leads [Ohm]
    C: np.ndarray  # (B,) aged capacity [A h]
    C_label: np.ndarray  # (B,) label (new) capacity: what the coulomb counter divides by
    T_amb: np.ndarray  # (B, 1)
    # the airframe class's propulsion scale (sim.fleet_params; the 450 class: exactly the nominal values)
    gamma: np.ndarray | float = NOM.gamma  # (B,) rotor drag torque per newton of thrust [m], ~ prop radius
    c_P: np.ndarray | float = NOM.c_P  # (B,) induced power F^1.5 coefficient, ~ 1 / prop radius
    ctrl: np.ndarray | float = 1.0  # (B, 3) the class's rate-loop output scale (roll, pitch, yaw)
    # motor thermal node (sim.thermal's Eq. 5) scaled to the class's motor: (B, 1) each
    R_w: np.ndarray | float = NOM.R_w  # winding resistance
    c_F: np.ndarray | float = NOM.c_F  # mechanical loss per N^2
    C_th: np.ndarray | float = NOM.C_th  # heat capacity; h, h_min and the fault heat a_Q scale with it
    heat: np.ndarray | float = 1.0  # C_th / NOM.C_th
    k_L: np.ndarray | float = NOM.k_L  # (B,) linear drag ~ frontal area (size^2)
    k_Omega: np.ndarray | float = NOM.k_Omega  # (B,) rotational damping ~ rotor thrust x arm^2 (size^4)


def rotor_positions(frame: np.ndarray, arm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotor (x, y) of plus (frame 0: rotor 1 on +x, 2 on +y) or X (frame 1: 45 deg further), (B, 4) each."""
    ang = np.arange(4)[None, :] * (np.pi / 2) + frame[:, None] * (np.pi / 4)
    return arm[:, None] * np.cos(ang), arm[:, None] * np.sin(ang)


def vehicle(draws: list[dict]) -> Vehicle:
    d = stack(draws, ("mass", "payload_kg", "payload_t", "frame", "arm", "cells", "cg", "kf", "cool", "capacity",
                      "age", "t_amb", "motor_tau", "thrust_to_weight", "flap", "twist"))
    F_max = d["thrust_to_weight"] * d["mass"] * NOM.g / 4.0  # the build's propulsion (realistic_params)
    rx, ry = rotor_positions(d["frame"], d["arm"])
    scale = (d["mass"] / NOM.m) * (d["arm"] / NOM.L) ** 2  # point-mass scaling of the inertia
    R = d["cells"] * P.R_CELL_5AH * (5.0 / d["capacity"]) * (1 + P.AGE_R_GROWTH * d["age"]) + P.R_LEADS
    size = np.array([float(x.get("size", 1.0)) for x in draws])  # prop and motor scale of the class (fleet)
    ctrl = np.stack([size ** 1.5, size ** 1.5, size ** 0.5], -1)  # sim.fleet_params: Froude-similar tuning
    mot = np.array([[float(x.get(k, 1.0)) for k in ("motor_R_w", "motor_c_F", "motor_heat")] for x in draws])
    heat = mot[:, 2:3]
    return Vehicle(d["mass"], d["payload_kg"], d["payload_t"], NOM.J[None, :] * scale[:, None], rx, ry, d["cg"],
                   d["flap"] * d["arm"] / np.sqrt(2.0), d["arm"][:, None] * d["twist"],
                   F_max[:, None] * d["kf"], NOM.h_nom * d["cool"] * heat, d["motor_tau"], d["cells"], R,
                   d["capacity"] * (1 - P.AGE_FADE * d["age"]), d["capacity"], d["t_amb"][:, None],
                   NOM.gamma * size, NOM.c_P / size, ctrl, NOM.R_w * mot[:, 0:1], NOM.c_F * mot[:, 1:2],
                   NOM.C_th * heat, heat, NOM.k_L * size ** 2, NOM.k_Omega * size ** 4)


class Held(NamedTuple):
    """Inputs held over one step."""

    F_base: np.ndarray  # (B, 4) F_tgt / d: everything but the temperature derating
    rho_Q_T: np.ndarray  # (B, 4) rho_Q / rho_T^1.5 (power factor) ...
    yaw_k: np.ndarray  # (B, 4) gamma s_i rho_Q / rho_T + arm delta_i (yaw moment per newton)
    h: np.ndarray  # (B, 4)
    Q_f: np.ndarray  # (B, 4)
    R: np.ndarray  # (B,)
    C: np.ndarray  # (B,)
    delta: np.ndarray  # (B,) weak-cell SoC deficit
    wind: np.ndarray  # (B, 3)
    phys: SimpleNamespace  # m, J, drag for rigid_body._deriv


def ocv_cell(soc: np.ndarray) -> np.ndarray:
    """One LiPo cell's rest voltage: the paper's 3S table / 3."""
    return battery.ocv(soc, NOM) / 3.0


def terminal(soc: np.ndarray, P_el: np.ndarray, veh: Vehicle, R: np.ndarray, delta: np.ndarray):
    """Pack terminal voltage and current (closed form as battery.terminal; max-power clamp)."""
    vc = ocv_cell(soc)
    E = veh.cells * vc - (vc - ocv_cell(soc - delta))
    disc = E * E - 4.0 * R * P_el
    V = 0.5 * (E + np.sqrt(np.maximum(disc, 0.0)))
    return V, (E - V) / R, disc < 0.0


def deriv(x: np.ndarray, u: Held, veh: Vehicle) -> tuple[np.ndarray, tuple]:
    T_m, F = x[:, 13:17], x[:, 17:21]
    d = faults.derating(T_m, 1.0, NOM)
    Fp = np.maximum(F, 0.0)
    P_el = veh.c_P * (u.rho_Q_T * Fp * np.sqrt(Fp)).sum(axis=1) + NOM.P_av
    V, I, lim = terminal(x[:, 12], P_el, veh, u.R, u.delta)
    dx = np.empty_like(x)
    Mx = (F * (veh.ry - veh.cg[:, 1:2])).sum(axis=1)
    My = -(F * (veh.rx - veh.cg[:, 0:1])).sum(axis=1)
    Mz = (F * u.yaw_k).sum(axis=1)
    T = F.sum(axis=1)
    ax, ay = body_airspeed(x, u.wind)
    Mx = Mx + veh.flap * T * ay
    My = My - veh.flap * T * ax
    rigid_body._deriv(x, T, Mx, My, Mz, u.phys, dx[:, :12])
    dx[:, 3:6] += (u.phys.k_L / u.phys.m)[:, None] * u.wind
    dx[:, 12] = -I / (3600.0 * u.C)
    I_m = thermal.motor_currents(F, I)
    dx[:, 13:17] = thermal.deriv(T_m, I_m, F, u.h, u.Q_f, veh.T_amb, veh)  # sim.thermal with the class's motor
    dx[:, 17:21] = (u.F_base * d - F) / veh.tau_m
    return dx, (V, I, lim, d)


def body_airspeed(x: np.ndarray, wind: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame x and y components (B,) of the airspeed v - w: the first two rows of R^T (v - w)
    with R = Rz Ry Rx (sim.rigid_body.rotation)."""
    a = x[:, 3:6] - wind
    sn, cn = np.sin(x[:, 6:9]), np.cos(x[:, 6:9])
    sp, st, ss = sn[:, 0], sn[:, 1], sn[:, 2]
    cp, ct, cs = cn[:, 0], cn[:, 1], cn[:, 2]
    bx = cs * ct * a[:, 0] + ss * ct * a[:, 1] - st * a[:, 2]
    by = (cs * st * sp - ss * cp) * a[:, 0] + (ss * st * sp + cs * cp) * a[:, 1] + ct * sp * a[:, 2]
    return bx, by


def held_inputs(thr: np.ndarray, kappa: np.ndarray, s: np.ndarray, ev: np.ndarray, fp: FaultPlan, veh: Vehicle,
                wind: np.ndarray, t: float) -> Held:
    """Inputs of one step: motor outputs thr (B, 4) in [0, 1], kappa_V (B,), physical severity s (B,),
    intermittent event flags ev (B,), wind (B, 3)."""
    s_b, s_m, s_h, s_p = (s * fp.kind[:, k] for k in (1, 2, 3, 4))
    oh = fp.onehot
    c = 1.0 - NOM.a_M * s_m[:, None] * oh
    c = np.where((ev * fp.kind[:, 2] > 0)[:, None] & (oh > 0), 0.0, c)  # ESC desync: no thrust
    cut = propeller.cut_of_severity(s_p)[:, None] * oh
    rT, rQ = propeller.thrust_factor(cut), propeller.torque_factor(cut)
    F_base = veh.fmax * c * rT * kappa[:, None] * thrust_fraction(thr)
    h = np.maximum(veh.h * (1.0 - NOM.a_h * s_h[:, None] * oh), NOM.h_min * veh.heat)
    sub = fp.submode
    R = veh.R * (1 + P.BATT_R_GROWTH * s_b * sub[:, 0]) + fp.r_spike * (ev * fp.kind[:, 1])
    C = veh.C * (1 - P.BATT_FADE * s_b * sub[:, 1])
    delta = P.IMBALANCE_CELL_SOC * s_b * sub[:, 2]
    m = veh.m0 + np.where(t >= veh.t_pay, veh.dm, 0.0)
    phys = SimpleNamespace(m=m, g=NOM.g, Jxx=veh.J[:, 0], Jyy=veh.J[:, 1], Jzz=veh.J[:, 2], k_L=veh.k_L,
                           k_Omega=veh.k_Omega)
    gamma = np.asarray(veh.gamma, np.float64).reshape(-1, 1)
    return Held(F_base, rQ / (rT * np.sqrt(rT)), gamma * SPIN * rQ / rT + veh.twist, h, NOM.a_Q * veh.heat * s_h[:, None] * oh,
                R, C, delta, wind, phys)


def mix(T: np.ndarray, tau: np.ndarray, veh: Vehicle) -> np.ndarray:
    """Generic quad mixer (the controller's, for the flight's frame; it knows geometry, not mass or CG),
    with sim.controller.mix_desaturate's priorities: roll/pitch, then yaw, then collective. (B, 4) [N]."""
    Fmax = NOM.F_max
    sy2 = (veh.ry * veh.ry).sum(axis=1, keepdims=True)
    sx2 = (veh.rx * veh.rx).sum(axis=1, keepdims=True)
    F = 0.25 * T[:, None] + tau[:, 0:1] * veh.ry / sy2 - tau[:, 1:2] * veh.rx / sx2
    y = np.clip(tau[:, 2], -NOM.tau_yaw_max, NOM.tau_yaw_max) * (0.25 / NOM.gamma)
    pos = SPIN > 0
    room = np.where(y[:, None] >= 0.0, np.where(pos, Fmax - F, F), np.where(pos, F, Fmax - F)).min(axis=1)
    y = y * np.clip(room / np.maximum(np.abs(y), 1e-9), 0.0, 1.0)
    F = F + y[:, None] * SPIN
    shift = np.maximum(F.max(axis=1) - Fmax, 0.0) - np.maximum(-F.min(axis=1), 0.0)
    return np.clip(F - shift[:, None], 0.0, Fmax)


def thrust_fraction(u: np.ndarray) -> np.ndarray:
    """The nominal thrust curve: ESC output u in [0, 1] -> F / F_max (what the log's thr1..4 hold)."""
    k = P.THR_MDL_FAC
    return (1.0 - k) * u + k * u * u


def motor_output(F_cmd: np.ndarray) -> np.ndarray:
    """The ESC output u in [0, 1] that the nominal thrust curve maps to F_cmd / F_max."""
    k = P.THR_MDL_FAC
    f = np.clip(F_cmd / NOM.F_max, 0.0, 1.0)
    return (-(1.0 - k) + np.sqrt((1.0 - k) ** 2 + 4.0 * k * f)) / (2.0 * k)


def kappa_v(V: np.ndarray, veh: Vehicle) -> np.ndarray:
    """kappa_V of the paper, about the pack's nominal voltage 3.7 V per cell (motors matched to the pack)."""
    V_nom = 3.7 * veh.cells
    return 1.0 - NOM.k_V * (V_nom - V) / V_nom
