"""Spreads of a quantity within a flight and between flights, and the test that finds a flight whose
mean disagrees with the others'.

Within a flight: the std over its selected samples, and the std of its **2 s window means**
(``WINDOW`` = 50 grid samples, non-overlapping, inside contiguous runs of selected samples; a run's
remainder shorter than a window is left out). Samples 40 ms apart are strongly correlated, window
means 2 s apart much less, so ``se = window_std / sqrt(windows)`` is the standard error of the
flight's mean. Between flights: the std (ddof 1) of the flights' means.

**Disagreement**: flight i disagrees on a quantity when ``|mean_i - mean of the others| > K * s`` with
``s = sqrt(se_i^2 + sum_j se_j^2 / (n - 1)^2)`` over the others j: the between-flight spread that the
measurement noise of the flight means alone would give. The others' own std cannot be the yardstick:
two sessions of two flights each (CrazyPAD's E8 and E9) hide in it (a flight from one session sits
within 1 std of the three others). ``K = 3``: with normal noise a flight passes 3 s by chance 0.27 %
of the time, so a Crazyflie reference of 4 flights and 5 compared quantities (20 comparisons) warns
falsely about once in 19 references; K = 2 (4.6 % each) would in 3 of 5.
"""

from __future__ import annotations

import math

import numpy as np

from quadfdi.core.resample import GRID_DT

WINDOW = 50  # grid samples: 2.0 s
K_DISAGREE = 3.0


def runs(sel: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) of each run of consecutive True."""
    s = np.concatenate([[0], np.asarray(sel, np.int8), [0]])
    d = np.flatnonzero(np.diff(s))
    return list(zip(d[0::2].tolist(), d[1::2].tolist()))


def window_means(x: np.ndarray, sel: np.ndarray, n: int = WINDOW) -> np.ndarray:
    """Means of non-overlapping ``n``-sample windows inside each run of ``sel`` with finite ``x``."""
    out = []
    for a, b in runs(np.asarray(sel, bool) & np.isfinite(x)):
        out += [float(x[i:i + n].mean()) for i in range(a, b - n + 1, n)]
    return np.array(out)


def _std(x: np.ndarray) -> float | None:
    return float(np.std(x, ddof=1)) if len(x) >= 2 else None


def flight_stat(x: np.ndarray, sel: np.ndarray) -> dict:
    """A flight's ``mean``, ``within_std``, ``window_std``, ``windows`` and ``seconds`` over its selected,
    finite samples (mean None when there is none)."""
    v = x[np.asarray(sel, bool) & np.isfinite(x)]
    w = window_means(x, sel)
    return {"mean": float(v.mean()) if len(v) else None, "within_std": _std(v), "window_std": _std(w),
            "windows": int(len(w)), "seconds": round(len(v) * GRID_DT, 2)}


def flight_se(st: dict) -> float | None:
    """Standard error of a flight's mean from its window means (None with fewer than two windows)."""
    return st["window_std"] / math.sqrt(st["windows"]) if st["window_std"] is not None else None


def _rms(values) -> float | None:
    v = [x for x in values if x is not None]
    return float(math.sqrt(sum(x * x for x in v) / len(v))) if v else None


def combine(per_flight: list[dict]) -> dict:
    """The reference's statistic of a quantity from each flight's (docs/formats.md "Vehicle reference")."""
    means = np.array([f["mean"] for f in per_flight if f["mean"] is not None])
    return {"mean": float(means.mean()) if len(means) else None, "between_std": _std(means),
            "within_std": _rms(f["within_std"] for f in per_flight),
            "window_std": _rms(f["window_std"] for f in per_flight),
            "se": _rms(flight_se(f) for f in per_flight),
            "seconds": round(sum(f["seconds"] for f in per_flight), 2), "flights": per_flight}


def disagreements(per_flight: list[dict], k: float = K_DISAGREE) -> list[dict]:
    """Each flight whose mean is more than ``k`` noise spreads from the others' mean (module docstring):
    index, its mean, the others' mean and the ratio ``z``."""
    out = []
    n = len(per_flight)
    if n < 2:
        return out
    for i, st in enumerate(per_flight):
        others = [per_flight[j] for j in range(n) if j != i]
        ses = [flight_se(o) for o in others] + [flight_se(st)]
        if st["mean"] is None or any(o["mean"] is None for o in others) or any(s is None for s in ses):
            continue
        rest = float(np.mean([o["mean"] for o in others]))
        spread = math.sqrt(ses[-1] ** 2 + sum(s * s for s in ses[:-1]) / (n - 1) ** 2)
        z = abs(st["mean"] - rest) / spread if spread > 0 else math.inf
        if z > k:
            out.append({"flight": i, "mean": st["mean"], "others": rest, "z": z, "spread": spread})
    return out
