"""Per-motor lumped thermal model (paper Eq. 5; cooling h_m and fault heat Q_f from Eq. 8).

One thermal node per motor: the winding and stator that heat first (C_th ~ 12 J/K, the copper
and iron of a 2212 motor), cooled by the prop wash to ambient through h_m. With h_nom = 0.35 W/K
the time constant C_th / h_nom is ~34 s, so a fault's heating shows within a 3.2 s window and the
healthy motor sits ~18 K above ambient in hover.

    C_th dT_m/dt = R_w I_m^2 + c_F F_m^2 + Q_f,m - h_m (T_m - T_amb),   I_m = F_m I_b / sum_i F_i

F_m here is the thrust the motor is driven to produce (its command after voltage and thermal
derating, before the effectiveness loss c_i): a chipped prop or weakened magnets waste the
drive's power as heat and lost thrust, they do not make the motor draw less.
"""

from __future__ import annotations

import numpy as np

from quadfdi.sim.params import VehicleParams

_EPS_F = 1e-6  # N: guards I_m against a zero total thrust (free fall with motors off)


def motor_currents(F: np.ndarray, I_b: np.ndarray) -> np.ndarray:
    """Eq. (5): I_m = F_m I_b / sum_i F_i [A]. F (batch, 4) [N], I_b (batch,) [A] -> (batch, 4)."""
    Fp = np.maximum(F, 0.0)
    total = (Fp[:, 0] + Fp[:, 1]) + (Fp[:, 2] + Fp[:, 3])
    return Fp * (I_b / np.maximum(total, _EPS_F))[:, None]


def heat_in(I_m: np.ndarray, F: np.ndarray, Q_f: np.ndarray | float, vp: VehicleParams) -> np.ndarray:
    """Heat into each motor node [W]: copper R_w I_m^2 + mechanical c_F F^2 + fault heat; (batch, 4)."""
    Fp = np.maximum(F, 0.0)
    return vp.R_w * I_m * I_m + vp.c_F * Fp * Fp + Q_f


def deriv(
    T_m: np.ndarray, I_m: np.ndarray, F: np.ndarray, h_m: np.ndarray | float, Q_f: np.ndarray | float,
    T_amb: np.ndarray | float, vp: VehicleParams,
) -> np.ndarray:
    """Eq. (5): dT_m/dt [K/s], all (batch, 4) (T_amb (batch, 1) or scalar) [degC, A, N, W/K, W]."""
    return (heat_in(I_m, F, Q_f, vp) - h_m * (T_m - T_amb)) / vp.C_th


def steady_state(I_m: np.ndarray, F: np.ndarray, h_m: np.ndarray | float, Q_f: np.ndarray | float,
                 T_amb: np.ndarray | float, vp: VehicleParams) -> np.ndarray:
    """Temperature at which Eq. (5) is at rest for constant inputs: T_amb + heat_in / h_m [degC]."""
    return T_amb + heat_in(I_m, F, Q_f, vp) / h_m
