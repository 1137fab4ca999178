"""ESC board temperature of the realistic suite (``esc_temp1..4``, degC): one first-order thermal node
per ESC, driven by the current that ESC delivers (docs/params.md "ESC temperature").

    C dT_k/dt = P_k - G_k (T_k - T_amb)
    P_k = R_k I_k^2 + S V_b I_k + V_b I_q          conduction (MOSFETs + copper, referred to the ESC's
                                                    input current), switching (~ V I t_sw f_pwm), logic
    G_k = G_still + G_flow,k sqrt(v_k / 1 m/s)     natural convection + forced (laminar plate: h ~ v^0.5)
    v_k = sqrt(v_i,k^2 + v_air^2),  v_i,k = sqrt(F_k / (2 rho pi R^2))   prop wash (momentum theory) and
                                                    the airspeed over the mean wind

I_k is the ESC's true input current (sim.esc_telemetry.esc_current: a cut blade's rotor draws more for
its thrust, so its ESC runs warmer), V_b the bus voltage, F_k the rotor's thrust, T_amb the flight's
ambient (sim.variability ``t_amb``, the motor thermal model's). At t = 0 (the vehicle at its mission
altitude) each ESC has warmed for ``t_pre`` seconds at the first record's losses from T_amb. The
reported value adds a per-ESC sensor offset and is quantised to 1 degC (BLHeli_32 telemetry byte).

Per vehicle (one ESC type on four arms): C, the base R, S, I_q, G_still, the base G_flow, t_pre; per
ESC: R and G_flow spreads, the sensor offset. All from a NEW stream per flight,
``SeedSequence(seed, spawn_key=(THERMAL_SPAWN, i))``, drawn after everything else: no earlier array of
a dataset moves. Only float64 +, -, *, / and sqrt on arrays (correctly rounded on every ISA); the one
exponential (the pre-flight warm-up) is libm's ``math.exp`` per scalar (commit 0fee2b6 says why).
"""

from __future__ import annotations

import math

import numpy as np

THERMAL_SPAWN = 6  # spawn_key (6, i): flight i's ESC thermal draws (1..5 are taken; 5: sim.esc_telemetry)
RHO_AIR = 1.225  # kg/m^3
PROP_R_M = 0.127  # m: the suite's 10" prop (sim.realistic_params.PROP_R_M)
# the node the sensor sits on: a small ESC's MCU/FET corner (~2 g, the 6S tip-over flight's 15-20 s time
# constant) .. a 6S 40-60 A ESC with a heat sink (~20 g, the UAVCAN mission's slow rise); docs/params.md
C_J_PER_K = (2.0, 20.0)
R_OHM = (0.010, 0.030)  # conduction loss per input-current squared (2 x R_ds(on) 2-5 mOhm + copper, over duty^2)
R_SPREAD = 0.10  # +- per ESC: MOSFET R_ds(on) tolerance
S_SW = (1.0e-3, 4.0e-3)  # switching loss per input power: (t_r + t_f) f_pwm / (2 duty), 50-150 ns at 24-48 kHz
I_Q_A = (0.010, 0.030)  # logic + gate driver supply current drawn from the bus (MCU, LDO/buck, driver)
G_STILL = (0.020, 0.050)  # W/K: natural convection of a 15-25 cm^2 board (h ~ 10-15 W/m^2/K) + leads
G_FLOW = (0.020, 0.080)  # W/K per sqrt(m/s): flat-plate forced convection (0.03 bare board, x2-3 heat sink)
G_SPREAD = 0.20  # +- per ESC: where on the arm it sits in the wash (as the motors' cooling spread)
PRE_S = (5.0, 30.0)  # s armed, taking off and climbing before the simulated flight's t = 0
OFFSET_C = 1.0  # +- per ESC: uncalibrated sensor (MCU die sensor, +-1-2 degC after factory trim)
STEP_C = 1.0  # degC per telemetry unit (BLHeli_32 / KISS telemetry byte)
NAMES = ("esc_temp1", "esc_temp2", "esc_temp3", "esc_temp4")


