"""Delay from onset on the fault flights BOTH models of a pair detect: a like-for-like speed figure.

``delay_onset_s`` averages each model's OWN detections, so the difference of two models' delays
mixes how fast each alarms with which flights each catches (a flight only one model catches, late,
moves that model's mean alone). Here, per pair of models on one test set and on the flights both
were evaluated on (docs/evaluation.md "Delay on common flights"):

- a model **detects** a flight when every one of its train seeds that saw the flight detects it:
  the per-flight ``detected`` that evaluate.protocol pools is the train-seed mean of 0/1 values, so
  it is exactly 1.0 then (a sum of n ones is n exactly, and n / n is 1 exactly, in floating point);
  its **delay** on the flight is the train-seed mean of ``delay_onset`` (each seed's delay, all
  seeds detecting);
- the **common flights** are the fault flights both models detect; per model the mean delay over
  them, and the paired difference a - b;
- the interval: the pair's replicate weights (the same resampled flights as the pair's other paired
  differences). A flight's membership in the common set depends on that flight alone, so the common
  set of a resample is the drawn flights that are common, each as often as drawn: a replicate's
  figure is sum_f w_f c_f delay_f / sum_f w_f c_f (c_f: 1 for a common flight). A replicate that
  draws no common flight is undefined (the interval needs at least half of the replicates defined).
"""

from __future__ import annotations

import numpy as np

from quadfdi.evaluate.bootstrap import percentile_interval


def common_flights(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> np.ndarray:
    """(F,) bool: fault flights every train seed of both models detects (per-flight stats of the same flights)."""
    return (a["fault"] > 0) & (a["detected"] == 1.0) & (b["detected"] == 1.0)


def _means(cols: np.ndarray) -> np.ndarray:
    """cols (..., 3): [common count, delay sum a, delay sum b] -> (..., 2) mean delays (NaN: no common flight)."""
    n = cols[..., :1]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, cols[..., 1:] / np.where(n > 0, n, 1.0), np.nan)


def _num(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def common_delay(a: dict[str, np.ndarray], b: dict[str, np.ndarray], weights: np.ndarray, ci: float) -> dict:
    """Mean delay from onset of a and of b on their common flights, the difference a - b, each with
    its flight-bootstrap interval under ``weights`` (B, F): {"flights", "a", "b", "diff"}."""
    c = common_flights(a, b)
    cols = np.stack([c * 1.0, np.where(c, a["delay_onset"], 0.0), np.where(c, b["delay_onset"], 0.0)], axis=1)
    point = _means(cols.sum(axis=0))
    reps = _means(weights @ cols)  # (B, 2)
    out = {"flights": int(c.sum())}
    for i, name in enumerate(("a", "b")):
        lo, hi = percentile_interval(reps[:, i], ci)
        out[name] = {"value": _num(point[i]), "lo": lo, "hi": hi}
    lo, hi = percentile_interval(reps[:, 0] - reps[:, 1], ci)
    out["diff"] = {"diff": _num(point[0] - point[1]), "lo": lo, "hi": hi}
    return out
