"""Headline metrics as ratios of summed per-flight counts (evaluate.outcomes), vectorised over a
leading replicate axis, and the exact Poisson (Garwood) interval of a false-alarm rate.

Macro F1 averages the per-class F1 over the classes with at least one true window in the pooled
flights (a class absent from a test set -- an incipient fault that never crosses the threshold --
is left out rather than scored 0; train/metrics.py scores it 0 because its splits hold every class).
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

# name -> (numerator key, denominator key) of a ratio of sums; macro_f1 and accuracy come from conf.
RATIOS = {
    "fa_per_h": ("fa", "exposure_h"),
    "detection_rate": ("detected", "fault"),
    "delay_onset_s": ("delay_onset", "detected"),
    "delay_thr_s": ("delay_thr", "detected_thr"),
    "early_rate": ("early", "thr"),
    "class_acc": ("class_ok", "detected"),
    "motor_acc": ("motor_ok", "motor_n"),
}
HEADLINE = ("macro_f1", "accuracy", *RATIOS)
COUNTS = ("fa", "exposure_h", "healthy", "fault", "detected", "early", "pre_onset", "motor_n")


def _div(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a, b = np.asarray(a, float), np.asarray(b, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(b > 0, a / np.where(b > 0, b, 1.0), np.nan)


def macro_f1_accuracy(conf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """conf (..., K, K) summed confusion counts -> macro F1 and accuracy (...)."""
    tp = np.diagonal(conf, axis1=-2, axis2=-1)
    support, predicted = conf.sum(axis=-1), conf.sum(axis=-2)
    f1 = _div(2 * tp, support + predicted)
    present = support > 0
    macro = _div(np.where(present, np.nan_to_num(f1), 0.0).sum(axis=-1), present.sum(axis=-1))
    return macro, _div(tp.sum(axis=-1), conf.sum(axis=(-2, -1)))


def metrics_from_sums(sums: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every headline metric from summed counts (arrays with any leading replicate shape)."""
    out = {}
    out["macro_f1"], out["accuracy"] = macro_f1_accuracy(sums["conf"])
    for name, (num, den) in RATIOS.items():
        out[name] = _div(sums[num], sums[den])
    return out


def sum_flights(stats: dict[str, np.ndarray], weights: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Sum per-flight stats (F, ...) over flights, or per replicate with weights (B, F) -> (B, ...)
    (one matrix product over all the stats side by side)."""
    if weights is None:
        return {key: a.sum(axis=0) for key, a in stats.items()}
    keys = list(stats)
    flat = [stats[k].reshape(stats[k].shape[0], -1) for k in keys]
    summed = weights @ np.concatenate(flat, axis=1)
    out, col = {}, 0
    for key, f in zip(keys, flat):
        out[key] = summed[:, col:col + f.shape[1]].reshape((weights.shape[0],) + stats[key].shape[1:])
        col += f.shape[1]
    return out


def garwood(count: float, exposure: float, ci: float = 0.95) -> tuple[float | None, float | None]:
    """Exact Poisson interval on count / exposure: chi2(a/2, 2n)/2 and chi2(1-a/2, 2n+2)/2 over the exposure."""
    if exposure <= 0:
        return None, None
    a = 1.0 - ci
    lo = 0.0 if count == 0 else chi2.ppf(a / 2, 2 * count) / 2
    hi = chi2.ppf(1 - a / 2, 2 * count + 2) / 2
    return float(lo / exposure), float(hi / exposure)
