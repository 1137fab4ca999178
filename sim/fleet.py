"""``generate`` of the fleet suite (``sim.scenario = "fleet"``; docs/fleet.md).

Every vehicle flies ``sim.flights_per_vehicle`` (F) flights, rows vehicle after vehicle: flight i is
flight i mod F of vehicle i // F. Its first ``sim.reference_flights`` (R) are healthy (the
reference flights); the later ones get classes by ``sim.fault_ratio`` with exact counts per split
(sim.assign, its own spawn key per split). Splits are by vehicle: ``n_traj / F`` vehicles in
distribution, split train / validation / test by ``sim.split`` as whole vehicles, then
``ood_traj / F`` test vehicles per out-of-distribution set: the realistic suite's four (mission,
vehicle, wind, incipient) and two held-out airframe sizes (250 and 650 mm, sim.fleet_params).

A vehicle (mass, frame, arm, pack type, CG, per-motor thrust, cooling and lag, vibration floor, prop
imbalance, thrust-to-weight, flap, mount twist) is drawn once from its own stream (FLEET_SPAWN, v);
each flight keeps the realistic suite's stream (2, i) for what changes between flights: the pack it
flies (age, so resistance and capacity, and the state of charge at boot), the payload, ambient,
wind, mission and fault. The closed loop, physics and logging are the realistic suite's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from quadfdi.sim import fleet_params as FP
from quadfdi.sim import realistic_params as P
from quadfdi.sim.assign import assign, split_counts
from quadfdi.sim.config import SimConfig
from quadfdi.sim.realistic import SPLIT_NAMES as REALISTIC_SPLITS
from quadfdi.sim.realistic import name_tables, row_indices, simulate_rows
from quadfdi.sim.variability import OOD_VEHICLE, draw_flight, draw_vehicle

SPLIT_NAMES = (*REALISTIC_SPLITS, "test_ood_size_250", "test_ood_size_650")
N_GROUPS = len(SPLIT_NAMES) - 3  # out-of-distribution sets, split codes 3..8, test groups 1..6
FLEET_SPAWN = 9  # spawn_key (9, v): vehicle v's draws (1..8 are taken; sim.realistic_params RATES_SPAWN 8)
ASSIGN_KEY = (0xF1E,)  # (0xF1E, 0): vehicles to splits; (0xF1E, 1, code): classes of that split's flights
VEHICLE_KEYS = ("mass", "frame", "arm", "cells", "cg", "kf", "cool", "capacity", "motor_tau", "vib_floor",
                "imbalance_g", "thrust_to_weight", "flap", "twist", "size", "airframe_class", "motor_R_w", "motor_c_F",
                "motor_heat")


def n_flights(cfg: SimConfig) -> int:
    return cfg.n_traj + N_GROUPS * cfg.ood_traj


def _classes(cfg: SimConfig, n: int, code: int) -> np.ndarray:
    """Classes of the n non-reference flights of one split: exact counts, permuted (sim.assign)."""
    if n == 0:
        return np.zeros(0, np.int8)
    return assign(cfg.seed, n, cfg.fault_ratio, (1.0, 0.0, 0.0), len(cfg.classes), (*ASSIGN_KEY, 1, code))[0]


def labels(cfg: SimConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Class, split code, test group (N,) int8 and the reference flag (N,) bool of all N flights."""
    F, R = cfg.flights_per_vehicle, cfg.reference_flights
    nv = cfg.n_traj // F
    codes = np.repeat(np.arange(3, dtype=np.int8), split_counts(nv, cfg.split))
    vsplit = np.empty(nv, np.int8)
    vsplit[np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(*ASSIGN_KEY, 0))).permutation(nv)] = codes
    n_ood = cfg.ood_traj // F
    vsplit = np.concatenate([vsplit] + [np.full(n_ood, 2 + g, np.int8) for g in range(1, N_GROUPS + 1)])
    split = np.repeat(vsplit, F)
    group = np.maximum(split - 2, 0).astype(np.int8)
    ref = np.tile(np.arange(F) < R, len(vsplit))
    cls = np.zeros(split.size, np.int8)
    for code in np.unique(split):
        rows = np.flatnonzero((split == code) & ~ref)
        cls[rows] = _classes(cfg, rows.size, int(code))
    return cls, split, group, ref


def vehicle_of(cfg: SimConfig, v: int, group: int) -> dict:
    """Vehicle v's draws (VEHICLE_KEYS): the realistic vehicle of its test group, then its airframe class."""
    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(FLEET_SPAWN, int(v))))
    veh = draw_vehicle(rng, OOD_VEHICLE if group == OOD_VEHICLE else 0, cfg.duration_s)
    veh["flap"] = float(rng.uniform(*P.FLAP_PER_MS))
    veh["twist"] = rng.uniform(-1.0, 1.0, 4) * math.radians(P.MOUNT_TWIST_DEG)
    veh = FP.scale_vehicle(veh, FP.CLASS_OF_GROUP.get(group, 0))
    return {k: veh[k] for k in VEHICLE_KEYS}


def draw_fleet_flight(cfg: SimConfig, i: int, group: int) -> dict:
    """Flight i's draws: the realistic flight (stream (2, i)) flown by its fleet vehicle."""
    d = draw_flight(cfg, i, group)
    veh = vehicle_of(cfg, i // cfg.flights_per_vehicle, group)
    lo, hi = FP.payload_range(veh["size"])
    if math.isfinite(d["payload_t"]):  # the flight's parcel, scaled to the class, inside its mass range
        d["payload_kg"] = float(np.clip(d["payload_kg"] * veh["size"] ** 2, lo - veh["mass"], hi - veh["mass"]))
    d.update(veh)
    return d


def generate(cfg: SimConfig, indices: Sequence[int] | None = None,
             progress: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """The fleet dataset's arrays: the realistic suite's keys (docs/formats.md) plus vehicle_id,
    vehicle_flight, reference_flight, airframe_class (and its names); rows = ``indices``."""
    idx = row_indices(n_flights(cfg), indices, "n_traj + 6 ood_traj")
    cls, split, group, ref = labels(cfg)
    out = simulate_rows(cfg, idx, (cls, split, group), lambda i, g: draw_fleet_flight(cfg, i, g), progress)
    F = cfg.flights_per_vehicle
    out.update({
        "vehicle_id": (idx // F).astype(np.int32), "vehicle_flight": (idx % F).astype(np.int16),
        "reference_flight": ref[idx], "airframe_class": np.array([FP.CLASS_OF_GROUP.get(int(g), 0) for g in group[idx]],
                                                                  np.int8),
    })
    out.update(name_tables(cfg, SPLIT_NAMES))
    out["airframe_class_names"] = np.array([c[0] for c in FP.AIRFRAME_CLASSES])
    return out
