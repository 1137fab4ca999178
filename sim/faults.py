"""Progressive fault scheduling (paper Eq. 6) and fault mechanisms (Eq. 7, 8).

Each faulty trajectory has one fault class k with severity s_k(t) = s_max sat((t - t_on) / T_r);
the other two classes' severities are zero. Fault injection lives here and only here (detection
is train/'s job). All functions are vectorised over a leading batch axis; a per-motor mask
``onehot`` (batch, 4) selects the faulty motor m_m or the overheated motor m_h.

Voltage sensitivity (Eq. 8's kappa_V, not defined further in the paper): at a fixed duty cycle
a motor's speed scales with the bus voltage and its thrust with speed squared, so to first order

    kappa_V = 1 - k_V (V_nom - V_b) / V_nom,   k_V = 2,

i.e. F_max is the full-command thrust at V_nom = 11.1 V; a full pack under load (~12.2 V) gives
~20 % more thrust per command, a sagging one less. The controller's integrators absorb it, so
the sag shows in the throttle channels the way it does in PX4 logs.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.contracts import CLASS_NAMES, HEALTHY  # noqa: F401  (faults.HEALTHY, beside the fault labels)
from quadfdi.sim.params import VehicleParams

BATTERY, MOTOR, OVERHEAT = (CLASS_NAMES.index(n) for n in ("BatteryFault", "MotorFault", "OverheatFault"))


def sat(u: np.ndarray) -> np.ndarray:
    """Eq. (6): min(max(u, 0), 1)."""
    return np.minimum(np.maximum(u, 0.0), 1.0)


def severity(t: np.ndarray | float, onset: np.ndarray, ramp: np.ndarray, s_max: np.ndarray) -> np.ndarray:
    """Eq. (6): s(t) = s_max sat((t - t_on) / T_r). Broadcasts (e.g. t (1, T) with onset (n, 1)).
    A healthy trajectory is s_max = 0 (with any finite onset and positive ramp)."""
    return s_max * sat((t - onset) / ramp)


def battery(s_b: np.ndarray, vp: VehicleParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. (7) battery fault, s_b (batch,) -> R_int [Ohm], C_eff [A h], DeltaV_f [V], k_I [-]."""
    return vp.R_0 * (1.0 + vp.a_R * s_b), vp.C_nom * (1.0 - vp.a_C * s_b), vp.Delta_V * s_b, 1.0 + vp.a_I * s_b


def motor_effectiveness(s_m: np.ndarray, onehot: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """Eq. (7): c_i = 1 - a_M s_m 1[i = m_m]; s_m (batch,), onehot (batch, 4) -> (batch, 4)."""
    return 1.0 - vp.a_M * s_m[:, None] * onehot


def cooling(s_h: np.ndarray, onehot: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """Eq. (8): h_m = max(h_nom (1 - a_h s_h 1[m = m_h]), h_min) [W/K], (batch, 4)."""
    return np.maximum(vp.h_nom * (1.0 - vp.a_h * s_h[:, None] * onehot), vp.h_min)


def fault_heat(s_h: np.ndarray, onehot: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """Eq. (8): Q_f,m = a_Q s_h 1[m = m_h] [W], (batch, 4)."""
    return vp.a_Q * s_h[:, None] * onehot


def overheat_factor(s_h: np.ndarray, onehot: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """Eq. (8), second factor of d_m: 1 - a_d s_h 1[m = m_h], (batch, 4)."""
    return 1.0 - vp.a_d * s_h[:, None] * onehot


def derating(T_m: np.ndarray, factor: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """Eq. (8): d_m = max((1 - lambda_T max(T_m - T_der, 0)) * factor, d_min), (batch, 4).
    ``factor`` is ``overheat_factor(...)`` (1 when no overheat fault)."""
    return np.maximum((1.0 - vp.lambda_T * np.maximum(T_m - vp.T_der, 0.0)) * factor, vp.d_min)


def kappa_v(V_b: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """Voltage sensitivity kappa_V = 1 - k_V (V_nom - V_b) / V_nom [-], (batch,)."""
    return 1.0 - vp.k_V * (vp.V_nom - V_b) / vp.V_nom

