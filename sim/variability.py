"""Per-flight draws of the realistic suite: vehicle, pack, ambient, wind, mission and fault.

Flight i draws everything here from ``default_rng(SeedSequence(seed, spawn_key=(FLIGHT_SPAWN, i)))``
in a fixed order; its in-flight noise (turbulence, state-estimate errors) comes from a second
stream, spawn_key (NOISE_SPAWN, i) (sim/realistic_dynamics.py), and its forward-flight rotor moment
then its motor mount twists from a third, spawn_key (AERO_SPAWN, i), added after the others so that
no earlier draw moved.
The paper's streams are
(1, i) (sim/draws.py) and (0xA55,) (sim/assign.py): none of them is touched.

``group`` is the flight's test group (sim/realistic_assign.py): 0 in distribution, 1 held-out
mission type, 2 held-out vehicle (frame and pack), 3 held-out wind range, 4 incipient severities.
Only the group's own quantity changes range; every other draw is the same function of the stream.
"""

from __future__ import annotations

import math

import numpy as np

from quadfdi.sim.config import SimConfig
from quadfdi.sim import mission
from quadfdi.sim import realistic_params as P

FLIGHT_SPAWN = 2
NOISE_SPAWN = 3
AERO_SPAWN = 7  # 4..6 are taken (sim.telemetry, sim.esc_telemetry, sim.esc_thermal)
OOD_MISSION, OOD_VEHICLE, OOD_WIND, OOD_INCIPIENT = 1, 2, 3, 4

# onset modes (fault_mode in dataset.npz)
MODES = ("progressive", "abrupt", "takeoff", "intermittent")


def flight_rng(seed: int, i: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(FLIGHT_SPAWN, int(i))))


def noise_rng(seed: int, i: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(NOISE_SPAWN, int(i))))


def _vehicle(rng: np.random.Generator, group: int, duration: float) -> dict:
    m0 = rng.uniform(*P.MASS_KG)
    has_payload = rng.uniform() < P.PAYLOAD_P
    dm = np.clip(rng.uniform(*P.PAYLOAD_KG), P.MASS_KG[0] - m0, P.MASS_KG[1] - m0) if has_payload else 0.0
    t_payload = rng.uniform(*P.PAYLOAD_T_FRAC) * duration if has_payload else np.inf
    frame = int(rng.integers(0, 2))
    cells = int(rng.choice(P.CELLS))
    arm = P.ARM_M
    if group == OOD_VEHICLE:
        frame, cells, arm = 1, P.OOD_CELLS, P.OOD_ARM_M
    return {
        "mass": m0, "payload_kg": dm, "payload_t": t_payload, "frame": frame, "arm": arm, "cells": cells,
        "cg": rng.uniform(-P.CG_OFFSET_M, P.CG_OFFSET_M, 2),
        "kf": 1.0 + rng.uniform(-P.KF_SPREAD, P.KF_SPREAD, 4),
        "cool": 1.0 + rng.uniform(-P.COOL_SPREAD, P.COOL_SPREAD, 4),
        "capacity": rng.uniform(*P.PACK_MASS_SHARE) * m0 * P.PACK_WH_PER_KG / (3.7 * cells),
        "age": rng.uniform(*P.AGE), "soc0": rng.uniform(*P.SOC_BOOT),
        "t_amb": rng.uniform(*P.T_AMB_C), "motor_tau": rng.uniform(*P.MOTOR_TAU_S, 4),
        # log-uniform, with libm's exp: numpy's AVX-512 exp rounds otherwise than AVX2 machines' (ISA-independent data)
        "vib_floor": math.exp(rng.uniform(math.log(P.VIB_FLOOR[0]), math.log(P.VIB_FLOOR[1]))),
        "imbalance_g": rng.uniform(*P.IMBALANCE_G, 4),
        "thrust_to_weight": rng.uniform(*P.THRUST_TO_WEIGHT),
    }


draw_vehicle = _vehicle  # the vehicle part alone (sim.fleet draws one per fleet vehicle from its own stream)


def _wind(rng: np.random.Generator, group: int, duration: float) -> dict:
    u = rng.uniform()
    lo, hi = P.OOD_WIND_MS if group == OOD_WIND else P.WIND_MS
    direction = rng.uniform(0, 2 * np.pi)
    gaps = rng.exponential(1.0 / P.GUST_RATE_HZ, P.GUST_MAX)
    return {
        "wind_ms": lo + (hi - lo) * u, "wind_dir": direction,
        "gust_t": np.cumsum(gaps), "gust_T": rng.uniform(*P.GUST_S, P.GUST_MAX),
        "gust_A": rng.uniform(*P.GUST_MS, P.GUST_MAX),
        "gust_dir": direction + rng.uniform(-np.pi / 6, np.pi / 6, P.GUST_MAX),
    }


def _fault(rng: np.random.Generator, cfg: SimConfig, group: int) -> dict:
    d = cfg.duration_s
    s_lo, s_hi = P.INCIPIENT_SMAX if group == OOD_INCIPIENT else cfg.severity_max
    out = {
        "onset": rng.uniform(*cfg.onset_frac) * d, "ramp": rng.uniform(*cfg.ramp_frac) * d,
        "s_max": rng.uniform(s_lo, s_hi), "motor": int(rng.integers(0, 4)),
        "mode_u": rng.uniform(), "submode": int(rng.integers(0, 3)), "snap_u": rng.uniform(),
        "snap_delay": rng.uniform(0.0, 1.0), "event_rate": rng.uniform(*P.EVENT_RATE_HZ),
    }
    out["event_gap"] = rng.exponential(1.0, P.N_EVENTS)  # unit-rate gaps, scaled by event_rate
    out["event_u"] = rng.uniform(size=P.N_EVENTS)  # event lengths within their class's range
    out["r_spike"] = rng.uniform(*P.R_SPIKE_OHM)
    return out


def draw_flight(cfg: SimConfig, i: int, group: int) -> dict:
    """Everything random about realistic flight i (in the fixed order vehicle, wind, mission, fault)."""
    rng = flight_rng(cfg.seed, i)
    d = _vehicle(rng, group, cfg.duration_s)
    d.update(_wind(rng, group, cfg.duration_s))
    kinds = (3,) if group == OOD_MISSION else mission.TRAIN_TYPES
    kind = int(kinds[int(rng.integers(0, len(kinds)))])
    d["mission"] = mission.draw(rng, kind)
    d.update(_fault(rng, cfg, group))
    aero = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(AERO_SPAWN, int(i))))
    d["flap"] = float(aero.uniform(*P.FLAP_PER_MS))
    d["twist"] = aero.uniform(-1.0, 1.0, 4) * math.radians(P.MOUNT_TWIST_DEG)  # after flap: flap unmoved
    d["group"] = group
    return d


def stack(draws: list[dict], keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The batch arrays of ``keys`` (leading axis = flight)."""
    return {k: np.stack([np.asarray(d[k], dtype=np.float64) for d in draws]) for k in keys}
