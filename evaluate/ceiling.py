"""The label-noise ceiling: the best window-level macro F1 and accuracy any
classifier can reach, given that labels near the severity threshold are ambiguous.

A window ending at sample e is labelled with the flight's fault class when severity[e] >=
severity_threshold, else Healthy (docs/formats.md). The crossing time is not observable to better
than the window spacing, so a window is *ambiguous* when moving its end by one stride either way
(e - stride, e + stride, clipped to the flight) would change its label. An ambiguous window is
counted as unavoidably wrong half of the time -- the ideal classifier is a coin between the two
labels it could carry (its label and the flight's other one: Healthy <-> the fault class) -- and
every other window as right. The expected confusion matrix (0.5 on the diagonal and 0.5 in the
other label's column for each ambiguous window) gives the ceiling's macro F1 (evaluate.metrics).

The windows are those of the prediction sets (any one per dataset: every model is evaluated on
the same windows), pooled over the simulator seeds of a test set.
"""

from __future__ import annotations

import numpy as np

from quadfdi.evaluate.load import DatasetInfo, Flights


def expected_confusion(fl: Flights, info: DatasetInfo) -> tuple[np.ndarray, np.ndarray]:
    """(F, K, K) expected confusion of the ideal classifier and (F,) ambiguous windows per flight."""
    a = info.arrays
    time, sev = a["time"], a["severity"][fl.rows]  # (T,), (F, T)
    thr = float(a["severity_threshold"])
    n_t = time.size
    dt = float(time[1] - time[0]) if n_t > 1 else 1.0
    stride = max(int(round(fl.stride_s / dt)), 1)
    e = np.clip(np.searchsorted(time, np.nan_to_num(fl.t_end, nan=0.0) - 1e-9 * dt), 0, n_t - 1)  # (F, W)
    f_idx = np.arange(fl.rows.size)[:, None]
    label = lambda idx: sev[f_idx, np.clip(idx, 0, n_t - 1)] >= thr  # noqa: E731
    here = label(e)
    amb = ((label(e - stride) != here) | (label(e + stride) != here)) & fl.valid
    cls = a["fault_class"][fl.rows].astype(np.int64)
    y = np.where(here, cls[:, None], 0)
    other = np.where(here, 0, cls[:, None])
    k = len(fl.class_names)
    conf = np.zeros((fl.rows.size, k, k))
    ff = np.broadcast_to(f_idx, y.shape)
    v = fl.valid
    np.add.at(conf, (ff[v], y[v], y[v]), np.where(amb[v], 0.5, 1.0))
    np.add.at(conf, (ff[amb], y[amb], other[amb]), 0.5)
    return conf, amb.sum(axis=1)
