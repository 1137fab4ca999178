"""Battery model (paper Eq. 4 with the fault terms of Eq. 7): LiPo OCV curve, power demand,
the algebraic terminal voltage / current pair, and the state-of-charge derivative.

V_b and I_b are coupled algebraically, with no dynamics between them:

    V_b = E - I_b R_int,   E = V_ocv(SoC) - DeltaV_f,   I_b = k P / V_b,   k = 1 + a_I s_b

so V_b^2 - E V_b + R_int k P = 0. The physical (high-voltage, low-current) operating point is the
larger root V_b = (E + sqrt(E^2 - 4 R_int k P)) / 2, solved in closed form at every evaluation
(never lagged one step behind the other). When E^2 < 4 R_int k P the pack cannot deliver the
demanded power at any current; we then clamp to its maximum-power point V_b = E/2,
I_b = E / (2 R_int) (the pack delivers E^2 / (4 R_int) < k P) and flag it. With this vehicle's
numbers that needs > ~300 W at the worst-case fault and charge, which the flights never ask for
(``generate`` reports the count of limited steps as ``battery_limited``).

All functions are vectorised over a leading batch axis.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from quadfdi.sim.params import VehicleParams


@lru_cache(maxsize=16)
def _table(soc: tuple[float, ...], volt: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    # np.interp converts tuple tables on every call (~13 us); convert once per vehicle.
    return np.array(soc, dtype=np.float64), np.array(volt, dtype=np.float64)


def ocv(soc: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """Open-circuit voltage V_ocv(SoC) [V], linear in the vehicle's 3S LiPo table; any shape.
    Outside [0, 1] it holds the end values (an empty pack does not go below 9 V here)."""
    xp, fp = _table(vp.ocv_soc, vp.ocv_volt)
    return np.interp(soc, xp, fp)


def prop_power(F: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """P_prop = c_P sum_i max(F_i, 0)^a_P [W], F (batch, 4) [N] -> (batch,)."""
    Fp = np.maximum(F, 0.0)
    if vp.a_P == 1.5:
        w = Fp * np.sqrt(Fp)  # exact IEEE sqrt: faster than ** and identical on every platform
    else:
        w = Fp**vp.a_P
    return vp.c_P * ((w[:, 0] + w[:, 1]) + (w[:, 2] + w[:, 3]))


def terminal(
    soc: np.ndarray, P: np.ndarray, R_int: np.ndarray | float, dV: np.ndarray | float,
    k_I: np.ndarray | float, vp: VehicleParams,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form terminal voltage and bus current.

    soc: (batch,) [-]; P: (batch,) total electrical demand P_prop + P_av [W];
    R_int [Ohm], dV [V], k_I [-]: (batch,) or scalars (Eq. 7 fault terms; 0 V / 1 when healthy).
    Returns V_b (batch,) [V], I_b (batch,) [A], limited (batch,) bool (max-power clamp active).
    """
    E = ocv(soc, vp) - dV  # (batch,)
    kP = k_I * P
    disc = E * E - 4.0 * R_int * kP
    limited = disc < 0.0
    V = 0.5 * (E + np.sqrt(np.maximum(disc, 0.0)))
    # I = kP / V on the physical root; at the clamp, I = (E - V) / R = E / (2 R). Both forms are
    # equal when disc = 0, so use the one that holds on both sides.
    I = (E - V) / R_int
    return V, I, limited


def deriv(I_b: np.ndarray, C_eff: np.ndarray | float) -> np.ndarray:
    """Eq. (4)/(7): dSoC/dt = -I_b / (3600 C_eff) [1/s]; I_b (batch,) [A], C_eff [A h]."""
    return -I_b / (3600.0 * C_eff)
