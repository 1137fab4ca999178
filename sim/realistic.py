"""``generate`` of the realistic suite (``sim.scenario = "realistic"``; docs/realistic.md).

Flights: ``n_traj`` in distribution (split train / validation / test by ``sim.split``, classes by
``sim.assign`` over ``sim.classes``), then 4 x ``ood_traj`` out-of-distribution test flights, one
set per held-out factor: mission type, vehicle (frame and pack), wind range, incipient severity.
Their split codes are 3..6 (``split_names``); they never enter training or validation.

Per chunk of ``sim.chunk`` flights: draws (sim.variability), fault plan (sim.realistic_faults),
closed loop (sim.realistic_loop), then the logged telemetry (sim.telemetry). Every random number
of flight i comes from streams keyed (seed, i), so any subset or chunking gives the same rows.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from quadfdi.sim.config import SimConfig
from quadfdi.core.errors import QuadfdiError
from quadfdi.sim import esc_telemetry, esc_thermal, mission, propeller, sensors, telemetry
from quadfdi.sim import realistic_dynamics as rd
from quadfdi.sim import realistic_faults as rf
from quadfdi.sim import realistic_loop as rl
from quadfdi.sim import realistic_params as P
from quadfdi.sim.assign import ASSIGN_SPAWN_KEY, assign
from quadfdi.sim.variability import MODES, draw_flight, stack

SPLIT_NAMES = ("train", "validation", "test", "test_ood_mission", "test_ood_vehicle", "test_ood_wind",
               "test_incipient")
BATTERY_SUBMODES = ("resistance", "capacity_fade", "cell_imbalance")
FRAME_NAMES = ("plus", "x")
DrawFn = Callable[[int, int], dict]  # (flight index, test group) -> the flight's draws


def labels(cfg: SimConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Class (N,) int8, split code (N,) int8 and test group (N,) int8 of all N = n_traj + 4 ood_traj flights."""
    nc = len(cfg.classes)
    cls, split = assign(cfg.seed, cfg.n_traj, cfg.fault_ratio, cfg.split, nc)
    groups = [np.zeros(cfg.n_traj, np.int8)]
    for g in range(1, 5):
        if cfg.ood_traj == 0:
            break
        c, _ = assign(cfg.seed, cfg.ood_traj, cfg.fault_ratio, (0.0, 0.0, 1.0), nc, (*ASSIGN_SPAWN_KEY, g))
        cls = np.concatenate([cls, c])
        split = np.concatenate([split, np.full(cfg.ood_traj, 2 + g, np.int8)])
        groups.append(np.full(cfg.ood_traj, g, np.int8))
    return cls, split, np.concatenate(groups)


def n_flights(cfg: SimConfig) -> int:
    return cfg.n_traj + 4 * cfg.ood_traj


def _series(rec: rl.Record, fp: rf.FaultPlan, draws: list[dict], veh, noise: np.ndarray, t_rec: np.ndarray,
            dt: float) -> dict[str, np.ndarray]:
    """Every logged channel at the 50 Hz record, (n_rec, B), before the logger's decimation."""
    vp = rd.NOM
    walk = np.cumsum(noise[:, :, 8:] * np.sqrt(dt), axis=0)
    sig_n = np.array([vp.sens_vb[0], vp.sens_ib[0]] + [vp.sens_temp[0]] * 4)
    sig_b = np.array([vp.sens_vb[1], vp.sens_ib[1]] + [vp.sens_temp[1]] * 4)
    meas = np.concatenate([rec.V[..., None], rec.I[..., None], rec.x[..., 13:17]], -1) \
        + noise[..., :6] * sig_n + walk[..., :6] * sig_b
    d = stack(draws, ("soc0", "vib_floor", "imbalance_g"))
    s = rf.physical_severity(fp, t_rec)
    delta0 = P.IMBALANCE_CELL_SOC * s[0] * fp.kind[:, 1] * fp.submode[:, 2]
    E_boot = telemetry.battery_rest_voltage(d["soc0"], veh.cells, delta0)  # a weak cell present at boot
    soc = telemetry.coulomb_soc(meas[..., 1], E_boot, veh.cells, veh.C_label, dt)
    cut = propeller.cut_of_severity(s * fp.kind[:, 4])[..., None] * fp.onehot
    px4, ap = telemetry.vibration(rec.x[..., 17:21], cut, d["imbalance_g"], rec.mass, d["vib_floor"], dt)
    rel = 1.0 + P.VIB_REL_NOISE * noise[..., 6:8]
    out = {name: rec.est[..., j] for j, name in enumerate(sensors.CHANNEL_NAMES[:12])}
    out.update({"V_b": meas[..., 0], "I_b": meas[..., 1], "SoC": soc, "vib_px4": px4 * rel[..., 0],
                "vib_ap": ap * rel[..., 1]})
    out.update({f"T{i + 1}": meas[..., 2 + i] for i in range(4)})
    out.update({f"thr{i + 1}": rec.thr[..., i] for i in range(4)})
    return out


