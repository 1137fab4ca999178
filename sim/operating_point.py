"""The operating point implied by a vehicle's parameters: level hover, healthy, at SoC 0.8.

It evaluates the battery, thermal and fault models at hover, so it sits above them: this module
imports ``sim.params`` and the subsystems, none of them imports it.

``python -m quadfdi.sim.operating_point [vehicle]`` prints every parameter, then these numbers
(docs/params.md quotes them).
"""

from __future__ import annotations

import numpy as np

from quadfdi.sim import battery, faults, thermal
from quadfdi.sim.params import VehicleParams, get_vehicle


def derived(vp: VehicleParams) -> dict[str, float]:
    """Operating-point numbers implied by the parameters (level hover at SoC 0.8, healthy)."""
    F = np.full((1, 4), vp.hover_thrust)
    P = battery.prop_power(F, vp) + vp.P_av
    V, I, _ = battery.terminal(np.array([0.8]), P, vp.R_0, 0.0, 1.0, vp)
    I_m = thermal.motor_currents(F, I)
    rise = thermal.steady_state(I_m, F, vp.h_nom, 0.0, 0.0, vp)[0, 0]
    return {
        "hover thrust per rotor [N]": vp.hover_thrust,
        "hover command at V_nom [-]": vp.hover_thrust / vp.F_max,
        "hover power incl. avionics [W]": float(P[0]),
        "hover bus voltage at SoC 0.8 [V]": float(V[0]),
        "hover bus current at SoC 0.8 [A]": float(I[0]),
        "kappa_V at that voltage [-]": float(faults.kappa_v(V, vp)[0]),
        "thermal time constant C_th/h_nom [s]": vp.C_th / vp.h_nom,
        "hover winding rise above ambient [K]": float(rise),
        # the largest demand P the pack can meet, E^2 / (4 R_int k_I) (Eq. 4, 7), at the worst state flown
        "max pack power at SoC 0.55, s_b = 1 [W]": float(
            (battery.ocv(np.array(0.55), vp) - vp.Delta_V) ** 2 / (4 * vp.R_0 * (1 + vp.a_R)) / (1 + vp.a_I)),
    }


if __name__ == "__main__":  # python -m quadfdi.sim.operating_point [vehicle]: every value, then derived numbers
    import sys
    from dataclasses import fields

    _vp = get_vehicle(sys.argv[1] if len(sys.argv) > 1 else "f450_3s")
    for _f in fields(_vp):
        print(f"{_f.name} = {getattr(_vp, _f.name)!r}")
    print()
    for _k, _v in derived(_vp).items():
        print(f"{_k}: {_v:.3f}")
