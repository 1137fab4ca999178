"""What a flight controller logs, from the realistic suite's 50 Hz record, through the ingest resampler.

Channel by channel (the paper's 23 plus the two vibration metrics), each group at a logging rate
drawn per flight from the rates real logs have (sim.realistic_params.LOG_HZ_MEASURED, ``log_rates``):
position and velocity of the estimate (``pos``), attitude of the estimate (``att``, yaw wrapped to
(-pi, pi]), body rates (``rate``), V_b, I_b and SoC (``batt``), motor temperatures (``esc``), motor
outputs u (``act``), vib_px4 (PX4's vehicle_imu_status) and vib_ap (ArduPilot's VIBE). A log sample
at rate r is the record sample nearest k / r (the logger writes the latest message: up to 10 ms of
timestamp jitter at 20 Hz, as in real logs).
Every channel then goes through ``core.resample.resample`` onto the 25 Hz grid, the function
real PX4/ArduPilot logs go through (anti-alias low-pass for channels above 25 Hz, linear
interpolation otherwise), so simulated and real flights reach the models the same way.

SoC is the flight controller's coulomb counter, as PX4's battery estimator does it: a voltage-based
guess at boot (the rest voltage per cell, inverted through the cell OCV curve), minus the integrated
measured current over the pack's LABEL capacity. It does not know the capacity fade of an aged or
faulty pack: that shows as voltage falling faster than the counted SoC says.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from quadfdi.core.channels import RATE_GROUP
from quadfdi.core.frames import wrap
from quadfdi.core.resample import resample
from quadfdi.sim import battery, propeller, sensors
from quadfdi.sim import realistic_params as P

CHANNEL_NAMES = sensors.CHANNEL_NAMES + ("vib_px4", "vib_ap")
CHANNEL_UNITS = sensors.CHANNEL_UNITS + ("m/s^2", "m/s^2")
RATE_OF = {c: RATE_GROUP[c] for c in CHANNEL_NAMES}
SENSOR_SPAWN = 4  # spawn_key (4, i): flight i's ADC/thermistor noise


def sensor_noise(seed: int, idx: np.ndarray, n_rec: int) -> np.ndarray:
    """(n_rec, B, 16) standard normals per flight: 8 white noises (V, I, T1-4, vib_px4, vib_ap), 8 walk increments."""
    return np.stack([np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(SENSOR_SPAWN, int(i))))
                     .standard_normal((n_rec, 16)) for i in idx], axis=1)


def _lag(x: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """First-order low-pass along axis 0 (time), started at its first value."""
    a = np.exp(-dt / tau)
    y, _ = lfilter([1 - a], [1, -a], x, axis=0, zi=a * x[:1])
    return y


def soc_inverse(v_cell: np.ndarray) -> np.ndarray:
    """SoC of a rest voltage per cell (the OCV curve inverted; it is strictly increasing)."""
    xp, fp = np.array(P.NOMINAL.ocv_soc), np.array(P.NOMINAL.ocv_volt) / 3.0
    return np.interp(v_cell, fp, xp)


def coulomb_soc(I_meas: np.ndarray, E_boot: np.ndarray, cells: np.ndarray, C_label: np.ndarray,
                dt: float) -> np.ndarray:
    """SoC estimate (n_rec, B): soc_inverse(E_boot / cells) - int I dt / (3600 C_label)."""
    boot = soc_inverse(E_boot / cells)
    used = np.concatenate([np.zeros((1, I_meas.shape[1])), np.cumsum(I_meas[:-1] * dt, axis=0)])
    return boot - used / (3600.0 * C_label)


def vibration(F: np.ndarray, cut: np.ndarray, residual_g: np.ndarray, mass: np.ndarray, floor: np.ndarray,
              dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Logged-metric values (n_rec, B) of vib_px4 and vib_ap before their sampling noise: the closed forms
    of sim.propeller, through PX4's EMA (time constant 1 / (alpha f_integ) = 0.5 s) and ArduPilot's
    2 Hz low-pass of the squared deviation. The healthy floor (B,) is the hover level: it scales with the
    mean rotor thrust over the hover thrust (the broadband rotor forcing grows as Omega^2 ~ thrust, as
    the imbalance force does), so a climb or a gust shakes the IMU more, as on the real quads, whose
    metric follows their throttle (docs/params.md "Vibration floor")."""
    rT = propeller.thrust_factor(cut)
    A, f = propeller.accel_amplitude(F, rT, propeller.imbalance_kgm(cut, residual_g), mass[..., None])
    load = np.clip(F.mean(-1) / (mass * P.NOMINAL.g / 4.0), 0.0, None)
    px4, ap = propeller.metrics(A, f, floor * load)
    px4 = _lag(px4, 1.0 / (P.PX4_VIB_ALPHA * P.IMU_INTEG_HZ), dt)
    ap = np.sqrt(_lag(ap * ap, 1.0 / (2 * np.pi * P.AP_VIBE_HZ), dt))
    return px4, ap


def log_rates(seed: int, idx: np.ndarray) -> dict[str, np.ndarray]:
    """Per channel group, the (B,) logging rates of flights ``idx``: each drawn uniformly from the group's
    measured rates (from flight i's own stream, in group order), capped at the record rate."""
    out = {g: np.empty(len(idx)) for g in P.LOG_HZ_MEASURED}
    for b, i in enumerate(idx):
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(P.RATES_SPAWN, int(i))))
        for g, rates in P.LOG_HZ_MEASURED.items():
            out[g][b] = min(rates[int(rng.integers(len(rates)))], P.RECORD_HZ)
    return out


def log_indices(n_rec: int, rate_hz: float) -> np.ndarray:
    """Record indices of a channel logged at rate_hz: nearest record sample to k / rate_hz."""
    k = np.arange(int(np.floor((n_rec - 1) / P.RECORD_HZ * rate_hz + 1e-9)) + 1)
    return np.floor(k * P.RECORD_HZ / rate_hz + 0.5).astype(np.int64)


def to_grid(series: dict[str, np.ndarray], grid: np.ndarray, rates: dict[str, np.ndarray],
            names: tuple[str, ...] = CHANNEL_NAMES, rate_of: dict[str, str] | None = None) -> np.ndarray:
    """Every channel ``names`` (name -> (n_rec, B) at RECORD_HZ) logged at its group's rate (``rate_of``,
    default RATE_OF; ``rates``: group -> (B,) Hz, ``log_rates``) and resampled onto grid:
    (B, len(grid), len(names)) float64. Each flight's channel is one ``resample`` call (the ingest API
    is per channel); NaN where the resampler masks (none when the record covers the grid)."""
    rate_of = RATE_OF if rate_of is None else rate_of
    n_rec, B = next(iter(series.values())).shape
    out = np.empty((B, len(grid), len(names)))
    for c, name in enumerate(names):
        for b in range(B):
            idx = log_indices(n_rec, float(rates[rate_of[name]][b]))
            v = series[name][idx, b]
            if name == "yaw":
                v = wrap(v)
            out[b, :, c] = resample(idx / P.RECORD_HZ, v, grid, angle=name == "yaw")[0]
    return out


def battery_rest_voltage(soc0: np.ndarray, cells: np.ndarray, delta0: np.ndarray) -> np.ndarray:
    """Open-circuit pack voltage at boot (weak cell delta0 of SoC below the others)."""
    vc = battery.ocv(soc0, P.NOMINAL) / 3.0
    return cells * vc - (vc - battery.ocv(soc0 - delta0, P.NOMINAL) / 3.0)
