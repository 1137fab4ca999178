"""Propeller damage: thrust and torque loss of a cut blade (blade-element theory) and the rotor
imbalance vibration, synthesised into the two vibration metrics flight controllers log.

Thrust and torque of a cut blade. Blade-element theory with constant chord c, constant lift and
drag coefficients and uniform inflow (tip losses neglected): an element at radius r sees the
dynamic pressure of (Omega r)^2, so per blade

    dT = 1/2 rho (Omega r)^2 c C_l dr   ->  T_blade(R') = k_T R'^3
    dQ = 1/2 rho (Omega r)^2 c C_d r dr ->  Q_blade(R') = k_Q R'^4

A two-blade prop with one blade cut by a fraction l of its radius (R' = (1 - l) R) keeps, at the
same rotor speed,

    rho_T(l) = (1 + (1 - l)^3) / 2   of its thrust,    rho_Q(l) = (1 + (1 - l)^4) / 2   of its torque.

At l = 0.3 (CUT_MAX, severity 1): rho_T = 0.67, rho_Q = 0.62. Torque falls faster than thrust, so
a cut prop also leaves a yaw-torque imbalance: the observable that tells it from a CG offset,
which changes the roll/pitch commands only (docs/params.md).

Imbalance. The cut removes Delta m = BLADE_G * TIP_MASS_FACTOR * l from one blade at radius
r_c = R (1 - l/2): a rotating force F = Delta m r_c Omega^2 in the rotor plane at the rotor
frequency f = Omega / 2 pi (80-150 Hz, above the rigid-body step's 100 Hz Nyquist, so it is not
integrated: it is synthesised). Through the FC's vibration mount (transmissibility MOUNT_T) the
IMU sees a rotating in-plane acceleration of amplitude A = MOUNT_T F / m, on top of the healthy
broadband floor sigma_f per axis. The two logged metrics, in closed form for that signal:

- ArduPilot VIBE (AP_InertialSensor): accel minus its 5 Hz low-pass, squared, 2 Hz low-pass, sqrt
  = the standard deviation of the content above 5 Hz: VibeX = VibeY = sqrt(sum_i A_i^2 / 2 + sigma_f^2).
  The channel ``vib_ap`` is the in-plane value (VibeX + VibeY) / 2.
- PX4 vehicle_imu_status.accel_vibration_metric (VehicleIMU): an EMA (0.99, 0.01) of
  |a_k - a_(k-1)| over the accel averaged per IMU_INTEG_RATE interval (dt_i = 5 ms). Averaging
  a sinusoid over dt_i scales it by sinc(f dt_i), differencing by 2 |sin(pi f dt_i)|; a rotating
  vector's difference has constant length, so a rotor adds (g_i A_i)^2, the white floor
  3 (2 sigma_f^2 / 5) (5 IMU samples at 1 kHz per average, difference of two). We take the RMS
  of the difference for its mean norm (8 % high for pure noise, exact for a pure rotor).

They are different quantities: VIBE is flat in frequency above 5 Hz, PX4's metric weighs the
rotor frequency by g(f) (1.35 at 90 Hz, 0 at 200 Hz). ``px4_metric_time_domain`` and
``ap_vibe_time_domain`` run both algorithms on a synthesised 1 kHz signal
(tests/test_realistic_physics.py checks the closed forms against them).
"""

from __future__ import annotations

import numpy as np

from quadfdi.sim.realistic_params import (AP_FLOOR_HZ, AP_VIBE_HZ, BLADE_G, CUT_MAX, IMU_INTEG_HZ, K_THRUST, MOUNT_T,
                                  PROP_R_M, PX4_VIB_ALPHA, TIP_MASS_FACTOR)

IMU_HZ = 1000.0  # raw accel sample rate (ICM-20602/42688 class at 1 kHz after the driver)


def thrust_factor(cut: np.ndarray) -> np.ndarray:
    """rho_T(l) = (1 + (1 - l)^3) / 2: thrust kept by a two-blade prop with one blade cut by l."""
    return 0.5 * (1.0 + (1.0 - cut) ** 3)


def torque_factor(cut: np.ndarray) -> np.ndarray:
    """rho_Q(l) = (1 + (1 - l)^4) / 2: torque (and shaft power at equal speed) kept."""
    return 0.5 * (1.0 + (1.0 - cut) ** 4)


def cut_of_severity(s: np.ndarray) -> np.ndarray:
    """Cut fraction l = CUT_MAX s of the propeller class's severity s."""
    return CUT_MAX * s


