"""Two `quadfdi detect` output folders (e.g. --runtime ort and cpp on one flight): the same alarms?

    PYTHONPATH=. python scripts/cmp_detect.py DIR_A DIR_B [DIR_A2 DIR_B2 ...]

Per pair: decided windows, the alarms of A (start, end, class, motor), whether B's are the same, and
the largest |difference| of the per-window probabilities (windows.npz ``proba``, ``motor_proba``).
Exit 1 when any pair's alarms differ.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def alarms(d: Path) -> tuple[dict, list[tuple]]:
    rec = json.loads((d / "alarms.json").read_text())
    return rec, [(a["start_s"], a["end_s"], a["class"], a.get("motor")) for a in rec["alarms"]]


def main(argv: list[str]) -> int:
    if len(argv) < 2 or len(argv) % 2:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    differ = False
    for a, b in zip(argv[0::2], argv[1::2]):
        (ra, al_a), (_, al_b) = alarms(Path(a)), alarms(Path(b))
        wa, wb = np.load(Path(a) / "windows.npz"), np.load(Path(b) / "windows.npz")
        dp = max((float(np.nanmax(np.abs(wa[k] - wb[k]))) for k in ("proba", "motor_proba")
                  if k in wa.files and k in wb.files and wa[k].size and np.isfinite(wa[k]).any()), default=0.0)
        same = al_a == al_b
        differ |= not same
        print(f"{a} vs {b}: decided {ra['decided_windows']}/{ra['windows']} ({ra['exposure_s']} s); alarms {al_a}; "
              f"same: {same}; max |dp| {dp:.2g}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
