"""Vehicle parameters: every symbol of the paper's Table 1, in SI units, for a named vehicle class.

One frozen dataclass, ``VehicleParams``; ``VEHICLES`` maps a vehicle-class name to its values and
``get_vehicle(name)`` looks one up. The only class so far is ``"f450_3s"``: a ~1.5 kg F450-class
quadrotor (450 mm motor-to-motor, arm L = 0.225 m), 10x4.5 inch propellers on 2212-920KV motors,
a 3S 5 Ah LiPo. docs/params.md tables every value with its reason.

Sources for the values (order of magnitude, not a system identification of one airframe):
- mass, arm, inertia: DJI F450 frame (282 g) + 4 x 2212 motors (~55 g) + 10" props (~12 g) +
  3S 5 Ah pack (~400 g) + flight controller, GPS, ESCs, wiring; inertia from point masses at the
  arm ends plus the central body, in line with published F450 identifications (Jxx ~ 0.015-0.02).
- rotor: 2212-920KV + 1045 prop on 3S: ~850 g (8.3 N) static thrust at full throttle, hover at
  ~40 % throttle, ~8-9 g/W at hover (manufacturer thrust tables, e.g. DJI E305/Emax MT2213).
- battery: a healthy 3S 5 Ah 20-30C pack has ~15-25 mOhm DC resistance, plus connectors/leads.
- LiPo open-circuit curve: the usual per-cell rest-voltage curve (4.20 V full, ~3.7-3.9 V
  plateau, 3.0 V empty) times three.

Plus-configuration geometry implied by the paper's Eq. (3) (z up): rotor 1 on +x, rotor 3 on -x
(pitch moment L(F3 - F1)), rotor 2 on +y, rotor 4 on -y (roll moment L(F2 - F4)); rotors 1 and 3
spin one way, 2 and 4 the other (yaw moment gamma(F1 - F2 + F3 - F4)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfdi.core.errors import QuadfdiError


@dataclass(frozen=True)
class VehicleParams:
    """Physical, fault, sensor and controller parameters of one vehicle class (SI units)."""

    name: str

    # --- rigid body (Eq. 2, 3) ---
    m: float  # kg, total take-off mass
    g: float  # m/s^2, standard gravity
    Jxx: float  # kg m^2, roll inertia
    Jyy: float  # kg m^2, pitch inertia
    Jzz: float  # kg m^2, yaw inertia
    L: float  # m, centre of mass to rotor axis
    gamma: float  # m, yaw reaction torque per newton of thrust (k_M / k_F of the prop)
    k_L: float  # N s/m, translational (linear) drag
    k_Omega: float  # N m s/rad, rotational drag
    F_max: float  # N, one rotor's thrust at full command and nominal bus voltage V_nom

    # --- battery (Eq. 4) ---
    C_nom: float  # A h, nominal capacity
    R_0: float  # Ohm, nominal internal resistance (pack + leads)
    V_nom: float  # V, nominal pack voltage (3 x 3.7 V); reference of kappa_V
    ocv_soc: tuple[float, ...]  # -, SoC grid of the open-circuit-voltage table
    ocv_volt: tuple[float, ...]  # V, V_ocv at those SoC (linear interpolation)
    P_av: float  # W, avionics (static) power
    c_P: float  # W / N^a_P, propeller power coefficient: P_i = c_P F_i^a_P
    a_P: float  # -, exponent of the thrust-power relation (momentum theory: 3/2)

    # --- motor thermal model (Eq. 5), one lumped winding node per motor ---
    C_th: float  # J/K, thermal capacity of the winding + stator node
    R_w: float  # Ohm, winding resistance (phase-to-phase)
    c_F: float  # W/N^2, mechanical/iron-loss heat per thrust squared
    h_nom: float  # W/K, nominal convective heat-transfer coefficient
    T_amb_range: tuple[float, float]  # degC, ambient temperature drawn per flight

    # --- fault amplitudes (Eq. 7, 8) ---
    a_R: float  # -, internal-resistance increase: R_int = R_0 (1 + a_R s_b)
    a_C: float  # -, capacity loss: C_eff = C_nom (1 - a_C s_b)
    Delta_V: float  # V, extra voltage sag at s_b = 1
    a_I: float  # -, extra current: I_b = (P / V_b)(1 + a_I s_b)
    a_M: float  # -, motor-effectiveness loss: c_i = 1 - a_M s_m
    a_h: float  # -, cooling loss: h_m = h_nom (1 - a_h s_h)
    a_Q: float  # W, fault heat at s_h = 1
    h_min: float  # W/K, lower bound of the heat-transfer coefficient
    lambda_T: float  # 1/degC, thermal derating slope above T_der
    T_der: float  # degC, derating onset temperature
    a_d: float  # -, overheat-induced effectiveness loss at s_h = 1
    d_min: float  # -, lower bound of the derating factor
    k_V: float  # -, kappa_V = 1 - k_V (V_nom - V_b) / V_nom

    # --- sensors (Eq. 9): (noise std, bias random-walk std per sqrt(s)) per channel group ---
    sens_pos_xy: tuple[float, float]  # m, m/sqrt(s)
    sens_pos_z: tuple[float, float]  # m, m/sqrt(s)
    sens_vel: tuple[float, float]  # m/s, m/s/sqrt(s)
    sens_att: tuple[float, float]  # rad, rad/sqrt(s)
    sens_rate: tuple[float, float]  # rad/s, rad/s/sqrt(s)
    sens_vb: tuple[float, float]  # V, V/sqrt(s)
    sens_ib: tuple[float, float]  # A, A/sqrt(s)
    sens_soc: tuple[float, float]  # -, 1/sqrt(s)
    sens_temp: tuple[float, float]  # degC, degC/sqrt(s)
    sens_thr: tuple[float, float]  # -, 1/sqrt(s)

    # --- cascaded controller (sim/controller.py) ---
    kp_xy: float  # 1/s^2, horizontal position gain
    kd_xy: float  # 1/s, horizontal velocity gain
    kp_z: float  # 1/s^2, altitude gain
    kd_z: float  # 1/s, vertical velocity gain
    ki_z: float  # 1/s^3, altitude integral gain (absorbs hover-thrust error)
    iz_max: float  # m/s^2, altitude integrator clamp
    tilt_max: float  # rad, maximum commanded tilt
    k_att_rp: float  # 1/s, roll/pitch angle gain
    k_att_yaw: float  # 1/s, yaw angle gain
    rate_max_rp: float  # rad/s, roll/pitch rate-setpoint limit
    rate_max_yaw: float  # rad/s, yaw rate-setpoint limit
    k_rate_rp: float  # 1/s, roll/pitch rate P gain (angular acceleration per rate error)
    ki_rate_rp: float  # 1/s^2, roll/pitch rate I gain
    k_rate_yaw: float  # 1/s, yaw rate P gain
    ki_rate_yaw: float  # 1/s^2, yaw rate I gain
    irate_max_rp: float  # rad/s^2, roll/pitch rate-integrator clamp
    irate_max_yaw: float  # rad/s^2, yaw rate-integrator clamp
    tau_yaw_max: float  # N m, yaw torque limit (yaw has the least authority)
    v_comp: bool  # PX4-style thrust scaling by V_nom / V_b (MC_BAT_SCALE_EN, off by default)

    def __post_init__(self) -> None:
        if len(self.ocv_soc) != len(self.ocv_volt) or len(self.ocv_soc) < 2:
            raise QuadfdiError(f"vehicle {self.name}: ocv_soc and ocv_volt must have the same length >= 2")
        if any(b <= a for a, b in zip(self.ocv_soc, self.ocv_soc[1:])):
            raise QuadfdiError(f"vehicle {self.name}: ocv_soc must be strictly increasing")

    @property
    def J(self) -> np.ndarray:
        """Diagonal of the inertia matrix, (3,) kg m^2 (principal axes = body axes)."""
        return np.array([self.Jxx, self.Jyy, self.Jzz])

    @property
    def hover_thrust(self) -> float:
        """Per-rotor thrust in level hover, N."""
        return self.m * self.g / 4.0


VEHICLES: dict[str, VehicleParams] = {
    "f450_3s": VehicleParams(
        name="f450_3s",
        # rigid body
        m=1.5,  # kg: F450 frame + 2212 motors + 10" props + 3S 5 Ah pack + avionics
        g=9.81,  # m/s^2: standard gravity
        Jxx=0.0175,  # kg m^2: 2 rotors (~70 g) at 0.225 m + pack/body; F450 identifications 0.015-0.02
        Jyy=0.0175,  # kg m^2: symmetric frame
        Jzz=0.031,  # kg m^2: all 4 rotors at 0.225 m + body; ~1.8 x Jxx as for flat X/+ frames
        L=0.225,  # m: half of the 450 mm motor-to-motor diagonal
        gamma=0.016,  # m: yaw torque/thrust ratio of a 10x4.5 prop (k_M/k_F ~ 0.01-0.02 m)
        k_L=0.25,  # N s/m: ~7 m/s^2 of tilt thrust balances drag near 25 m/s, typical small quad
        k_Omega=0.005,  # N m s/rad: 0.015 N m at 3 rad/s, a few % of the rotor torque authority
        F_max=8.5,  # N: 2212-920KV + 1045 prop at 11.1 V, ~870 g static thrust (thrust/weight 2.3)
        # battery
        C_nom=5.0,  # A h: the 5 Ah pack
        R_0=0.025,  # Ohm: healthy 3S 5 Ah pack (~15-20 mOhm) + XT60, leads, PDB
        V_nom=11.1,  # V: 3 x 3.7 V nominal cell voltage
        ocv_soc=(0.0, 0.05, 0.10, 0.15, 0.20, 0.30, 0.40, 0.50, 0.60, 0.70, 0.80, 0.90, 1.0),  # -
        # V: 3 x the LiPo cell rest curve (3.0 V empty, 3.7-3.9 V plateau, 4.2 V full)
        ocv_volt=(9.00, 9.90, 10.50, 10.80, 11.04, 11.19, 11.31, 11.40, 11.52, 11.70, 11.91, 12.21, 12.60),
        P_av=6.0,  # W: flight controller + GPS + receiver + telemetry radio + ESC logic (~0.5 A)
        c_P=5.5,  # W/N^1.5: 39 W per rotor at hover (3.68 N), ~9.5 g/W, 161 W and ~14 A for the vehicle
        a_P=1.5,  # -: momentum theory, induced power ~ F^(3/2)
        # motor thermal model (lumped winding node)
        C_th=12.0,  # J/K: ~30 g of copper+stator iron that heats first (c ~ 400 J/kg/K)
        R_w=0.12,  # Ohm: 2212-920KV phase-to-phase winding resistance ~0.1-0.13 Ohm
        c_F=0.35,  # W/N^2: iron + bearing + ESC losses, ~4.7 W at hover; ~6.2 W total with copper
        h_nom=0.35,  # W/K: self-ventilated outrunner in prop wash; tau = C_th/h = 34 s, rise ~18 K at hover
        T_amb_range=(10.0, 35.0),  # degC: spring-to-summer outdoor flight
        # fault amplitudes
        a_R=2.0,  # -: resistance x3 at s_b = 1 (swollen/aged pack, a failing cell or connector)
        a_C=0.3,  # -: 30 % capacity loss at s_b = 1 (an aged pack near end of life)
        Delta_V=0.8,  # V: one weak/damaged cell sagging ~0.8 V more than its neighbours under load
        a_I=0.2,  # -: +20 % current at s_b = 1 (leakage through a soft-shorted cell, ESC heating)
        a_M=0.5,  # -: a chipped prop / demagnetised motor losing up to 50 % of its thrust
        a_h=0.6,  # -: 60 % of the cooling lost (clogged/obstructed motor bell, bearing grease)
        a_Q=30.0,  # W: shorted turns or a seized bearing dissipating ~30 W in the motor
        h_min=0.10,  # W/K: still-air natural convection + conduction into the arm
        lambda_T=0.02,  # 1/degC: ESC/motor derating, 2 % thrust per degC above T_der
        T_der=70.0,  # degC: typical ESC/motor thermal-limit onset (magnets, enamel rated 120-180)
        a_d=0.3,  # -: up to 30 % effectiveness loss of the overheating motor (softened magnets)
        d_min=0.3,  # -: derating never takes a motor below 30 %
        k_V=2.0,  # -: at fixed duty, speed ~ V and thrust ~ speed^2, so dF/F = 2 dV/V
        # sensors (noise std, bias random-walk std per sqrt(s)); telemetry = estimator outputs
        sens_pos_xy=(0.02, 0.02),  # m: fused GNSS/EKF local position, slow drift
        sens_pos_z=(0.03, 0.03),  # m: baro-fused altitude, baro drift
        sens_vel=(0.02, 0.005),  # m/s: EKF velocity
        sens_att=(0.005, 0.001),  # rad: 0.3 deg attitude noise, slow heading drift
        sens_rate=(0.01, 0.0005),  # rad/s: filtered MEMS gyro at 25 Hz, gyro bias instability
        sens_vb=(0.02, 0.002),  # V: power-module ADC, 10-bit-class resolution
        sens_ib=(0.15, 0.02),  # A: hall/shunt current sensor noise and offset drift
        sens_soc=(0.002, 0.0005),  # -: coulomb-counting SoC estimate
        sens_temp=(0.25, 0.02),  # degC: ESC/motor NTC thermistor
        sens_thr=(0.001, 0.0),  # -: DShot/PWM quantisation (1/2000); a digital value does not drift
        # controller
        kp_xy=1.2,  # 1/s^2: horizontal loop, natural frequency 1.1 rad/s
        kd_xy=1.8,  # 1/s: damping ratio 0.82
        kp_z=6.75,  # 1/s^2: with kd_z and ki_z a triple pole at -1.5 rad/s: (s+1.5)^3
        kd_z=4.5,  # 1/s
        ki_z=3.375,  # 1/s^3: a thrust loss ramping at 0.6 m/s^3 leaves a 0.18 m altitude sag
        iz_max=4.0,  # m/s^2: integrator clamp (anti wind-up)
        tilt_max=0.40,  # rad: 23 deg tilt limit (PX4 MPC_TILTMAX_AIR is 45; gentle survey flying)
        k_att_rp=7.0,  # 1/s: roll/pitch angle loop (PX4 MC_ROLL_P 6.5)
        k_att_yaw=2.5,  # 1/s: yaw angle loop (PX4 MC_YAW_P 2.8)
        rate_max_rp=3.0,  # rad/s: 170 deg/s roll/pitch rate limit
        rate_max_yaw=1.5,  # rad/s: 86 deg/s yaw rate limit
        k_rate_rp=25.0,  # 1/s: rate-loop bandwidth ~25 rad/s (no motor lag modelled)
        ki_rate_rp=40.0,  # 1/s^2: rate integrator (I/P = 1.6/s as PX4's MC_ROLLRATE_I/P); re-balances a weak motor
        k_rate_yaw=8.0,  # 1/s
        ki_rate_yaw=8.0,  # 1/s^2
        irate_max_rp=60.0,  # rad/s^2: ~1.05 N m; a rotor at 50 % needs ~0.83 N m (m g L / 4) of commanded torque
        irate_max_yaw=4.0,  # rad/s^2: ~0.12 N m of integrated yaw torque; a rotor at 50 % needs ~0.06
        tau_yaw_max=0.10,  # N m: 1.6 N of differential thrust per rotor; a 50 % motor loss needs 0.06
        v_comp=False,  # PX4's MC_BAT_SCALE_EN defaults to off; the integrators absorb the sag
    ),
}


def get_vehicle(name: str) -> VehicleParams:
    """The parameters of vehicle class ``name``; QuadfdiError listing the valid names otherwise."""
    try:
        return VEHICLES[name]
    except KeyError:
        raise QuadfdiError(f"unknown vehicle {name!r}; valid vehicles: {', '.join(sorted(VEHICLES))}") from None