def imbalance_kgm(cut: np.ndarray, residual_g: np.ndarray) -> np.ndarray:
    """Mass imbalance m r [kg m]: the cut tip (Delta m at R (1 - l/2)) plus a healthy prop's residual
    imbalance (residual_g grams at 0.1 m)."""
    dm = BLADE_G * 1e-3 * TIP_MASS_FACTOR * cut
    return dm * PROP_R_M * (1.0 - 0.5 * cut) + residual_g * 1e-4


def rotor_speed(F: np.ndarray, rho_T: np.ndarray) -> np.ndarray:
    """Omega [rad/s] of a rotor making thrust F [N] with thrust factor rho_T: F = K rho_T Omega^2."""
    return np.sqrt(np.maximum(F, 0.0) / (K_THRUST * rho_T))


def px4_gain(f_hz: np.ndarray) -> np.ndarray:
    """g(f) = |sinc(f dt_i)| 2 |sin(pi f dt_i)|: a sinusoid's amplitude through PX4's average-then-difference."""
    x = f_hz / IMU_INTEG_HZ
    return np.abs(np.sinc(x)) * 2.0 * np.abs(np.sin(np.pi * x))


def metrics(A: np.ndarray, f_hz: np.ndarray, floor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state (px4, ap) metrics [m/s^2] of rotating in-plane amplitudes A (..., 4) at rotor
    frequencies f_hz (..., 4) on a white floor ``floor`` (...) per axis."""
    n_avg = IMU_HZ / IMU_INTEG_HZ
    px4 = np.sqrt(((px4_gain(f_hz) * A) ** 2).sum(-1) + 3.0 * 2.0 * floor**2 / n_avg)
    ap = np.sqrt((A**2).sum(-1) / 2.0 + floor**2)
    return px4, ap


def accel_amplitude(F: np.ndarray, rho_T: np.ndarray, mr: np.ndarray, mass: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """In-plane IMU acceleration amplitude A (..., 4) [m/s^2] and rotor frequency (..., 4) [Hz] of
    rotors with thrust F, thrust factor rho_T and imbalance mr [kg m] on a vehicle of mass (..., 1)."""
    omega = rotor_speed(F, rho_T)
    return MOUNT_T * mr * omega**2 / mass, omega / (2 * np.pi)


# ---------------------------------------------------------------- time-domain reference (tests)


def synthesise(A: np.ndarray, f_hz: np.ndarray, floor: float, seconds: float, rng: np.random.Generator) -> np.ndarray:
    """1 kHz accel (n, 3) of rotors (A, f (4,)) spinning with random phases, plus white floor noise."""
    t = np.arange(int(seconds * IMU_HZ)) / IMU_HZ
    ph = rng.uniform(0, 2 * np.pi, A.shape)
    arg = 2 * np.pi * f_hz[None] * t[:, None] + ph[None]
    a = np.stack([(A * np.cos(arg)).sum(-1), (A * np.sin(arg)).sum(-1), np.zeros_like(t)], -1)
    return a + floor * rng.standard_normal(a.shape)


def px4_metric_time_domain(a: np.ndarray) -> np.ndarray:
    """PX4 VehicleIMU::UpdateAccelVibrationMetrics on 1 kHz accel: average per 5 ms, difference, norm, EMA."""
    n = int(IMU_HZ / IMU_INTEG_HZ)
    avg = a[: len(a) // n * n].reshape(-1, n, 3).mean(axis=1)
    d = np.linalg.norm(np.diff(avg, axis=0), axis=-1)
    out, m = np.empty_like(d), 0.0
    for k, v in enumerate(d):
        m = (1 - PX4_VIB_ALPHA) * m + PX4_VIB_ALPHA * v
        out[k] = m
    return out


def ap_vibe_time_domain(a: np.ndarray) -> np.ndarray:
    """ArduPilot calc_vibration: floor = LPF_5Hz(a); vibe = sqrt(LPF_2Hz((a - floor)^2)), per axis (n, 3)."""
    dt = 1.0 / IMU_HZ
    k_f = dt / (dt + 1 / (2 * np.pi * AP_FLOOR_HZ))
    k_v = dt / (dt + 1 / (2 * np.pi * AP_VIBE_HZ))
    fl, v = np.zeros(3), np.zeros(3)
    out = np.empty_like(a)
    for k in range(len(a)):
        fl = fl + k_f * (a[k] - fl)
        d = a[k] - fl
        v = v + k_v * (d * d - v)
        out[k] = np.sqrt(v)
    return out
