"""The alarm policy chosen on validation flights only: sweep the [evaluate] grid, apply the rule.

Grid: every threshold x k/n x clear_m of [evaluate] (latch from [alarm]). For each model, each grid
policy runs on the validation flights of all its (sim seed, train seed) prediction sets; counts
are pooled (summed) over them. The rule, in order:

1. eligible: validation false alarms per healthy flight-hour <= evaluate.target_fa_per_h (if no
   policy qualifies: the policies with the fewest false alarms per hour);
2. among them the highest detection rate (fewest missed faults);
3. then the shortest mean delay from fault onset;
4. then the first in grid order (thresholds, then k/n, then clear_m, as listed).

Test sets are never touched here; the choice and the whole sweep go to evaluation.json.
"""

from __future__ import annotations

import itertools

import numpy as np

from quadfdi.core.alarm import AlarmConfig
from quadfdi.evaluate.config import EvaluateConfig, parse_kn
from quadfdi.evaluate.load import DatasetInfo, Flights
from quadfdi.evaluate.metrics import metrics_from_sums
from quadfdi.evaluate.outcomes import SCALAR_KEYS, alarm_outcomes

VALIDATION = "validation"


def grid(ev: EvaluateConfig, alarm: AlarmConfig) -> list[dict]:
    out = []
    for t, kn, m in itertools.product(ev.thresholds, ev.kn, ev.clear_m):
        k, n = parse_kn(kn)
        out.append({"threshold": float(t), "k": k, "n": n, "clear_m": int(m), "latch": bool(alarm.latch)})
    return out


def sweep(sets: list[Flights], infos: dict[str, DatasetInfo], policies: list[dict]) -> list[dict]:
    """Pooled validation counts of every policy, for the sets of one model: one row per policy."""
    p = len(policies)
    sums = {key: np.zeros(p) for key in SCALAR_KEYS}
    for fl in sets:
        info = infos[fl.dataset]
        code = info.split_names.index(VALIDATION) if VALIDATION in info.split_names else -1
        val = fl.subset(fl.split == code)
        f = val.rows.size
        if f == 0:
            continue
        stacked = {key: np.repeat([pol[key] for pol in policies], f) for key in ("threshold", "k", "n", "clear_m", "latch")}
        out = alarm_outcomes(val, info, stacked, reps=p, classes=False)
        for key in SCALAR_KEYS:
            sums[key] += out[key].reshape(p, f).sum(axis=1)
    rows = []
    for i, pol in enumerate(policies):
        s = {key: sums[key][i] for key in SCALAR_KEYS}
        m = metrics_from_sums(dict(s, conf=np.zeros((1, 1))))
        rows.append(dict(pol, fa=float(s["fa"]), exposure_h=float(s["exposure_h"]), faults=float(s["fault"]),
                         fa_per_h=_f(m["fa_per_h"]), detection_rate=_f(m["detection_rate"]),
                         delay_onset_s=_f(m["delay_onset_s"])))
    return rows


def _f(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def choose(rows: list[dict], target_fa_per_h: float) -> int:
    """Index of the chosen row under the rule of the module docstring."""
    fa = np.array([np.inf if r["fa_per_h"] is None else r["fa_per_h"] for r in rows])
    eligible = np.flatnonzero(fa <= target_fa_per_h)
    if eligible.size == 0:
        eligible = np.flatnonzero(fa == fa.min())
    det = lambda i: -1.0 if rows[i]["detection_rate"] is None else rows[i]["detection_rate"]  # noqa: E731
    delay = lambda i: np.inf if rows[i]["delay_onset_s"] is None else rows[i]["delay_onset_s"]  # noqa: E731
    return int(min(eligible, key=lambda i: (-det(i), delay(i), i)))
