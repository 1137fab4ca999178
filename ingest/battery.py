"""The pack's cell count: from the log's parameters, checked against its voltage.

From voltage alone the count is the smallest n with V_max / n <= 4.35 V (a LiPo/LiHV cell never
rests above it). Rounding V / 4.2 is wrong for a pack that is not full: a 4S pack resting at
3.5 V/cell (14.0 V) rounds to 3S, while ceil(14.0 / 4.35) = 4. Parameters win over the voltage:
PX4's ``battery_status.cell_count`` (what the driver used), then BAT1_N_CELLS (PX4 >= 1.11), then the
legacy BAT_N_CELLS; ArduPilot BATT_CELLS. A disagreement is reported, never resolved silently.
"""

from __future__ import annotations

import math

import numpy as np

V_CELL_MAX = 4.35  # V: LiHV full charge; no lithium cell rests above it


def cells_from_voltage(v_max: float) -> int:
    """Smallest cell count whose per-cell voltage is at most V_CELL_MAX (0 for no usable voltage)."""
    if not np.isfinite(v_max) or v_max < 2.5:
        return 0
    return int(math.ceil(v_max / V_CELL_MAX - 1e-9))


def cell_count(candidates: list[tuple[str, int]], v_max: float) -> dict:
    """Pick the cell count: first positive candidate (name, value); record every source and disagreements."""
    from_v = cells_from_voltage(v_max)
    given = [(k, int(v)) for k, v in candidates if v is not None and int(v) > 0]
    out: dict = {"sources": dict(given), "from_voltage": from_v or None,
                 "v_max": float(v_max) if np.isfinite(v_max) else None}
    if given:
        out["cells"], out["source"] = given[0][1], given[0][0]
    elif from_v:
        out["cells"], out["source"] = from_v, f"voltage: ceil({v_max:.2f} V / {V_CELL_MAX} V)"
    else:
        out["cells"], out["source"] = None, "unknown"
    values = {v for _, v in given} | ({from_v} if from_v else set())
    out["disagreement"] = len(values) > 1
    return out