def _esc(rec: rl.Record, fp: rf.FaultPlan, draws: list[dict], seed: int, idx: np.ndarray, t_rec: np.ndarray,
         time: np.ndarray) -> np.ndarray:
    """ESC telemetry (sim.esc_telemetry, sim.esc_thermal) on the grid, (B, T, 12): their own noise and
    draw streams, after everything else."""
    s = rf.physical_severity(fp, t_rec)
    cut = propeller.cut_of_severity(s * fp.kind[:, 4])[..., None] * fp.onehot
    white, gain = esc_telemetry.esc_noise(seed, idx, len(t_rec))
    F, V = rec.x[..., 17:21].astype(np.float64), rec.V.astype(np.float64)
    I = esc_telemetry.esc_current(F, cut, V)
    series = esc_telemetry.esc_series(F, cut, V, white, gain, I)
    flight = stack(draws, ("t_amb", "wind_ms", "wind_dir"))
    series.update(esc_thermal.esc_temperatures(F, I, V, rec.x[..., 3:6].astype(np.float64), flight,
                                               esc_thermal.draw(seed, idx), float(t_rec[1] - t_rec[0])))
    return telemetry.to_grid(series, time, telemetry.log_rates(seed, idx), esc_telemetry.ESC_CHANNEL_NAMES,
                             esc_telemetry.ESC_RATE_OF)


def _states(rec: rl.Record, n: int) -> np.ndarray:
    """True STATE_NAMES at the 25 Hz grid (every second 50 Hz record), (B, n, 19)."""
    k = np.arange(n) * 2
    x = rec.x[k]
    st = np.concatenate([x[..., 0:13], rec.V[k][..., None], rec.I[k][..., None], x[..., 13:17]], -1)
    return np.ascontiguousarray(np.moveaxis(st, 0, 1))


def _chunk(cfg: SimConfig, idx: np.ndarray, cls: np.ndarray, split: np.ndarray, group: np.ndarray,
           time: np.ndarray, draw: DrawFn) -> dict[str, np.ndarray]:
    draws = [draw(int(i), int(g)) for i, g in zip(idx, group)]
    fp = rf.plan(draws, cfg.classes, cls, cfg.duration_s)
    rec = rl.integrate(draws, fp, cfg.seed, idx, cfg.duration_s, cfg.sim_dt_s)
    veh = rd.vehicle(draws)
    dt_rec = 1.0 / P.RECORD_HZ
    t_rec = np.arange(rec.x.shape[0]) * dt_rec
    noise = telemetry.sensor_noise(cfg.seed, idx, rec.x.shape[0])
    tel = telemetry.to_grid(_series(rec, fp, draws, veh, noise, t_rec, dt_rec), time, telemetry.log_rates(cfg.seed, idx))
    esc = _esc(rec, fp, draws, cfg.seed, idx, t_rec, time)
    if not (np.isfinite(tel).all() and np.isfinite(esc).all()):
        raise QuadfdiError("sim: a logged channel does not cover the telemetry grid (resampler mask)")
    sev = rf.label_severity(fp, time).T  # (B, T)
    reached = sev >= cfg.severity_threshold
    out = {
        "telemetry": tel.astype(np.float32), "esc_telemetry": esc.astype(np.float32), "states": _states(rec, len(time)).astype(np.float32),
        "severity": sev.astype(np.float32), "fault_class": cls.astype(np.int8), "split": split.astype(np.int8),
        "traj_index": idx.astype(np.int64), "test_group": group.astype(np.int8),
        "onset_s": np.where(fp.kind[:, 0] > 0, np.nan, np.maximum(fp.onset, 0.0)),
        "ramp_s": np.where(fp.kind[:, 0] > 0, np.nan, np.where(fp.mode == rf.TAKEOFF, 0.0, fp.ramp)),
        "severity_max": fp.s_max, "fault_motor": np.where(fp.onehot.any(1), fp.onehot.argmax(1), -1).astype(np.int8),
        "detectable_s": np.where(reached.any(1), time[np.argmax(reached, 1)], np.nan),
        "fault_mode": np.where(fp.kind[:, 0] > 0, -1, fp.mode).astype(np.int8),
        "battery_submode": np.where(fp.kind[:, 1] > 0, fp.submode.argmax(1), -1).astype(np.int8),
        "prop_cut_frac": propeller.cut_of_severity(fp.s_max * fp.kind[:, 4]),
        "battery_limited": rec.limited.astype(np.int32),
    }
    out.update(_flight_params(draws, veh))
    return out