def draw(seed: int, idx: np.ndarray) -> dict[str, np.ndarray]:
    """Per flight (fixed order, its own stream): name -> (B,) or (B, 4)."""
    keys = ("C", "R", "S", "I_q", "G_still", "G_flow", "t_pre", "offset")
    out: dict[str, list] = {k: [] for k in keys}
    for i in idx:
        g = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(THERMAL_SPAWN, int(i))))
        out["C"].append(g.uniform(*C_J_PER_K))
        out["R"].append(g.uniform(*R_OHM) * (1.0 + g.uniform(-R_SPREAD, R_SPREAD, 4)))
        out["S"].append(g.uniform(*S_SW))
        out["I_q"].append(g.uniform(*I_Q_A))
        out["G_still"].append(g.uniform(*G_STILL))
        out["G_flow"].append(g.uniform(*G_FLOW) * (1.0 + g.uniform(-G_SPREAD, G_SPREAD, 4)))
        out["t_pre"].append(g.uniform(*PRE_S))
        out["offset"].append(g.uniform(-OFFSET_C, OFFSET_C, 4))
    return {k: np.asarray(v, np.float64) for k, v in out.items()}


def losses(I: np.ndarray, V: np.ndarray, d: dict[str, np.ndarray]) -> np.ndarray:
    """Heat [W] (..., B, 4) of ESCs delivering I (..., B, 4) [A] from the bus V (..., B) [V]."""
    Ip = np.maximum(I, 0.0)
    Vb = V[..., None]
    return d["R"] * Ip * Ip + d["S"][:, None] * Vb * Ip + d["I_q"][:, None] * Vb


def conductance(F: np.ndarray, v_air: np.ndarray, d: dict[str, np.ndarray]) -> np.ndarray:
    """Board-to-air conductance [W/K] (..., B, 4): rotor thrust F (..., B, 4) [N], airspeed (..., B) [m/s]."""
    v_i2 = np.maximum(F, 0.0) / (2.0 * RHO_AIR * math.pi * PROP_R_M * PROP_R_M)  # induced velocity squared
    v = np.sqrt(v_i2 + (v_air * v_air)[..., None])
    return d["G_still"][:, None] + d["G_flow"] * np.sqrt(v)


def temperatures(P: np.ndarray, G: np.ndarray, T_amb: np.ndarray, d: dict[str, np.ndarray], dt: float) -> np.ndarray:
    """True board temperatures (n, B, 4) [degC] from the losses P and conductances G (n, B, 4) at step dt:
    backward Euler in the decay with the sample's inputs held, T' = (C T + dt (P + G T_amb)) / (C + dt G)
    (dt / tau < 1e-3: the scheme's error is far below the 1 degC unit)."""
    C = d["C"][:, None]
    Ta = T_amb[:, None]
    rise = P[0] / G[0]
    warm = np.array([[1.0 - math.exp(-t * g / c) for g in row] for t, row, c in zip(d["t_pre"], G[0], d["C"])])
    T = np.empty_like(P)
    T[0] = Ta + rise * warm
    for n in range(1, len(P)):
        T[n] = (C * T[n - 1] + dt * (P[n - 1] + G[n - 1] * Ta)) / (C + dt * G[n - 1])
    return T


def reported(T: np.ndarray, d: dict[str, np.ndarray]) -> np.ndarray:
    """What the ESC reports: T + its sensor offset, quantised to STEP_C (n, B, 4)."""
    return np.round((T + d["offset"]) / STEP_C) * STEP_C


def airspeed(v: np.ndarray, wind_ms: np.ndarray, wind_dir: np.ndarray) -> np.ndarray:
    """|v - w_mean| (n, B) [m/s] of the true velocity v (n, B, 3) over the flight's mean wind (horizontal);
    turbulence and gusts are left out (they are not recorded)."""
    wx = wind_ms * np.array([math.cos(a) for a in wind_dir])
    wy = wind_ms * np.array([math.sin(a) for a in wind_dir])
    ax, ay, az = v[..., 0] - wx, v[..., 1] - wy, v[..., 2]
    return np.sqrt(ax * ax + ay * ay + az * az)


def esc_temperatures(F: np.ndarray, I: np.ndarray, V: np.ndarray, vel: np.ndarray, flight: dict[str, np.ndarray],
                     d: dict[str, np.ndarray], dt: float) -> dict[str, np.ndarray]:
    """``esc_temp1..4`` at the record, name -> (n, B): thrust F and ESC current I (n, B, 4), bus V (n, B),
    velocity (n, B, 3), ``flight``: t_amb, wind_ms, wind_dir (B,); ``d`` from ``draw``."""
    G = conductance(F, airspeed(vel, flight["wind_ms"], flight["wind_dir"]), d)
    T = reported(temperatures(losses(I, V, d), G, flight["t_amb"], d, dt), d)
    return {name: T[..., k] for k, name in enumerate(NAMES)}
