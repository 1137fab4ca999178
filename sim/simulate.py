"""Closed-loop flights with progressive faults, batch by batch: ``simulate_batch`` and ``generate``.

``generate(cfg, indices)`` simulates trajectories in chunks of ``cfg.chunk`` (one vectorised
batch each): per trajectory the random draws (``sim.draws``), the class and split
(``sim.assign``, a function of the seed and n_traj only), the flight (``sim.dynamics``), then
the sensors (Eq. 9, ``sim.sensors``). The physics is elementwise over the batch and every
trajectory has its own generator, so simulating any subset of indices, in any chunking, gives
bit-identical rows.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from quadfdi.sim.config import SimConfig
from quadfdi.core.errors import QuadfdiError
from quadfdi.sim import faults, reference, sensors
from quadfdi.sim.assign import assign
from quadfdi.sim.draws import draw_trajectory
from quadfdi.sim.dynamics import FaultSchedule, Samples, initial_state, integrate
from quadfdi.sim.params import VehicleParams, get_vehicle


def fault_schedule(draws: list[dict], fault_class: np.ndarray) -> FaultSchedule:
    """The fault of every trajectory of a batch; a healthy one gets s_max = 0."""
    B = len(draws)
    cls = np.asarray(fault_class)
    healthy = cls == faults.HEALTHY
    onehot = np.zeros((B, 4))
    onehot[np.arange(B), [d["motor"] for d in draws]] = 1.0
    return FaultSchedule(
        onset=np.where(healthy, 0.0, [d["onset"] for d in draws]),
        ramp=np.where(healthy, 1.0, [d["ramp"] for d in draws]),
        s_max=np.where(healthy, 0.0, [d["s_max"] for d in draws]),
        is_b=(cls == faults.BATTERY).astype(np.float64),
        is_m=(cls == faults.MOTOR).astype(np.float64),
        is_h=(cls == faults.OVERHEAT).astype(np.float64),
        onehot=onehot,
    )


def _batch_major(rec: Samples, vp: VehicleParams) -> dict[str, np.ndarray]:
    def bt(a: np.ndarray) -> np.ndarray:  # (T, B, ...) -> (B, T, ...)
        return np.ascontiguousarray(np.moveaxis(a, 0, 1))

    X = bt(rec.x)
    # STATE_NAMES order: p, v, eta, omega, SoC, V_b, I_b, T1..T4
    states = np.concatenate([X[..., 0:13], bt(rec.V_b)[..., None], bt(rec.I_b)[..., None], X[..., 13:17]],
                            axis=-1)
    return {
        "states": states,
        "throttle": bt(rec.F_cmd) / vp.F_max,
        "effectiveness": bt(rec.eff),
        "thrust_act": bt(rec.F_act),
        "cooling": bt(rec.h_m),
        "fault_heat": bt(rec.Q_f),
        "r_int": bt(rec.R_int),
        "c_eff": bt(rec.C_eff),
        "kappa_v": bt(rec.kappa),
        "reference": bt(rec.ref),
        "battery_limited": rec.n_limited,
    }


def simulate_batch(draws: list[dict], fault_class: np.ndarray, cfg: SimConfig,
                   vp: VehicleParams) -> dict[str, np.ndarray]:
    """Integrate one batch of closed-loop flights; true per-sample quantities (float64).

    draws: ``draw_trajectory`` outputs; fault_class: (batch,) int. Returns a dict of arrays with a
    leading (batch, T) shape: states (B, T, 19), throttle (B, T, 4), effectiveness, thrust_act,
    cooling, fault_heat (B, T, 4), r_int, c_eff, kappa_v (B, T), reference (B, T, 4),
    battery_limited (B,).
    """
    ref = reference.prepare([d["ref"] for d in draws])
    t_amb = np.array([d["t_amb"] for d in draws])[:, None]  # (B, 1)
    x0, V0 = initial_state(draws, ref, vp)
    rec = integrate(x0, V0, ref, fault_schedule(draws, fault_class), t_amb, cfg, vp)
    return _batch_major(rec, vp)


def _indices(cfg: SimConfig, indices: Sequence[int] | None) -> np.ndarray:
    if indices is None:
        return np.arange(cfg.n_traj, dtype=np.int64)
    idx = np.asarray(list(indices), dtype=np.int64).reshape(-1)
    if idx.size == 0:
        raise QuadfdiError("sim: no trajectory indices to simulate")
    bad = idx[(idx < 0) | (idx >= cfg.n_traj)]
    if bad.size:
        raise QuadfdiError(
            f"sim: trajectory index {int(bad[0])} is outside 0..{cfg.n_traj - 1} (sim.n_traj={cfg.n_traj})")
    return idx


def _simulate_chunk(cfg: SimConfig, vp: VehicleParams, chunk: np.ndarray, cls: np.ndarray, split: np.ndarray,
                    time: np.ndarray) -> dict[str, np.ndarray]:
    """The per-trajectory dataset arrays of trajectories ``chunk`` (classes ``cls``, splits ``split``)."""
    draws = [draw_trajectory(cfg, vp, int(i)) for i in chunk]
    true = simulate_batch(draws, cls, cfg, vp)
    truth = sensors.truth_channels(true["states"], true["throttle"])
    y, _ = sensors.measure(truth, np.stack([d["noise"] for d in draws]), np.stack([d["incr"] for d in draws]),
                           vp, cfg.sample_dt_s)
    healthy = cls == faults.HEALTHY
    motor_fault = (cls == faults.MOTOR) | (cls == faults.OVERHEAT)
    onset = np.where(healthy, np.nan, [d["onset"] for d in draws])
    ramp = np.where(healthy, np.nan, [d["ramp"] for d in draws])
    s_max = np.where(healthy, 0.0, [d["s_max"] for d in draws])
    sev = faults.severity(time[None, :], np.nan_to_num(onset)[:, None], np.nan_to_num(ramp, nan=1.0)[:, None],
                          s_max[:, None])  # (B, T)
    reached = sev >= cfg.severity_threshold
    det = np.where(reached.any(axis=1), time[np.argmax(reached, axis=1)], np.nan)
    return {
        "telemetry": y.astype(np.float32),
        "states": true["states"].astype(np.float32),
        "severity": sev.astype(np.float32),
        "fault_class": cls.astype(np.int8),
        "onset_s": onset.astype(np.float64),
        "ramp_s": ramp.astype(np.float64),
        "severity_max": s_max.astype(np.float64),
        "fault_motor": np.where(motor_fault, [d["motor"] for d in draws], -1).astype(np.int8),
        "detectable_s": det,
        "split": split.astype(np.int8),
        "traj_index": chunk.astype(np.int64),
        "effectiveness": true["effectiveness"].astype(np.float32),
        "thrust_act": true["thrust_act"].astype(np.float32),
        "cooling": true["cooling"].astype(np.float32),
        "fault_heat": true["fault_heat"].astype(np.float32),
        "r_int": true["r_int"].astype(np.float32),
        "c_eff": true["c_eff"].astype(np.float32),
        "kappa_v": true["kappa_v"].astype(np.float32),
        "reference": true["reference"].astype(np.float32),
        "t_amb": np.array([d["t_amb"] for d in draws], dtype=np.float64),
        "battery_limited": true["battery_limited"].astype(np.int32),
    }


def generate(cfg: SimConfig, indices: Sequence[int] | None = None,
             progress: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """Simulate trajectories ``indices`` (all of 0..n_traj-1 when None) and return the dataset arrays.

    Processed in chunks of ``cfg.chunk`` trajectories (one vectorised batch each);
    ``progress(n)`` is called after each chunk with the number of trajectories it held.
    Row j of every per-trajectory array is trajectory ``indices[j]``, bit-identical to its row in
    any other run with the same config (n_traj included) and seed.

    Keys (n = len(indices), T = cfg.n_samples, S = 19 states):
      telemetry (n, T, 23) float32   noisy telemetry y (Eq. 9), channels CHANNEL_NAMES
      time (T,) float64              k * sample_dt_s
      channel_names, channel_units (23,) str;  state_names, state_units (S,) str
      states (n, T, S) float32       true x (Eq. 1) + I_b at the samples
      severity (n, T) float32        the active fault's s_k(t) (Eq. 6); 0 for healthy
      fault_class (n,) int8          0 Healthy, 1 Battery, 2 Motor, 3 Overheat
      onset_s, ramp_s (n,) float64   t_on, T_r [s]; NaN for healthy
      severity_max (n,) float64      s_max; 0 for healthy
      fault_motor (n,) int8          0..3 for motor and overheat faults, else -1
      detectable_s (n,) float64      first sample time with severity >= threshold; NaN if none
      split (n,) int8                0 train, 1 validation, 2 test (sim.assign)
      traj_index (n,) int64          i
      severity_threshold () float64  cfg.severity_threshold
      effectiveness (n, T, 4) float32   c_i d_m;  thrust_act (n, T, 4) float32 F_act [N]
      cooling (n, T, 4) float32 h_m [W/K];  fault_heat (n, T, 4) float32 Q_f [W]
      r_int (n, T) float32 [Ohm];  c_eff (n, T) float32 [A h];  kappa_v (n, T) float32 [-]
      reference (n, T, 4) float32  x, y, z [m] and yaw [rad] references
      t_amb (n,) float64 [degC];  battery_limited (n,) int32 steps at the battery clamp
    """
    cfg.validate()
    if cfg.scenario == "realistic":  # the realistic suite (docs/realistic.md); the paper path below is untouched
        from quadfdi.sim.realistic import generate as generate_realistic

        return generate_realistic(cfg, indices, progress)
    if cfg.scenario == "fleet":  # the fleet suite (docs/fleet.md): the realistic physics, vehicles flown many times
        from quadfdi.sim.fleet import generate as generate_fleet

        return generate_fleet(cfg, indices, progress)
    vp = get_vehicle(cfg.vehicle)
    idx = _indices(cfg, indices)
    cls_all, split_all = assign(cfg.seed, cfg.n_traj, cfg.fault_ratio, cfg.split)
    time = np.arange(cfg.n_samples, dtype=np.float64) * cfg.sample_dt_s

    parts: list[dict[str, np.ndarray]] = []
    for start in range(0, idx.size, cfg.chunk):
        chunk = idx[start:start + cfg.chunk]
        parts.append(_simulate_chunk(cfg, vp, chunk, cls_all[chunk], split_all[chunk], time))
        if progress is not None:
            progress(int(chunk.size))

    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    out["time"] = time
    out["channel_names"] = np.array(sensors.CHANNEL_NAMES)
    out["channel_units"] = np.array(sensors.CHANNEL_UNITS)
    out["state_names"] = np.array(sensors.STATE_NAMES)
    out["state_units"] = np.array(sensors.STATE_UNITS)
    out["severity_threshold"] = np.array(cfg.severity_threshold, dtype=np.float64)
    return out
