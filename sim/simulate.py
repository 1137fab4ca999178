"""Closed-loop flights with progressive faults: the augmented-state integrator and ``generate``.

Augmented integrated state (Eq. 1), (batch, 17): p (0:3) [m], v (3:6) [m/s], eta (6:9) [rad],
omega_B (9:12) [rad/s], SoC (12) [-], T_m (13:17) [degC]. V_b and I_b are algebraic (closed
form in ``battery.terminal`` at every evaluation), so they are outputs, not integrated states.

Integration: classic RK4 (weights 1/6, 1/3, 1/3, 1/6, stages at 0, h/2, h/2, h; not the 3/8
rule) at a fixed step ``cfg.sim_dt_s`` = 5 ms, ``cfg.substeps`` = 8 steps per 40 ms telemetry
sample. Why: the fastest closed-loop mode is the body-rate loop at ~25 rad/s (h * 25 = 0.125,
far inside RK4's stability region and with a local error ~1e-9), and a fixed step keeps every
trajectory of a batch on the same time grid, which is what makes the batch vectorisable and the
result independent of the batch's composition. The controller runs at every step and its
command is held over the step (zero-order hold), like a 200 Hz flight controller; so are the
exogenous fault severities s_k(t) (Eq. 6) and the voltage sensitivity kappa_V, which uses the
bus voltage of the previous step (a 5 ms lag, shorter than the 20-50 ms response of a motor and
ESC; it keeps V_b's quadratic closed form exact within the step, since the power demand then
does not depend on V_b itself).

Samples: telemetry sample k is taken at t_k = k * sample_dt_s, at the start of internal step
8k: the state x(t_k), the command computed from it (thr = F_cmd / F_max) and the algebraic
V_b, I_b, d_m, F_act of the first RK4 stage of that step (state and command of the same instant).

Thrust path per evaluation: F_drive = d_m kappa_V F_cmd (the thrust a healthy rotor would make
at this command, bus voltage and thermal derating), F_act = c_i F_drive (Eq. 8). Electrical
power (Eq. 4) and motor heating (Eq. 5) follow F_drive: a motor that lost effectiveness still
draws its drive's power.

Randomness: trajectory i draws everything (reference, initial state, fault timing and size,
faulty motor, sensor noise and bias increments) from its own generator
``default_rng(SeedSequence(seed, spawn_key=(1, i)))`` in the fixed order of ``DRAW_ORDER``;
fault class and split come from ``sim.assign`` (a function of the seed and n_traj only). The
physics is elementwise numpy over the batch (no BLAS, no cross-trajectory reductions), so
simulating any subset of indices gives bit-identical rows.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from core.config import SimConfig
from core.errors import QuadfdiError
from sim import battery, controller, faults, reference, rigid_body, sensors, thermal
from sim.assign import assign
from sim.params import VehicleParams, get_vehicle

N_X = 17  # integrated augmented state size
TRAJ_SPAWN = 1  # spawn_key = (TRAJ_SPAWN, i) for trajectory i
REF_BLOCK_STEPS = 128  # reference evaluated for this many steps at once (speed only)

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

# Extra per-sample fault/physics variables returned by generate (for plots), with units.
EXTRA_UNITS = {
    "effectiveness": "-",  # (n, T, 4) c_i d_m
    "thrust_act": "N",  # (n, T, 4) F_act
    "cooling": "W/K",  # (n, T, 4) h_m
    "fault_heat": "W",  # (n, T, 4) Q_f,m
    "r_int": "Ohm",  # (n, T) R_int
    "c_eff": "A h",  # (n, T) C_eff
    "kappa_v": "-",  # (n, T) kappa_V
    "reference": "m, m, m, rad",  # (n, T, 4) x, y, z, yaw reference
    "t_amb": "degC",  # (n,)
    "battery_limited": "steps",  # (n,) internal steps at the battery's maximum-power clamp
}


# ----------------------------------------------------------------------------- integrator


def rk4_step(f: Callable[[np.ndarray, float], np.ndarray], x: np.ndarray, t: float, dt: float,
             k1: np.ndarray | None = None) -> np.ndarray:
    """One classic RK4 step of x' = f(x, t); ``k1`` = f(x, t) when the caller already has it.
    x: (batch, n) -> (batch, n)."""
    if k1 is None:
        k1 = f(x, t)
    h2 = 0.5 * dt
    k2 = f(x + h2 * k1, t + h2)
    k3 = f(x + h2 * k2, t + h2)
    k4 = f(x + dt * k3, t + dt)
    return x + (dt / 6.0) * ((k1 + k4) + 2.0 * (k2 + k3))


class StepInputs(NamedTuple):
    """Inputs held over one internal step (zero-order hold); all (batch, ...) float64."""

    F_kappa: np.ndarray  # (batch, 4) N: kappa_V * F_cmd
    c: np.ndarray  # (batch, 4) -: effectiveness c_i (Eq. 7)
    dfac: np.ndarray  # (batch, 4) -: overheat factor 1 - a_d s_h 1[m = m_h] (Eq. 8)
    h_m: np.ndarray  # (batch, 4) W/K: cooling (Eq. 8)
    Q_f: np.ndarray  # (batch, 4) W: fault heat (Eq. 8)
    R_int: np.ndarray  # (batch,) Ohm
    C_eff: np.ndarray  # (batch,) A h
    dV: np.ndarray  # (batch,) V
    k_I: np.ndarray  # (batch,) -
    T_amb: np.ndarray  # (batch, 1) degC


class Aux(NamedTuple):
    """Algebraic quantities of one evaluation."""

    V_b: np.ndarray  # (batch,) V
    I_b: np.ndarray  # (batch,) A
    limited: np.ndarray  # (batch,) bool, battery at its maximum-power clamp
    d: np.ndarray  # (batch, 4) -, derating d_m
    F_act: np.ndarray  # (batch, 4) N


def augmented_deriv(x: np.ndarray, u: StepInputs, vp: VehicleParams) -> tuple[np.ndarray, Aux]:
    """d/dt of the augmented state (batch, 17) under held inputs ``u``, and the algebraic Aux."""
    T_m = x[:, 13:17]  # (batch, 4)
    d = faults.derating(T_m, u.dfac, vp)  # (batch, 4) Eq. 8
    F_drive = u.F_kappa * d  # (batch, 4)
    F_act = u.c * F_drive  # (batch, 4) Eq. 8
    P = battery.prop_power(F_drive, vp) + vp.P_av  # (batch,) Eq. 4
    V_b, I_b, limited = battery.terminal(x[:, 12], P, u.R_int, u.dV, u.k_I, vp)
    dsoc = battery.deriv(I_b, u.C_eff)  # (batch,)
    I_m = thermal.motor_currents(F_drive, I_b)  # (batch, 4) Eq. 5
    dT = thermal.deriv(T_m, I_m, F_drive, u.h_m, u.Q_f, u.T_amb, vp)  # (batch, 4)
    dx = np.empty_like(x)
    rigid_body.deriv(x, F_act, vp, out=dx[:, :12])  # (batch, 12) Eq. 2-3
    dx[:, 12] = dsoc
    dx[:, 13:17] = dT
    return dx, Aux(V_b, I_b, limited, d, F_act)


# ----------------------------------------------------------------------------- per-trajectory draws


def trajectory_rng(seed: int, i: int) -> np.random.Generator:
    """The generator of trajectory i: everything random about it comes from here."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(TRAJ_SPAWN, int(i))))