def _flight_params(draws: list[dict], veh) -> dict[str, np.ndarray]:
    """Per-flight vehicle, pack, ambient, wind and mission parameters (dataset keys)."""
    d = stack(draws, ("mass", "payload_kg", "payload_t", "frame", "arm", "cells", "cg", "kf", "cool", "capacity",
                      "age", "soc0", "t_amb", "motor_tau", "vib_floor", "imbalance_g", "wind_ms", "wind_dir"))
    return {
        "mass_kg": d["mass"], "payload_kg": d["payload_kg"], "payload_t_s": np.where(np.isfinite(d["payload_t"]),
                                                                                     d["payload_t"], np.nan),
        "frame": d["frame"].astype(np.int8), "arm_m": d["arm"], "cg_offset_m": d["cg"], "thrust_coef_factor": d["kf"],
        "cooling_factor": d["cool"], "motor_tau_s": d["motor_tau"], "vib_floor_ms2": d["vib_floor"],
        "prop_imbalance_g": d["imbalance_g"], "pack_cells": d["cells"].astype(np.int8),
        "pack_capacity_ah": d["capacity"], "pack_age": d["age"], "pack_r_ohm": veh.R, "pack_c_true_ah": veh.C,
        "soc0": d["soc0"], "t_amb": d["t_amb"], "wind_ms": d["wind_ms"], "wind_dir_rad": d["wind_dir"],
        "mission_type": np.array([int(x["mission"]["kind"]) for x in draws], np.int8),
    }


def generate(cfg: SimConfig, indices: Sequence[int] | None = None,
             progress: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """The realistic dataset's arrays (docs/formats.md, "Realistic suite"); rows = ``indices``
    (default all n_traj + 4 ood_traj flights), each bit-identical to its row in any other run."""
    idx = row_indices(n_flights(cfg), indices, "n_traj + 4 ood_traj")
    cls_all, split_all, group_all = labels(cfg)
    out = simulate_rows(cfg, idx, (cls_all, split_all, group_all), lambda i, g: draw_flight(cfg, i, g), progress)
    out.update(name_tables(cfg, SPLIT_NAMES))
    return out


def row_indices(n: int, indices: Sequence[int] | None, what: str) -> np.ndarray:
    """``indices`` as int64 (default 0..n-1), each checked to lie in 0..n-1."""
    idx = np.arange(n, dtype=np.int64) if indices is None else np.asarray(list(indices), np.int64).reshape(-1)
    if idx.size == 0 or idx.min() < 0 or idx.max() >= n:
        raise QuadfdiError(f"sim: trajectory indices must lie in 0..{n - 1} ({what})")
    return idx


def simulate_rows(cfg: SimConfig, idx: np.ndarray, lab: tuple[np.ndarray, np.ndarray, np.ndarray], draw: DrawFn,
                  progress: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """The per-flight arrays of rows ``idx``, chunk by chunk; ``lab`` = (class, split, group) of every
    flight, ``draw(i, group)`` flight i's draws (sim.variability.draw_flight's dict)."""
    cls_all, split_all, group_all = lab
    time = np.arange(cfg.n_samples, dtype=np.float64) * cfg.sample_dt_s
    parts = []
    for start in range(0, idx.size, cfg.chunk):
        c = idx[start:start + cfg.chunk]
        parts.append(_chunk(cfg, c, cls_all[c], split_all[c], group_all[c], time, draw))
        if progress is not None:
            progress(int(c.size))
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    out["time"] = time
    return out


def name_tables(cfg: SimConfig, split_names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The dataset-wide arrays: channel, state, class, split and code names, the label threshold."""
    return {
        "channel_names": np.array(telemetry.CHANNEL_NAMES), "channel_units": np.array(telemetry.CHANNEL_UNITS),
        "esc_channel_names": np.array(esc_telemetry.ESC_CHANNEL_NAMES),
        "esc_channel_units": np.array(esc_telemetry.ESC_CHANNEL_UNITS),
        "state_names": np.array(sensors.STATE_NAMES), "state_units": np.array(sensors.STATE_UNITS),
        "severity_threshold": np.array(cfg.severity_threshold, dtype=np.float64),
        "class_names": np.array(cfg.classes), "split_names": np.array(split_names),
        "mission_names": np.array(mission.MISSION_TYPES), "fault_mode_names": np.array(MODES),
        "battery_submode_names": np.array(BATTERY_SUBMODES), "frame_names": np.array(FRAME_NAMES),
    }
