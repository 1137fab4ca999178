"""``labels.json`` beside a ``flight.npz``: the known fault intervals of a real flight (optional).

    {"faults": [{"class": "MotorFault", "motor": 2, "start_s": 31.0, "end_s": 44.5, "note": "..."}]}

``class`` is one of core.contracts.CLASS_NAMES other than Healthy; ``motor`` (1..4, project order,
docs/flight_format.md) only for MotorFault and OverheatFault; times in s on the flight's clock
(``time`` of flight.npz, seconds from the log start). Everything outside the intervals is
unlabelled, not Healthy: a log says what was seen, not what was absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfdi.core.contracts import CLASS_NAMES
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json

MOTOR_CLASSES = ("MotorFault", "OverheatFault")


def load_labels(path: str | Path, time: np.ndarray) -> list[dict]:
    """The fault intervals of labels.json, checked against the flight's time span (one-line errors)."""
    data = read_json(path, "labels")
    faults = data.get("faults") if isinstance(data, dict) else None
    if not isinstance(faults, list):
        raise QuadfdiError(f"{path}: needs a 'faults' list")
    t0, t1 = float(time[0]), float(time[-1])
    for i, f in enumerate(faults):
        where = f"{path}: faults[{i}]"
        if f.get("class") not in CLASS_NAMES[1:]:
            raise QuadfdiError(f"{where}: class {f.get('class')!r} is not one of {', '.join(CLASS_NAMES[1:])}")
        if f["class"] in MOTOR_CLASSES and f.get("motor") not in (1, 2, 3, 4):
            raise QuadfdiError(f"{where}: {f['class']} needs 'motor' 1..4 (project order)")
        a, b = f.get("start_s"), f.get("end_s")
        if not (isinstance(a, (int, float)) and isinstance(b, (int, float)) and t0 <= a < b <= t1 + 1e-6):
            raise QuadfdiError(f"{where}: start_s/end_s must satisfy {t0:.2f} <= start_s < end_s <= {t1:.2f}")
    return faults
