"""Faults of the realistic suite: onset modes, intermittent events, and what each class does.

Onset modes (``fault_mode``; drawn per flight, by class; ``sim.variability.MODES``):

- progressive: s(t) = s_max sat((t - t_on) / T_r) (the paper's Eq. 6: wear, a warming motor);
- abrupt: the same with T_r = ABRUPT_S (a prop strike, a cell that fails, debris in a motor bell);
- takeoff: s = s_max from t = 0 (a damaged propeller or a degraded pack flown as it is);
- intermittent: events after t_on, Poisson at 0.2-1 /s: a connector whose resistance spikes for
  50-500 ms (battery), an ESC that desyncs and drops its motor for 20-100 ms (motor).

Class -> modes (probabilities): Battery: takeoff 0.3, progressive 0.35, abrupt 0.15,
intermittent 0.2; Motor: progressive 0.45, abrupt 0.3, intermittent 0.25; Overheat: progressive
0.7, abrupt 0.3; Propeller: takeoff 0.5, abrupt 0.5. Half the in-flight onsets are moved to the
start of the next manoeuvre (mission segment that moves), 0-1 s in: onsets during manoeuvres.

Label severity (``severity`` in dataset.npz, what windows are labelled with): s(t) above; for an
intermittent fault it is s_max from the first event on (the fault is present between spikes).

Effects at severity s (battery submode drawn per flight: 0 resistance growth, 1 capacity fade,
2 cell imbalance; every one of them is visible to the shunt and the voltage sense):
  Battery   R_int x (1 + BATT_R_GROWTH s) | C x (1 - BATT_FADE s) | weakest cell IMBALANCE_CELL_SOC s
            of SoC below the others; intermittent: + r_spike (0.03-0.15 Ohm) during a spike
  Motor     c_m = 1 - a_M s on the faulty motor (demagnetisation, shorted turns); desync: c_m = 0
  Overheat  h_m x (1 - a_h s) and Q_f = a_Q s on the motor (Eq. 8); no direct derating: derating
            comes from its temperature only (d_m of Eq. 8 with a_d = 0)
  Propeller cut l = CUT_MAX s of one blade: rho_T, rho_Q (sim/propeller.py) and its imbalance
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from quadfdi.sim import mission
from quadfdi.sim import realistic_params as P

ABRUPT_S = 0.2  # s: an abrupt fault's ramp (one tenth of the controller's slowest loop)
# cumulative mode probabilities per class name, in MODES order (progressive, abrupt, takeoff, intermittent)
MODE_CDF = {
    "BatteryFault": (0.35, 0.50, 0.80, 1.0),
    "MotorFault": (0.45, 0.75, 0.75, 1.0),
    "OverheatFault": (0.70, 1.0, 1.0, 1.0),
    "PropellerFault": (0.0, 0.5, 1.0, 1.0),
}
PROGRESSIVE, ABRUPT, TAKEOFF, INTERMITTENT = range(4)


class FaultPlan(NamedTuple):
    """Each flight's fault, (B,) or (B, 4) float64 unless said."""

    kind: np.ndarray  # (B, 5) one-hot over (healthy, battery, motor, overheat, propeller)
    onehot: np.ndarray  # (B, 4) the faulty motor (rotor-side faults), else zeros
    mode: np.ndarray  # (B,) int
    submode: np.ndarray  # (B, 3) one-hot battery submode
    onset: np.ndarray  # (B,) s
    ramp: np.ndarray  # (B,) s
    s_max: np.ndarray  # (B,) 0 for healthy
    ev_start: np.ndarray  # (B, N_EVENTS) s, inf when unused
    ev_len: np.ndarray  # (B, N_EVENTS) s
    r_spike: np.ndarray  # (B,) Ohm


