"""Physics features relative to the vehicle's reference at the window's operating point (the
``*_ref`` baselines; the reference and what it expects sample by sample: train/vehicle_ref.py).

The physics features that describe the vehicle (train/features.py) are replaced by their deviation
from what the vehicle's own reference gives for the same window:

- ``share_dev{i}``: motor i's command share over the window (``thr_ratio{i}``) minus the window mean
  of the reference's share at each sample's forward speed and yaw rate; ``share_dev_max`` the largest
  (a damaged propeller's motor is commanded more than its healthy share).
- ``dT{i}_ref``: the window mean of motor i's temperature minus the four's mean, minus the reference's
  airborne mean of the same; ``dT_ref_max`` the largest.
- ``r_int_ref``: the sag per ampere per cell beyond the reference's: ``features.internal_resistance`` of
  the per-cell voltage with the reference's sag taken out, ``V_cell - sag_ref I`` (R_cell - R_ref, shrunk
  towards 0 as ``r_int`` is when the current hardly varies).
- ``{vib}_mean_ref``, ``{vib}_max_ref``: the window's mean and largest vibration minus the window mean of
  the reference's floor at each sample's collective.

The others (``v_cell_mean``, ``v_cell_slope``, the temperature offsets' slopes, ``soc_slope``) are kept as
they are: they describe the flight (pack charge, heating), not the airframe.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from quadfdi.train.features import MOTORS, VIBRATION_CHANNELS, check_windows, internal_resistance, \
    physics_feature_names, physics_features

KEPT = ("v_cell_mean", "v_cell_slope", *(f"dT{i}_slope" for i in MOTORS), "dT_slope_max", "soc_slope")


def ref_feature_names(channel_names: Sequence[str]) -> list[str]:
    names = list(KEPT) + ["r_int_ref"] + [f"share_dev{i}" for i in MOTORS] + ["share_dev_max"]
    names += [f"dT{i}_ref" for i in MOTORS] + ["dT_ref_max"]
    return names + [f"{v}_{s}_ref" for v in VIBRATION_CHANNELS if v in channel_names for s in ("mean", "max")]


def ref_features(x, channel_names: Sequence[str], cells, expect: np.ndarray, const: np.ndarray) -> np.ndarray:
    """(n, W, C) windows, (n,) cell counts (or None), ``expect`` (n, W, 4 + vibration metrics) and ``const``
    (n, 5) of ``VehicleRefs.windows`` -> (n, F) in ``ref_feature_names`` order."""
    a = check_windows(x, channel_names)
    names = list(channel_names)
    n, w = a.shape[:2]
    vibs = [v for v in VIBRATION_CHANNELS if v in names]
    if expect.shape != (n, w, 4 + len(vibs)) or const.shape != (n, 5):
        raise ValueError(f"expected series {expect.shape} and constants {const.shape} do not match windows {a.shape}")
    phys = physics_features(a, names, cells)
    pnames = physics_feature_names(names)
    kept = phys[:, [pnames.index(k) for k in KEPT]]
    ch = {c: a[:, :, names.index(c)] for c in names}
    k = np.ones(n) if cells is None else np.asarray(cells, np.float64)
    v_res = ch["V_b"] / k[:, None] - const[:, 4:5] * ch["I_b"]
    r_ref = internal_resistance(v_res, ch["I_b"])[:, None]
    ratio = phys[:, [pnames.index(f"thr_ratio{i}") for i in MOTORS]]
    share_dev = ratio - expect[:, :, :4].mean(axis=1)
    dt = phys[:, [pnames.index(f"dT{i}") for i in MOTORS]] - const[:, :4]
    cols = [kept, r_ref, share_dev, share_dev.max(axis=1, keepdims=True), dt, dt.max(axis=1, keepdims=True)]
    for j, v in enumerate(vibs):
        floor = expect[:, :, 4 + j].mean(axis=1, keepdims=True)
        cols += [ch[v].mean(axis=1, keepdims=True) - floor, ch[v].max(axis=1, keepdims=True) - floor]
    return np.concatenate(cols, axis=1)
