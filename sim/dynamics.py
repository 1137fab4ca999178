"""The augmented-state derivative and the fixed-step RK4 integration loop of one batch.

Augmented integrated state (Eq. 1), (batch, 17): p (0:3) [m], v (3:6) [m/s], eta (6:9) [rad],
omega_B (9:12) [rad/s], SoC (12) [-], T_m (13:17) [degC]. V_b and I_b are algebraic (closed
form in ``battery.terminal`` at every evaluation), so they are outputs, not integrated states.

Integration: classic RK4 (``core.rk4.rk4_step``: weights 1/6, 1/3, 1/3, 1/6, stages at 0, h/2,
h/2, h; not the 3/8 rule) at a fixed step ``cfg.sim_dt_s`` = 5 ms, ``cfg.substeps`` = 8 steps
per 40 ms telemetry sample. Why: the fastest closed-loop mode is the body-rate loop at
~25 rad/s (h * 25 = 0.125, far inside RK4's stability region and with a local error ~1e-9),
and a fixed step keeps every trajectory of a batch on the same time grid, which is what makes the batch vectorisable and the
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

The physics is elementwise numpy over the batch (no BLAS, no cross-trajectory reductions), so
a trajectory's numbers do not depend on the other trajectories of its batch.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from quadfdi.sim.config import SimConfig
from quadfdi.core.rk4 import rk4_step
from quadfdi.sim import battery, controller, faults, reference, rigid_body, thermal
from quadfdi.sim.params import VehicleParams

N_X = 17  # integrated augmented state size
REF_BLOCK_STEPS = 128  # reference evaluated for this many steps at once (speed only)


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


class FaultSchedule(NamedTuple):
    """Each trajectory's fault, as Eq. (6)-(8) need it; all (batch, ...) float64."""

    onset: np.ndarray  # (batch,) s, t_on (0 for healthy)
    ramp: np.ndarray  # (batch,) s, T_r (1 for healthy)
    s_max: np.ndarray  # (batch,) -, final severity (0 for healthy)
    is_b: np.ndarray  # (batch,) 1 for a battery fault, else 0
    is_m: np.ndarray  # (batch,) 1 for a motor fault, else 0
    is_h: np.ndarray  # (batch,) 1 for an overheat fault, else 0
    onehot: np.ndarray  # (batch, 4) the faulty / overheated motor (drawn for every class)


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


def step_inputs(s: np.ndarray, sched: FaultSchedule, F_cmd: np.ndarray, kappa: np.ndarray,
                T_amb: np.ndarray, vp: VehicleParams) -> StepInputs:
    """The inputs held over one step: fault terms (Eq. 7-8) at severity s (batch,) and the command."""
    s_b, s_m, s_h = s * sched.is_b, s * sched.is_m, s * sched.is_h
    R_int, C_eff, dV, k_I = faults.battery(s_b, vp)
    c = faults.motor_effectiveness(s_m, sched.onehot, vp)
    h_m = faults.cooling(s_h, sched.onehot, vp)
    Q_f = faults.fault_heat(s_h, sched.onehot, vp)
    dfac = faults.overheat_factor(s_h, sched.onehot, vp)
    return StepInputs(F_cmd * kappa[:, None], c, dfac, h_m, Q_f, R_int, C_eff, dV, k_I, T_amb)


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


class Samples:
    """Per-sample record of one batch, time-major (T, batch, ...) while integrating."""

    def __init__(self, n_t: int, B: int) -> None:
        self.x = np.empty((n_t, B, N_X))
        self.V_b, self.I_b = np.empty((n_t, B)), np.empty((n_t, B))
        self.F_cmd, self.eff, self.F_act = np.empty((n_t, B, 4)), np.empty((n_t, B, 4)), np.empty((n_t, B, 4))
        self.h_m, self.Q_f = np.empty((n_t, B, 4)), np.empty((n_t, B, 4))
        self.R_int, self.C_eff, self.kappa = np.empty((n_t, B)), np.empty((n_t, B)), np.empty((n_t, B))
        self.ref = np.empty((n_t, B, 4))
        self.n_limited = np.zeros(B, dtype=np.int64)  # internal steps at the battery clamp

    def take(self, k: int, x: np.ndarray, aux: Aux, F_cmd: np.ndarray, u: StepInputs, kappa: np.ndarray,
             r: tuple[np.ndarray, ...]) -> None:
        """Sample k: the state, the command computed from it and the first stage's Aux."""
        self.x[k] = x
        self.V_b[k] = aux.V_b
        self.I_b[k] = aux.I_b
        self.F_cmd[k] = F_cmd
        self.eff[k] = u.c * aux.d
        self.F_act[k] = aux.F_act
        self.h_m[k] = u.h_m
        self.Q_f[k] = u.Q_f
        self.R_int[k] = u.R_int
        self.C_eff[k] = u.C_eff
        self.kappa[k] = kappa
        self.ref[k, :, 0:3] = r[0]
        self.ref[k, :, 3] = r[3]


def integrate(x: np.ndarray, V_prev: np.ndarray, ref: dict[str, np.ndarray], sched: FaultSchedule,
              T_amb: np.ndarray, cfg: SimConfig, vp: VehicleParams) -> Samples:
    """Closed-loop flight of one batch from state x (batch, 17) and bus voltage V_prev (batch,)
    at t = 0 to the last sample; ``ref`` from ``reference.prepare``, T_amb (batch, 1)."""
    dt = cfg.sim_dt_s
    sub = cfg.substeps
    n_steps = (cfg.n_samples - 1) * sub
    rec = Samples(cfg.n_samples, x.shape[0])
    cs = controller.init_state(faults.kappa_v(V_prev, vp), vp)

    # exogenous inputs precomputed in vectorised blocks (same numbers as step by step)
    t_grid = np.arange(n_steps + 1) * dt  # (n_steps + 1,) t_n = n dt
    sev = faults.severity(t_grid[:, None], sched.onset, sched.ramp, sched.s_max)  # (n_steps + 1, B) Eq. 6
    block = REF_BLOCK_STEPS
    for n in range(n_steps + 1):
        t = t_grid[n]
        j = n % block
        if j == 0:
            ref_block = reference.evaluate(ref, t_grid[n:n + block])
        r = tuple(a[j] for a in ref_block)
        kappa = faults.kappa_v(V_prev, vp)  # bus voltage of the previous step
        F_cmd, cs = controller.command(x, r, cs, kappa, vp, dt)  # (B, 4), held over the step
        u = step_inputs(sev[n], sched, F_cmd, kappa, T_amb, vp)
        k1, aux = augmented_deriv(x, u, vp)
        V_prev = aux.V_b
        rec.n_limited += aux.limited
        if n % sub == 0:
            rec.take(n // sub, x, aux, F_cmd, u, kappa, r)
        if n == n_steps:
            break
        x = rk4_step(lambda ts, xs: augmented_deriv(xs, u, vp)[0], t, x, dt, k1)
    return rec
