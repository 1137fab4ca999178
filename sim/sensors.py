"""Telemetry channels and the measurement model (paper Eq. 9).

    y(t_k) = C x(t_k) + b(t_k) + n(t_k),   n ~ N(0, Sigma_n),
    b(t_k) = b(t_{k-1}) + sqrt(dt) eps_k,   eps_k ~ N(0, Sigma_b),   b(t_0) = 0

with diagonal Sigma_n and Sigma_b (one noise std and one bias random-walk std per channel, from
the vehicle's ``sens_*`` fields; the walk's std is per sqrt(second), so the bias after 16 s has
std 4 sigma_b). C selects the 23 telemetry channels from the true per-sample quantities: the
Eq. (1) state, the bus current, and the motor commands as throttle fractions F_cmd / F_max (what
PX4 logs as actuator_outputs). b starts at zero: each flight begins right after an estimator
reset. Telemetry channels and true states are exported as names and units.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.channels import SIM_CHANNEL_NAMES, SIM_CHANNEL_UNITS
from quadfdi.sim.params import VehicleParams

CHANNEL_NAMES = SIM_CHANNEL_NAMES
CHANNEL_UNITS = SIM_CHANNEL_UNITS
N_CHANNELS = len(CHANNEL_NAMES)  # 23

# True augmented state per sample (Eq. 1 plus the algebraic bus current I_b).
STATE_NAMES = (
    "x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r",
    "SoC", "V_b", "I_b", "T1", "T2", "T3", "T4",
)
STATE_UNITS = (
    "m", "m", "m", "m/s", "m/s", "m/s", "rad", "rad", "rad", "rad/s", "rad/s", "rad/s",
    "-", "V", "A", "degC", "degC", "degC", "degC",
)

# C of Eq. (9): telemetry channel j reads STATE_NAMES[_STATE_OF_CHANNEL[j]]; -1 = throttle (input).
_STATE_OF_CHANNEL = tuple(STATE_NAMES.index(c) if c in STATE_NAMES else -1 for c in CHANNEL_NAMES)

# channel -> VehicleParams field holding (noise std, bias walk std per sqrt(s))
_SENSOR_GROUP = {
    "x": "sens_pos_xy", "y": "sens_pos_xy", "z": "sens_pos_z",
    "vx": "sens_vel", "vy": "sens_vel", "vz": "sens_vel",
    "roll": "sens_att", "pitch": "sens_att", "yaw": "sens_att",
    "p": "sens_rate", "q": "sens_rate", "r": "sens_rate",
    "V_b": "sens_vb", "I_b": "sens_ib", "SoC": "sens_soc",
    "T1": "sens_temp", "T2": "sens_temp", "T3": "sens_temp", "T4": "sens_temp",
    "thr1": "sens_thr", "thr2": "sens_thr", "thr3": "sens_thr", "thr4": "sens_thr",
}


def sigmas(vp: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel noise std and bias random-walk std (per sqrt(s)), each (23,)."""
    pairs = np.array([getattr(vp, _SENSOR_GROUP[c]) for c in CHANNEL_NAMES], dtype=np.float64)
    return pairs[:, 0].copy(), pairs[:, 1].copy()


def draw_unit(rng: np.random.Generator, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """One trajectory's standard-normal draws: noise (T, 23), bias increments (T-1, 23).
    (The last part of a trajectory's fixed draw order; scaled by ``measure``.)"""
    noise = rng.standard_normal((n_samples, N_CHANNELS))
    incr = rng.standard_normal((n_samples - 1, N_CHANNELS))
    return noise, incr


def truth_channels(states: np.ndarray, throttle: np.ndarray) -> np.ndarray:
    """C x: the noise-free telemetry, (n, T, 23), from states (n, T, 19) and throttle (n, T, 4)."""
    cols = [throttle[..., int(c[3]) - 1] if j < 0 else states[..., j]
            for j, c in zip(_STATE_OF_CHANNEL, CHANNEL_NAMES)]
    return np.stack(cols, axis=-1)


def bias(unit_incr: np.ndarray, sigma_b: np.ndarray, dt: float) -> np.ndarray:
    """Random-walk bias b, (n, T, 23), from unit increments (n, T-1, 23); b[:, 0] = 0."""
    n, tm1, c = unit_incr.shape
    b = np.zeros((n, tm1 + 1, c))
    np.cumsum(unit_incr * (np.sqrt(dt) * sigma_b), axis=1, out=b[:, 1:])
    return b


def measure(truth: np.ndarray, unit_noise: np.ndarray, unit_incr: np.ndarray, vp: VehicleParams,
            dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (9): y = C x + b + n. truth (n, T, 23); unit_noise (n, T, 23); unit_incr (n, T-1, 23).
    Returns y (n, T, 23) float64 and the bias b (n, T, 23)."""
    sigma_n, sigma_b = sigmas(vp)
    b = bias(unit_incr, sigma_b, dt)
    return truth + b + unit_noise * sigma_n, b
