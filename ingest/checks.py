"""Plausibility checks that turn a logged but meaningless channel into an unusable one (said so).

A channel can be present and wrong: a current sensor that was never calibrated reads a few amps
for a multirotor in the air (the 6S GPS-interference log reads at most 1.5 A), a disconnected
monitor reads ~0 V. Masking them beats feeding a model a confident zero.
"""

from __future__ import annotations

import numpy as np

from quadfdi.ingest.model import LogRead

I_AIRBORNE_MIN = 2.0  # A: no multirotor hovers on less (the simulator's 1.5 kg quad draws ~14 A)
V_CELL_MIN = 2.5  # V: below it a lithium cell is dead or the monitor is not connected


def _in_air(t: np.ndarray, airborne) -> np.ndarray:
    m = np.zeros(len(t), bool)
    for a, b in airborne:
        m |= (t >= a) & (t <= b)
    return m


def plausibility(lr: LogRead) -> None:
    cells = (lr.vehicle.get("battery") or {}).get("cells") or 1
    vb = lr.channels.get("V_b")
    if vb is not None and np.nanmax(vb.v, initial=0.0) < V_CELL_MIN * cells:
        del lr.channels["V_b"]
        lr.status["V_b"] = f"unusable: at most {np.nanmax(vb.v, initial=0.0):.2f} V for {cells} cells (monitor not connected?)"
    ib = lr.channels.get("I_b")
    if ib is not None and lr.airborne:
        air = _in_air(ib.t, lr.airborne)
        if air.any() and np.nanmax(ib.v[air], initial=0.0) < I_AIRBORNE_MIN:
            del lr.channels["I_b"]
            lr.status["I_b"] = (f"unusable: at most {np.nanmax(ib.v[air], initial=0.0):.2f} A while airborne "
                                f"(< {I_AIRBORNE_MIN:g} A: current sensor not calibrated)")
