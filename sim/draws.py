"""Per-trajectory random draws: everything random about one flight, from its own generator.

Trajectory i draws its reference, initial state, fault timing and size, faulty motor and unit
sensor noise from ``default_rng(SeedSequence(seed, spawn_key=(TRAJ_SPAWN, i)))``, in the fixed
order of ``DRAW_ORDER``, and nothing else draws from that generator. So the numbers of trajectory
i depend only on (seed, i) and the config, never on which other trajectories are simulated with
it. Fault class and split are not drawn here: ``sim.assign`` fixes them from (seed, n_traj).
"""

from __future__ import annotations

import numpy as np

from quadfdi.sim.config import SimConfig
from quadfdi.sim import reference, sensors
from quadfdi.sim.params import VehicleParams

TRAJ_SPAWN = 1  # spawn_key = (TRAJ_SPAWN, i) for trajectory i; sim.assign uses (0xA55,)

# Initial-condition ranges (uniform), around the reference at t = 0.
INIT_POS_XY_M = 0.5  # m: +- horizontal offset from the reference
INIT_POS_Z_M = 0.3  # m: +- altitude offset
INIT_VEL_MS = 0.3  # m/s: +- velocity offset per axis
INIT_TILT_RAD = 0.08  # rad: +- roll and pitch (4.6 deg)
INIT_YAW_RAD = 0.05  # rad: +- heading offset from the reference
INIT_RATE_RADS = 0.1  # rad/s: +- body rates (larger ones make a 0.1 s throttle spike at t = 0)
INIT_SOC = (0.55, 1.0)  # -: a flight somewhere in its first half
INIT_WARM = (0.4, 1.0)  # -: motors this far from ambient to their healthy hover steady state
INIT_TEMP_JITTER_K = 1.0  # K: +- per-motor spread

DRAW_ORDER = (
    "reference (sim.reference.draw)",
    "initial state: dp(3), dv(3), droll, dpitch, dyaw, omega(3), SoC0, T_amb, warm, jitter(4)",
    "fault: onset fraction, ramp fraction, s_max, motor index (drawn for every class)",
    "sensors: unit noise (T, 23), unit bias increments (T-1, 23) (sim.sensors.draw_unit)",
)


def trajectory_rng(seed: int, i: int) -> np.random.Generator:
    """The generator of trajectory i: everything random about it comes from here."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(TRAJ_SPAWN, int(i))))


def draw_trajectory(cfg: SimConfig, vp: VehicleParams, i: int) -> dict:
    """All random quantities of trajectory i, drawn in the fixed ``DRAW_ORDER``.

    The fault draws are made for every trajectory, healthy ones included, so that a trajectory's
    sensor noise does not depend on its class."""
    rng = trajectory_rng(cfg.seed, i)
    ref = reference.draw(rng)
    init = np.concatenate([
        rng.uniform(-1.0, 1.0, 3) * np.array([INIT_POS_XY_M, INIT_POS_XY_M, INIT_POS_Z_M]),
        rng.uniform(-INIT_VEL_MS, INIT_VEL_MS, 3),
        rng.uniform(-1.0, 1.0, 3) * np.array([INIT_TILT_RAD, INIT_TILT_RAD, INIT_YAW_RAD]),
        rng.uniform(-INIT_RATE_RADS, INIT_RATE_RADS, 3),
    ])  # (12,) offsets of p, v, eta, omega
    soc0 = rng.uniform(*INIT_SOC)
    t_amb = rng.uniform(*vp.T_amb_range)
    warm = rng.uniform(*INIT_WARM)
    jitter = rng.uniform(-INIT_TEMP_JITTER_K, INIT_TEMP_JITTER_K, 4)
    onset = rng.uniform(*cfg.onset_frac) * cfg.duration_s
    ramp = rng.uniform(*cfg.ramp_frac) * cfg.duration_s
    s_max = rng.uniform(*cfg.severity_max)
    motor = int(rng.integers(0, 4))
    noise, incr = sensors.draw_unit(rng, cfg.n_samples)
    return {"ref": ref, "init": init, "soc0": soc0, "t_amb": t_amb, "warm": warm, "jitter": jitter,
            "onset": onset, "ramp": ramp, "s_max": s_max, "motor": motor, "noise": noise, "incr": incr}
