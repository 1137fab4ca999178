"""Percentile bootstrap by flight: resample flights, sum their counts, recompute the ratios.

A replicate is a multinomial draw of how many times each flight (the resampling unit; flights of
every simulator seed are units of one pool) is taken, ``weights`` (B, F); the replicate's sums
are ``weights @ counts``, so no metric code runs per replicate. Paired comparisons use the same
weights for both models (the same resampled flights), so the flight-to-flight variation they
share cancels in the difference.
"""

from __future__ import annotations

import zlib

import numpy as np

from quadfdi.evaluate.metrics import HEADLINE, metrics_from_sums, sum_flights


def draw_weights(units: list[tuple[str, int]], replicates: int, seed: int) -> np.ndarray:
    """(B, F) resampling counts of the flights ``units`` (dataset, row); seeded by the config seed and
    the units themselves, so the same flights get the same replicates in every model's evaluation."""
    key = zlib.crc32(repr(sorted(units)).encode())
    rng = np.random.default_rng([seed, key])
    f = len(units)
    return rng.multinomial(f, np.full(f, 1.0 / f), size=replicates).astype(np.float64)


def percentile_interval(samples: np.ndarray, ci: float) -> tuple[float | None, float | None]:
    ok = samples[np.isfinite(samples)]
    if ok.size < 0.5 * samples.size:  # undefined in most replicates (e.g. no fault flight drawn)
        return None, None
    a = (1.0 - ci) / 2 * 100
    lo, hi = np.percentile(ok, [a, 100 - a])
    return float(lo), float(hi)


def _num(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def intervals(stats: dict[str, np.ndarray], weights: np.ndarray, ci: float) -> dict[str, dict]:
    """Each headline metric: {"value", "lo", "hi"} (value on the flights themselves)."""
    point = metrics_from_sums(sum_flights(stats))
    reps = metrics_from_sums(sum_flights(stats, weights))
    out = {}
    for name in HEADLINE:
        lo, hi = percentile_interval(reps[name], ci)
        out[name] = {"value": _num(point[name]), "lo": lo, "hi": hi}
    return out


def point_and_replicates(stats: dict[str, np.ndarray], weights: np.ndarray) -> tuple[dict, dict]:
    """Metrics on the flights themselves and per replicate (B,)."""
    return metrics_from_sums(sum_flights(stats)), metrics_from_sums(sum_flights(stats, weights))


def paired(a: tuple[dict, dict], b: tuple[dict, dict], ci: float, names: tuple[str, ...]) -> dict[str, dict]:
    """Metric of a minus metric of b on the same flights and the same replicates: {"diff", "lo", "hi"};
    ``a`` and ``b`` are ``point_and_replicates`` of both models under the same weights."""
    (pa, ra), (pb, rb) = a, b
    out = {}
    for name in names:
        lo, hi = percentile_interval(ra[name] - rb[name], ci)
        out[name] = {"diff": _num(pa[name] - pb[name]), "lo": lo, "hi": hi}
    return out