def draw_trajectory(cfg: SimConfig, vp: VehicleParams, i: int) -> dict:
    """All random quantities of trajectory i, drawn in the fixed ``DRAW_ORDER``."""
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


# ----------------------------------------------------------------------------- batch simulation


def initial_state(draws: list[dict], ref: dict[str, np.ndarray], vp: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """Augmented state at t = 0 (batch, 17) and the bus voltage V_b(0) (batch,).

    Around the reference at t = 0 plus the drawn offsets; motors warmed ``warm`` of the way from
    ambient to their healthy hover steady state (Eq. 5 at rest with hover current and thrust)."""
    p_r, v_r, _, psi_r, _ = reference.evaluate(ref, 0.0)
    off = np.stack([d["init"] for d in draws])  # (batch, 12)
    soc0 = np.array([d["soc0"] for d in draws])
    t_amb = np.array([d["t_amb"] for d in draws])
    warm = np.array([d["warm"] for d in draws])
    jitter = np.stack([d["jitter"] for d in draws])  # (batch, 4)

    B = len(draws)
    F_h = np.full((B, 4), vp.hover_thrust)
    P_h = battery.prop_power(F_h, vp) + vp.P_av
    V0, I0, _ = battery.terminal(soc0, P_h, vp.R_0, 0.0, 1.0, vp)
    I_m = thermal.motor_currents(F_h, I0)
    T_ss = thermal.steady_state(I_m, F_h, vp.h_nom, 0.0, t_amb[:, None], vp)  # (batch, 4)
    T0 = t_amb[:, None] + warm[:, None] * (T_ss - t_amb[:, None]) + jitter

    x = np.empty((B, N_X))
    x[:, 0:3] = p_r + off[:, 0:3]
    x[:, 3:6] = v_r + off[:, 3:6]
    x[:, 6:8] = off[:, 6:8]
    x[:, 8] = psi_r + off[:, 8]
    x[:, 9:12] = off[:, 9:12]
    x[:, 12] = soc0
    x[:, 13:17] = T0
    return x, V0


def simulate_batch(draws: list[dict], fault_class: np.ndarray, cfg: SimConfig,
                   vp: VehicleParams) -> dict[str, np.ndarray]:
    """Integrate one batch of closed-loop flights; true per-sample quantities (float64).

    draws: ``draw_trajectory`` outputs; fault_class: (batch,) int. Returns a dict of arrays with a
    leading (batch, T) shape: states (B, T, 19), throttle (B, T, 4), effectiveness, thrust_act,
    cooling, fault_heat (B, T, 4), r_int, c_eff, kappa_v (B, T), reference (B, T, 4),
    battery_limited (B,).
    """
    B = len(draws)
    dt = cfg.sim_dt_s
    sub = cfg.substeps
    n_t = cfg.n_samples
    n_steps = (n_t - 1) * sub

    ref = reference.prepare([d["ref"] for d in draws])
    cls = np.asarray(fault_class)
    healthy = cls == faults.HEALTHY
    onset = np.where(healthy, 0.0, [d["onset"] for d in draws])
    ramp = np.where(healthy, 1.0, [d["ramp"] for d in draws])
    s_max = np.where(healthy, 0.0, [d["s_max"] for d in draws])
    is_b = (cls == faults.BATTERY).astype(np.float64)
    is_m = (cls == faults.MOTOR).astype(np.float64)
    is_h = (cls == faults.OVERHEAT).astype(np.float64)
    onehot = np.zeros((B, 4))
    onehot[np.arange(B), [d["motor"] for d in draws]] = 1.0
    t_amb = np.array([d["t_amb"] for d in draws])[:, None]  # (B, 1)

    x, V_prev = initial_state(draws, ref, vp)
    cs = controller.init_state(faults.kappa_v(V_prev, vp), vp)

    rec = {
        "x": np.empty((n_t, B, N_X)), "V_b": np.empty((n_t, B)), "I_b": np.empty((n_t, B)),
        "F_cmd": np.empty((n_t, B, 4)), "eff": np.empty((n_t, B, 4)), "F_act": np.empty((n_t, B, 4)),
        "h_m": np.empty((n_t, B, 4)), "Q_f": np.empty((n_t, B, 4)), "R_int": np.empty((n_t, B)),
        "C_eff": np.empty((n_t, B)), "kappa": np.empty((n_t, B)), "ref": np.empty((n_t, B, 4)),
    }
    n_limited = np.zeros(B, dtype=np.int64)

    # exogenous inputs precomputed in vectorised blocks (same numbers as step by step)
    t_grid = np.arange(n_steps + 1) * dt  # (n_steps + 1,) t_n = n dt
    sev = faults.severity(t_grid[:, None], onset, ramp, s_max)  # (n_steps + 1, B) Eq. 6
    block = REF_BLOCK_STEPS
    for n in range(n_steps + 1):
        t = t_grid[n]
        j = n % block
        if j == 0:
            ref_block = reference.evaluate(ref, t_grid[n:n + block])
        r = tuple(a[j] for a in ref_block)
        # fault inputs, held over the step (Eq. 7-8)
        s = sev[n]  # (B,)
        s_b, s_m, s_h = s * is_b, s * is_m, s * is_h
        R_int, C_eff, dV, k_I = faults.battery(s_b, vp)
        c = faults.motor_effectiveness(s_m, onehot, vp)
        h_m = faults.cooling(s_h, onehot, vp)
        Q_f = faults.fault_heat(s_h, onehot, vp)
        dfac = faults.overheat_factor(s_h, onehot, vp)
        kappa = faults.kappa_v(V_prev, vp)  # bus voltage of the previous step

        F_cmd, cs = controller.command(x, r, cs, kappa, vp, dt)  # (B, 4), held over the step
        u = StepInputs(F_cmd * kappa[:, None], c, dfac, h_m, Q_f, R_int, C_eff, dV, k_I, t_amb)
        k1, aux = augmented_deriv(x, u, vp)
        V_prev = aux.V_b
        n_limited += aux.limited

        if n % sub == 0:
            k = n // sub
            rec["x"][k] = x
            rec["V_b"][k] = aux.V_b
            rec["I_b"][k] = aux.I_b
            rec["F_cmd"][k] = F_cmd
            rec["eff"][k] = c * aux.d
            rec["F_act"][k] = aux.F_act
            rec["h_m"][k] = h_m
            rec["Q_f"][k] = Q_f
            rec["R_int"][k] = R_int
            rec["C_eff"][k] = C_eff
            rec["kappa"][k] = kappa
            rec["ref"][k, :, 0:3] = r[0]
            rec["ref"][k, :, 3] = r[3]
        if n == n_steps:
            break
        x = rk4_step(lambda xs, ts: augmented_deriv(xs, u, vp)[0], x, t, dt, k1)

    def bt(a: np.ndarray) -> np.ndarray:  # (T, B, ...) -> (B, T, ...)
        return np.ascontiguousarray(np.moveaxis(a, 0, 1))

    X = bt(rec["x"])
    # STATE_NAMES order: p, v, eta, omega, SoC, V_b, I_b, T1..T4
    states = np.concatenate([X[..., 0:13], bt(rec["V_b"])[..., None], bt(rec["I_b"])[..., None], X[..., 13:17]],
                            axis=-1)
    return {
        "states": states,
        "throttle": bt(rec["F_cmd"]) / vp.F_max,
        "effectiveness": bt(rec["eff"]),
        "thrust_act": bt(rec["F_act"]),
        "cooling": bt(rec["h_m"]),
        "fault_heat": bt(rec["Q_f"]),
        "r_int": bt(rec["R_int"]),
        "c_eff": bt(rec["C_eff"]),
        "kappa_v": bt(rec["kappa"]),
        "reference": bt(rec["ref"]),
        "battery_limited": n_limited,
    }


# ----------------------------------------------------------------------------- dataset


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
    vp = get_vehicle(cfg.vehicle)
    idx = _indices(cfg, indices)
    cls_all, split_all = assign(cfg.seed, cfg.n_traj, cfg.fault_ratio, cfg.split)
    n_t = cfg.n_samples
    time = np.arange(n_t, dtype=np.float64) * cfg.sample_dt_s

    parts: list[dict[str, np.ndarray]] = []
    for start in range(0, idx.size, cfg.chunk):
        chunk = idx[start:start + cfg.chunk]
        draws = [draw_trajectory(cfg, vp, int(i)) for i in chunk]
        cls = cls_all[chunk]
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
        parts.append({
            "telemetry": y.astype(np.float32),
            "states": true["states"].astype(np.float32),
            "severity": sev.astype(np.float32),
            "fault_class": cls.astype(np.int8),
            "onset_s": onset.astype(np.float64),
            "ramp_s": ramp.astype(np.float64),
            "severity_max": s_max.astype(np.float64),
            "fault_motor": np.where(motor_fault, [d["motor"] for d in draws], -1).astype(np.int8),
            "detectable_s": det,
            "split": split_all[chunk].astype(np.int8),
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
        })
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


# ----------------------------------------------------------------------------- summary


def summarize(out: dict[str, np.ndarray]) -> str:
    """Per-class telemetry sanity summary of a ``generate`` output (text table).

    Changes are (mean of the last second) - (mean of the first second) of the noisy telemetry;
    "faulty motor" columns use the faulty/overheated motor, minus the mean of the other three.
    """
    names = list(out["channel_names"])
    tel = out["telemetry"].astype(np.float64)
    st = out["states"].astype(np.float64)
    sn = list(out["state_names"])
    cls, fm = out["fault_class"], out["fault_motor"]
    n_last = min(25, tel.shape[1] // 4)

    def change(a: np.ndarray) -> np.ndarray:  # (n, T, ...) -> (n, ...)
        return a[:, -n_last:].mean(axis=1) - a[:, :n_last].mean(axis=1)

    thr = tel[..., names.index("thr1"):names.index("thr1") + 4]
    temp = tel[..., names.index("T1"):names.index("T1") + 4]
    d_v, d_i = change(tel[..., names.index("V_b")]), change(tel[..., names.index("I_b")])
    d_thr, d_temp = change(thr), change(temp)
    head = ("dV_b [V]", "dI_b [A]", "d thr mean [-]", "d thr faulty-others", "d T faulty-others [K]")
    rows = [f"{'class':9s} {'n':>3s}  " + "".join(f"{h:22s}" for h in head) + "max T [degC]"]
    labels = ("Healthy", "Battery", "Motor", "Overheat")

    def fmt(x: np.ndarray) -> str:
        return f"{x.mean():+6.2f} [{x.min():+5.2f},{x.max():+5.2f}]" if x.size else "-"

    for k, label in enumerate(labels):
        m = cls == k
        if not m.any():
            continue
        own = (cls[m] >= 2)
        idx = np.flatnonzero(m)
        if own.all():
            sel = fm[idx].astype(np.int64)
            onehot = np.eye(4, dtype=bool)[sel]
            thr_rel = d_thr[idx][onehot] - d_thr[idx][~onehot].reshape(-1, 3).mean(axis=1)
            t_rel = d_temp[idx][onehot] - d_temp[idx][~onehot].reshape(-1, 3).mean(axis=1)
            extra = f"{fmt(thr_rel):22s}{fmt(t_rel):22s}"
        else:
            extra = f"{'-':22s}{'-':22s}"
        rows.append(f"{label:9s} {m.sum():3d}  {fmt(d_v[m]):22s}{fmt(d_i[m]):22s}{fmt(d_thr[m].mean(axis=1)):22s}"
                    f"{extra}{temp[m].max():6.1f}")
    tilt = np.degrees(np.arccos(np.cos(st[..., sn.index("roll")]) * np.cos(st[..., sn.index("pitch")])))
    err = np.linalg.norm(st[..., 0:3] - out["reference"][..., 0:3], axis=-1)[:, 50:]
    f = cls > 0
    rows.append(f"max tilt {tilt.max():.1f} deg; position error after 2 s: RMS {np.sqrt((err**2).mean()):.3f} m, "
                f"max {err.max():.3f} m; finite: {bool(np.isfinite(tel).all())}; battery clamp steps: "
                f"{int(out['battery_limited'].sum())}")
    if f.any():
        rows.append(f"latest detectable time {np.nanmax(out['detectable_s'][f]):.2f} s of {out['time'][-1]:.2f} s; "
                    f"undetectable fault trajectories: {int(np.isnan(out['detectable_s'][f]).sum())}; "
                    f"min effectiveness {out['effectiveness'].min():.3f}")
    return "\n".join(rows)


if __name__ == "__main__":  # python -m sim.simulate [seed]: paper-scale timing and summary
    import sys
    import time as _time

    _cfg = SimConfig(seed=int(sys.argv[1]) if len(sys.argv) > 1 else 0)
    generate(_cfg, indices=range(4))  # warm-up (imports, caches)
    _t0 = _time.perf_counter()
    _out = generate(_cfg)
    _dt = _time.perf_counter() - _t0
    print(f"generate: {_cfg.n_traj} trajectories x {_cfg.duration_s:g} s "
          f"({(_cfg.n_samples - 1) * _cfg.substeps} steps of {_cfg.sim_dt_s * 1e3:g} ms) in {_dt:.2f} s")
    print(summarize(_out))
