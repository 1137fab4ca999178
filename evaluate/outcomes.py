"""Per-flight outcomes of one prediction set under one alarm policy: the counts every metric sums.

Each flight contributes additive quantities (below); a metric is a ratio of their sums over
flights (evaluate.metrics), so the bootstrap resamples flights and sums these counts instead of
re-running any metric code.

| key | per flight |
|---|---|
| conf | (K, K) window confusion counts, row = true label, column = arg-max class |
| healthy, fault | 1 for a healthy / faulty flight |
| exposure_h | healthy flights: decided windows (Flights.voting) x window spacing, in hours (0 for fault flights) |
| fa | healthy flights: alarms raised (episodes) |
| detected | fault flights: the alarm is active at some window ending at or after onset_s |
| delay_onset | detected: end time of that first active window - onset_s (s) |
| thr | fault flights whose severity crosses the threshold (detectable_s finite) |
| detected_thr, delay_thr | the same, from detectable_s |
| early | thr flights with an alarm raised at a window ending before detectable_s |
| pre_onset | fault flights with an alarm raised before onset_s (a false alarm on a fault flight) |
| class_ok | detected and the alarm's class at the detecting window is the flight's fault class |
| motor_n, motor_ok | detected rotor-side flights (fault_motor >= 0) of a set with motor_proba; reported motor (core.alarm rule 5) right at detection |
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.alarm import reported_motor, rotor_columns
from quadfdi.evaluate.alarms import set_trace
from quadfdi.evaluate.load import DatasetInfo, Flights

SCALAR_KEYS = ("healthy", "fault", "exposure_h", "fa", "detected", "delay_onset", "thr", "detected_thr", "delay_thr",
               "early", "pre_onset", "class_ok", "motor_n", "motor_ok")


def confusion(fl: Flights) -> np.ndarray:
    """(F, K, K) per-flight window confusion counts of the arg-max decision."""
    k = len(fl.class_names)
    pred = fl.proba.argmax(axis=2)
    f = np.repeat(np.arange(fl.rows.size)[:, None], pred.shape[1], axis=1)
    conf = np.zeros((fl.rows.size, k, k))
    v = fl.valid
    np.add.at(conf, (f[v], fl.y_true[v], pred[v]), 1.0)
    return conf


def _first(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row: whether any window is set, and the first one's index (0 if none)."""
    return mask.any(axis=1), mask.argmax(axis=1)


def alarm_outcomes(fl: Flights, info: DatasetInfo, policy: dict, reps: int = 1, classes: bool = True
                   ) -> dict[str, np.ndarray]:
    """The alarm rows of the table above for ``reps`` stacked copies of the flights (the sweep stacks
    the grid: policy values may be (reps * F,) arrays); returns (reps * F,) arrays. ``classes=False``
    (the sweep): class_ok and motor_ok are not computed (0)."""
    a = info.arrays
    tile = (lambda x: np.concatenate([x] * reps)) if reps > 1 else (lambda x: x)
    tr = set_trace(fl, policy, reps, classes)
    t_end = tile(fl.t_end)
    cls = tile(a["fault_class"][fl.rows].astype(np.int64))
    onset = tile(np.nan_to_num(a["onset_s"][fl.rows], nan=np.inf))
    det_s = tile(a["detectable_s"][fl.rows])
    motor = tile(a["fault_motor"][fl.rows].astype(np.int64))
    healthy, fault = cls == 0, cls != 0
    n_valid = tile(fl.voting()).sum(axis=1)  # exposure: the decided windows, as detect's exposure_s
    out = {"healthy": healthy * 1.0, "fault": fault * 1.0,
           "exposure_h": np.where(healthy, n_valid * fl.stride_s / 3600.0, 0.0),
           "fa": np.where(healthy, tr.raised.sum(axis=1), 0) * 1.0}
    te = np.nan_to_num(t_end, nan=-np.inf)  # padding never counts as after onset
    hit, i = _first(tr.active & (te >= onset[:, None]))
    hit &= fault
    rows = np.arange(hit.size)
    out["detected"] = hit * 1.0
    out["delay_onset"] = np.where(hit, t_end[rows, i] - np.where(np.isfinite(onset), onset, 0.0), 0.0)
    thr = fault & np.isfinite(det_s)
    det_fill = np.where(thr, det_s, np.inf)
    hit_t, j = _first(tr.active & (te >= det_fill[:, None]))
    hit_t &= thr
    out["thr"], out["detected_thr"] = thr * 1.0, hit_t * 1.0
    out["delay_thr"] = np.where(hit_t, t_end[rows, j] - np.where(thr, det_s, 0.0), 0.0)
    before = lambda lim: (tr.raised & (np.nan_to_num(t_end, nan=np.inf) < lim[:, None])).any(axis=1)  # noqa: E731
    out["early"] = (thr & before(det_fill)) * 1.0
    out["pre_onset"] = (fault & before(onset)) * 1.0
    out["class_ok"] = (hit & (tr.cls[rows, i] == cls)) * 1.0
    rotor = hit & (motor >= 0) & (fl.motor is not None)
    out["motor_n"] = rotor * 1.0
    # core.alarm rule 5, as detect reports it: no motor for a non-rotor-side alarm class (counted wrong)
    shown = reported_motor(tr.cls[rows, i], tr.motor[rows, i], rotor_columns(fl.class_names))
    out["motor_ok"] = (rotor & (shown == motor)) * 1.0
    return out


def flight_outcomes(fl: Flights, info: DatasetInfo, policy: dict) -> dict[str, np.ndarray]:
    """Every row of the table above for one prediction set under one policy."""
    out = alarm_outcomes(fl, info, policy)
    out["conf"] = confusion(fl)
    return out
