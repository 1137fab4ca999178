"""ESC telemetry of the realistic suite: per-motor RPM and current as the ESCs report them (PX4
``esc_status.esc[i].esc_rpm`` / ``esc_current``, ArduPilot ``ESC.RPM`` / ``ESC.Curr``), logged at the
ESC telemetry rate and resampled onto the grid by the same path as every other channel
(sim.telemetry.to_grid -> core.resample).

From the 50 Hz record (docs/params.md "ESC telemetry"):

- ``rpm_k``: the rotor speed of the thrust the model integrates, ``Omega = sqrt(F / (K rho_T))``
  (sim.propeller.rotor_speed: the same relation the vibration model uses; a cut blade spins faster
  for the same thrust), in rpm, quantised to the ESC's telemetry unit (100 eRPM over 7 pole pairs
  of a 14-pole 22xx motor: 14.3 rpm; BLHeli_32 / KISS telemetry). No other noise: the ESC counts
  commutations.
- ``esc_cur_k``: the motor's electrical power over the bus voltage, ``c_P (rho_Q / rho_T^1.5) F^1.5 / V_b``
  (the power term of sim.realistic_dynamics.deriv: the four sum to ``I_b - P_av / V_b``), times a
  per-ESC gain error (uncalibrated shunt/hall sensing, +-ESC_CUR_GAIN uniform) plus white noise
  (ESC_CUR_NOISE_A), quantised to 0.01 A (the telemetry unit).

- ``esc_temp_k``: the ESC board temperature of sim.esc_thermal (a first-order node per ESC heated by
  the current above, cooled to the flight's ambient through the prop wash), 1 degC units. It is not
  the motor winding temperature T1-4 (another quantity, sim.thermal).

Random numbers come from a NEW stream per flight, ``SeedSequence(seed, spawn_key=(ESC_SPAWN, i))``:
no earlier draw moves, so every existing array of a dataset stays bit-identical (tests/test_esc_sim.py).
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.channels import RATE_GROUP
from quadfdi.sim import propeller
from quadfdi.sim import realistic_params as P

ESC_SPAWN = 5  # spawn_key (5, i): flight i's ESC telemetry noise (1..4 are taken: sim.draws, variability, telemetry)
ESC_CHANNEL_NAMES = ("rpm1", "rpm2", "rpm3", "rpm4", "esc_cur1", "esc_cur2", "esc_cur3", "esc_cur4",
                     "esc_temp1", "esc_temp2", "esc_temp3", "esc_temp4")
ESC_CHANNEL_UNITS = ("rpm",) * 4 + ("A",) * 4 + ("degC",) * 4
ESC_RATE_OF = {n: RATE_GROUP[n] for n in ESC_CHANNEL_NAMES}  # core.channels: the esc group
POLE_PAIRS = 7  # 14-pole outrunner (2212 / 2216 class)
ERPM_STEP = 100.0  # eRPM per telemetry unit (BLHeli_32 / KISS ESC telemetry frame)
ESC_CUR_NOISE_A = 0.1  # A, white, per telemetry sample
ESC_CUR_GAIN = 0.05  # +-: per-ESC current gain error (ESC current sensing is uncalibrated)
ESC_CUR_STEP_A = 0.01  # A per telemetry unit


def esc_noise(seed: int, idx: np.ndarray, n_rec: int) -> tuple[np.ndarray, np.ndarray]:
    """Per flight, from its own stream: white current noise (n_rec, B, 4) and gain errors (B, 4)."""
    gens = [np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(ESC_SPAWN, int(i)))) for i in idx]
    gain = np.stack([g.uniform(-ESC_CUR_GAIN, ESC_CUR_GAIN, 4) for g in gens])
    white = np.stack([g.standard_normal((n_rec, 4)) for g in gens], axis=1)
    return white, 1.0 + gain


def rpm_of(F: np.ndarray, cut: np.ndarray) -> np.ndarray:
    """Reported rpm (.., 4) of rotors making thrust F [N] with blade cut fraction ``cut``."""
    omega = propeller.rotor_speed(F, propeller.thrust_factor(cut))
    rpm = omega * (60.0 / (2.0 * np.pi))
    step = ERPM_STEP / POLE_PAIRS
    return np.round(rpm / step) * step


def esc_current(F: np.ndarray, cut: np.ndarray, V: np.ndarray) -> np.ndarray:
    """True motor current (.., 4) [A]: electrical power c_P (rho_Q / rho_T^1.5) F^1.5 over the bus voltage V (..)."""
    rT, rQ = propeller.thrust_factor(cut), propeller.torque_factor(cut)
    Fp = np.maximum(F, 0.0)
    return P.NOMINAL.c_P * (rQ / (rT * np.sqrt(rT))) * Fp * np.sqrt(Fp) / V[..., None]


def esc_series(F: np.ndarray, cut: np.ndarray, V: np.ndarray, white: np.ndarray,
               gain: np.ndarray, true_cur: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The rpm and current channels at the 50 Hz record, name -> (n_rec, B): F (n_rec, B, 4) produced
    thrust, cut (n_rec, B, 4), V (n_rec, B) bus voltage, noise from ``esc_noise``; ``true_cur``:
    ``esc_current(F, cut, V)`` if the caller has it."""
    rpm = rpm_of(F, cut)
    true_cur = esc_current(F, cut, V) if true_cur is None else true_cur
    cur = true_cur * gain[None] + ESC_CUR_NOISE_A * white
    cur = np.round(cur / ESC_CUR_STEP_A) * ESC_CUR_STEP_A
    out = {f"rpm{k + 1}": rpm[..., k] for k in range(4)}
    out.update({f"esc_cur{k + 1}": cur[..., k] for k in range(4)})
    return out