def plan(draws: list[dict], class_names: tuple[str, ...], cls: np.ndarray, duration: float) -> FaultPlan:
    """The fault plan of a batch from its draws and class labels (index into class_names)."""
    B = len(draws)
    names = [class_names[c] for c in cls]
    kinds = ("Healthy", "BatteryFault", "MotorFault", "OverheatFault", "PropellerFault")
    kind = np.array([[n == k for k in kinds] for n in names], dtype=np.float64)
    mode = np.array([0 if n == "Healthy" else int(np.searchsorted(MODE_CDF[n], d["mode_u"], side="right"))
                     for n, d in zip(names, draws)])
    mode = np.minimum(mode, 3)
    onset = np.array([d["onset"] for d in draws])
    ramp = np.where(mode == ABRUPT, ABRUPT_S, [d["ramp"] for d in draws])
    starts = mission.manoeuvre_starts(mission.prepare([d["mission"] for d in draws]))  # (B, N_SEG)
    delay = np.array([d["snap_delay"] for d in draws])
    after = np.where(starts >= onset[:, None], starts, np.inf).min(axis=1) + delay
    snap = (np.array([d["snap_u"] for d in draws]) < P.MANOEUVRE_SNAP_P) & (after <= 0.6 * duration)
    onset = np.where(snap & (mode != TAKEOFF), after, onset)
    onset = np.where(mode == TAKEOFF, -1.0, onset)
    ramp = np.where(mode == TAKEOFF, 1e-3, ramp)
    healthy = kind[:, 0] > 0
    s_max = np.where(healthy, 0.0, [d["s_max"] for d in draws])
    rotor = (kind[:, 2] + kind[:, 3] + kind[:, 4]) > 0
    onehot = np.zeros((B, 4))
    onehot[np.arange(B), [d["motor"] for d in draws]] = 1.0
    onehot *= rotor[:, None]
    sub = np.zeros((B, 3))
    sub[np.arange(B), [d["submode"] for d in draws]] = 1.0
    gap = np.stack([d["event_gap"] for d in draws]) / np.array([d["event_rate"] for d in draws])[:, None]
    ev_start = onset[:, None] + np.cumsum(gap, axis=1) - gap[:, :1]  # first event at the onset
    lo, hi = np.where(kind[:, 1:2] > 0, P.CONN_SPIKE_S[0], P.DESYNC_S[0]), \
        np.where(kind[:, 1:2] > 0, P.CONN_SPIKE_S[1], P.DESYNC_S[1])
    ev_len = lo + (hi - lo) * np.stack([d["event_u"] for d in draws])
    ev_start = np.where((mode == INTERMITTENT)[:, None], ev_start, np.inf)
    return FaultPlan(kind, onehot, mode, sub, onset, np.maximum(ramp, 1e-3), s_max, ev_start, ev_len,
                     np.array([d["r_spike"] for d in draws]))


def label_severity(fp: FaultPlan, t: np.ndarray) -> np.ndarray:
    """Severity of each flight at times t (n,): (n, B). Intermittent: s_max from the first event."""
    s = fp.s_max * np.clip((t[:, None] - fp.onset) / fp.ramp, 0.0, 1.0)
    return np.where(fp.mode == INTERMITTENT, fp.s_max * (t[:, None] >= fp.onset), s)


def event_mask(fp: FaultPlan, n_steps: int, dt: float) -> np.ndarray:
    """(n_steps + 1, B) bool: an intermittent event is active at step n (t = n dt)."""
    B = fp.onset.shape[0]
    diff = np.zeros((n_steps + 2, B), dtype=np.int32)
    a = np.clip(np.ceil(fp.ev_start / dt), 0, n_steps + 1)
    b = np.clip(np.ceil((fp.ev_start + fp.ev_len) / dt), 0, n_steps + 1)
    a = np.where(np.isfinite(a), a, n_steps + 1).astype(np.int64)
    b = np.where(np.isfinite(b), b, n_steps + 1).astype(np.int64)
    cols = np.broadcast_to(np.arange(B)[:, None], a.shape)
    np.add.at(diff, (a.ravel(), cols.ravel()), 1)
    np.add.at(diff, (b.ravel(), cols.ravel()), -1)
    return np.cumsum(diff, axis=0)[: n_steps + 1] > 0


def physical_severity(fp: FaultPlan, t: np.ndarray) -> np.ndarray:
    """Severity driving the physics at times t (n,): (n, B); intermittent faults act through events only."""
    s = fp.s_max * np.clip((t[:, None] - fp.onset) / fp.ramp, 0.0, 1.0)
    return np.where(fp.mode == INTERMITTENT, 0.0, s)
