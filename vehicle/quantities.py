"""Per-sample quantities of one flight that a vehicle reference describes, on the 25 Hz grid, in
project rotor order (NaN where a channel is not logged or masked).

- motor command share: ``thr_k / mean(thr_1..4)``, the quantity a motor fault moves and the
  ``m*_rel`` model channels divide out; defined where all four commands are logged and spinning.
- forward speed ``cos(yaw) vx + sin(yaw) vy`` (the ``vx_h`` model channel) and yaw rate (``r``, or
  where a log has no body rates, as the Crazyflie's, the derivative of the unwrapped yaw).
- steady samples: core/hover.py's test (settled 2 s after a take-off, |vz| <= 0.5 m/s, |roll| and
  |pitch| <= 0.25 rad, collective >= 0.05), with 0 for a roll or pitch the log does not have.
- ESC shares (rpm, current: over the four's mean; temperature: minus the four's mean, K).
- motor temperature offsets (``T1..T4`` minus the four's mean, K): simulated flights only.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core import hover
from quadfdi.core.resample import GRID_DT
from quadfdi.vehicle.flights import Flight

ROTORS = range(1, 5)
CMD_MIN = float(hover.CMD_MIN)  # below it the motors are not spinning: no share


def motor_commands(fl: Flight) -> np.ndarray:
    """(T, 4) thr1..thr4."""
    return np.stack([fl.col(f"thr{k}") for k in ROTORS], axis=1)


def per_motor_ratio(x: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """(T, 4) -> (T, 4) each over the four's mean; NaN where one is missing or the mean is <= floor."""
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = x.mean(axis=1, keepdims=True)
        out = x / mean
    return np.where(np.isfinite(mean) & (mean > floor), out, np.nan)


def motor_shares(fl: Flight) -> np.ndarray:
    """(T, 4) command shares; NaN where a command is missing or the collective is below ``CMD_MIN``."""
    return per_motor_ratio(motor_commands(fl), CMD_MIN)


def share_samples(fl: Flight) -> np.ndarray:
    """(T,) bool: airborne with all four shares defined (the samples a flight's mean share rests on)."""
    return fl.airborne & np.isfinite(motor_shares(fl)).all(axis=1)


def _zero_if_absent(fl: Flight, name: str) -> np.ndarray:
    x = fl.col(name)
    return np.zeros_like(x) if not fl.usable(name) else x


def hover_columns(fl: Flight) -> np.ndarray:
    """(T, 8) core.hover.INPUTS; a roll or pitch the log does not carry (Crazyflie: no pitch) enters as 0,
    so the tilt test reads the axis that is logged."""
    cols = {n: fl.col(n) for n in hover.INPUTS}
    cols["roll"], cols["pitch"] = _zero_if_absent(fl, "roll"), _zero_if_absent(fl, "pitch")
    return np.stack([cols[n] for n in hover.INPUTS], axis=1).astype(np.float32)


def steady(fl: Flight) -> np.ndarray:
    """(T,) bool: core.hover's steady-sample test on this flight (airborne and settled included)."""
    return hover.steady(hover_columns(fl), fl.airborne)


def hover_estimate(fl: Flight) -> hover.Hover:
    return hover.estimate(hover_columns(fl), fl.airborne)


def forward_speed(fl: Flight) -> np.ndarray:
    """(T,) m/s along the heading; NaN without yaw or velocity."""
    yaw = fl.col("yaw")
    return np.cos(yaw) * fl.col("vx") + np.sin(yaw) * fl.col("vy")


def yaw_rate(fl: Flight) -> tuple[np.ndarray, str]:
    """(T,) rad/s and where it came from: ``r`` when logged, else the central difference of the unwrapped
    yaw over one grid step each side (NaN where either neighbour is missing), else all NaN."""
    if fl.usable("r"):
        return fl.col("r"), "r"
    yaw = fl.col("yaw")
    out = np.full_like(yaw, np.nan)
    if len(yaw) >= 3:
        d = yaw[2:] - yaw[:-2]
        d = (d + np.pi) % (2 * np.pi) - np.pi  # unwrap the step across +-pi
        out[1:-1] = d / (2 * GRID_DT)
    return out, ("d(yaw)/dt (no body rates logged)" if fl.usable("yaw") else "none (neither r nor yaw logged)")


def esc_quantities(fl: Flight) -> dict[str, tuple[np.ndarray, str]]:
    """ESC telemetry the flight logs: name -> ((T, 4), unit). rpm and current as shares of the four's mean,
    temperature as the difference from the four's mean (a ratio of temperatures in degC means nothing)."""
    out: dict[str, tuple[np.ndarray, str]] = {}
    for key, prefix in (("rpm_share", "rpm"), ("current_share", "esc_cur")):
        if all(fl.usable(f"{prefix}{k}") for k in ROTORS):
            out[key] = (per_motor_ratio(np.stack([fl.col(f"{prefix}{k}") for k in ROTORS], axis=1)), "-")
    if all(fl.usable(f"esc_temp{k}") for k in ROTORS):
        t = np.stack([fl.col(f"esc_temp{k}") for k in ROTORS], axis=1)
        out["temp_offset"] = (t - t.mean(axis=1, keepdims=True), "K")
    return out


def motor_temp_offsets(fl: Flight) -> np.ndarray | None:
    """(T, 4) each motor's temperature minus the four's mean (K), or None when T1..T4 are not all logged
    (a real log never has them: only the simulator models the motor windings' temperature)."""
    if not all(fl.usable(f"T{k}") for k in ROTORS):
        return None
    t = np.stack([fl.col(f"T{k}") for k in ROTORS], axis=1)
    return t - t.mean(axis=1, keepdims=True)
