"""Per-window features for the non-neural baselines: window statistics and physics features.

Every function takes raw telemetry windows ``x`` of shape (n, W, C) -- n windows of W samples of C
channels, as ``formats.dataset.make_windows`` cuts them -- and the dataset's ``channel_names`` (C,).
Channels are looked up BY NAME, never by column index, so the paper dataset (23 channels) and the
realistic suite (25: the same plus ``vib_px4``, ``vib_ap``) both work. Slopes are least-squares
slopes against the window's normalised time t_i = i / (W - 1) in [0, 1] (as train/baseline.py and
the CNODE's path): a slope is the change across the window, in the channel's unit.

Window statistics (``stat_features``, 3 C features): each channel's mean, slope and std.

Physics features (``physics_features``), each one an observable a fault moves on a real vehicle:

- ``r_int``: internal-resistance estimate in ohm, minus the slope of V_b against I_b within the
  window, shrunk towards 0 when the current hardly varies:
  R = -cov(V, I) / (var(I) + I_FLOOR_A^2). For var(I) >> I_FLOOR_A^2 this is the least-squares
  dV/dI; at constant current (a window without throttle changes holds no information on R) it
  goes to 0 instead of dividing noise by noise.
- ``v_cell_mean``, ``v_cell_slope``: pack voltage per cell (V_b / cells when the cell count is
  known, else V_b itself).
- ``thr_ratio{i}``: motor i's mean command over the window divided by the mean of the four motors'
  mean commands (1 on a symmetric healthy hover); ``thr_ratio_max``: the largest ratio minus 1
  (max minus mean, in units of the mean).
- ``dT{i}``, ``dT{i}_slope``: motor i's temperature minus the mean of the four (K), its window mean
  and slope; ``dT_max``, ``dT_slope_max``: the largest of each. The temperature is the motor winding's
  (``T1..T4``, the simulator's) where the windows carry it, else motor i's ESC board's (``esc_temp1..4``,
  what a log carries: train/baselines_channels.py).
- ``{vib}_mean``, ``{vib}_max`` for every vibration channel present (``vib_px4``, ``vib_ap``).
- ``soc_slope``: the slope of the logged SoC.

Inputs are checked at entry: a ``ValueError`` names the shapes (or the missing channels).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

I_FLOOR_A = 0.25  # A: current std below which the resistance estimate is shrunk towards 0
MOTORS = (1, 2, 3, 4)
VIBRATION_CHANNELS = ("vib_px4", "vib_ap")
PHYSICS_CHANNELS = ("V_b", "I_b", "SoC", *(f"thr{i}" for i in MOTORS))  # and one TEMPERATURES set
TEMPERATURES = (tuple(f"T{i}" for i in MOTORS), tuple(f"esc_temp{i}" for i in MOTORS))  # windings, else ESCs


def temperature_channels(channel_names: Sequence[str]) -> tuple[str, ...]:
    """The four temperatures the ``dT`` features read: the windings' where present, else the ESCs'."""
    found = next((t for t in TEMPERATURES if all(c in channel_names for c in t)), None)
    if found is None:
        raise ValueError(f"physics features need T1..T4 or esc_temp1..4; the windows have {', '.join(channel_names)}")
    return found


def check_windows(x: Any, channel_names: Sequence[str]) -> np.ndarray:
    """(n, W, C) finite windows with C == len(channel_names), as float64; ValueError otherwise."""
    a = np.asarray(x)
    names = list(channel_names)
    if a.ndim != 3:
        raise ValueError(f"windows must have shape (n, W, C), found {a.shape}")
    if a.shape[1] < 2:
        raise ValueError(f"windows must hold at least 2 samples (W >= 2), found shape {a.shape}")
    if a.shape[2] != len(names):
        raise ValueError(f"windows have C = {a.shape[2]} channels (shape {a.shape}) but {len(names)} channel names")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"windows of shape {a.shape} contain NaN or inf")
    return a.astype(np.float64, copy=False)


def slope(x: np.ndarray) -> np.ndarray:
    """Least-squares slope along axis 1 against t in [0, 1]: (n, W) -> (n,), (n, W, C) -> (n, C)."""
    w = x.shape[1]
    tc = np.linspace(0.0, 1.0, w) - 0.5
    return np.tensordot(tc, x, axes=([0], [1])) / float(tc @ tc)


def stat_feature_names(channel_names: Sequence[str]) -> list[str]:
    return [f"{s}_{c}" for s in ("mean", "slope", "std") for c in channel_names]


def stat_features(x: Any, channel_names: Sequence[str]) -> np.ndarray:
    """(n, W, C) windows -> (n, 3 C) [mean_c..., slope_c..., std_c...] (``stat_feature_names`` order)."""
    a = check_windows(x, channel_names)
    return np.concatenate([a.mean(axis=1), slope(a), a.std(axis=1)], axis=1)


def internal_resistance(v: np.ndarray, i: np.ndarray) -> np.ndarray:
    """(n, W) voltage and current -> (n,) R = -cov(V, I) / (var(I) + I_FLOOR_A^2) in ohm."""
    vc = v - v.mean(axis=1, keepdims=True)
    ic = i - i.mean(axis=1, keepdims=True)
    return -(vc * ic).mean(axis=1) / ((ic * ic).mean(axis=1) + I_FLOOR_A ** 2)


def physics_feature_names(channel_names: Sequence[str]) -> list[str]:
    names = ["r_int", "v_cell_mean", "v_cell_slope"]
    names += [f"thr_ratio{i}" for i in MOTORS] + ["thr_ratio_max"]
    names += [f"dT{i}" for i in MOTORS] + [f"dT{i}_slope" for i in MOTORS] + ["dT_max", "dT_slope_max"]
    names += [f"{v}_{s}" for v in VIBRATION_CHANNELS if v in channel_names for s in ("mean", "max")]
    return names + ["soc_slope"]


def physics_features(x: Any, channel_names: Sequence[str], cells: Any = None) -> np.ndarray:
    """(n, W, C) windows -> (n, F) physics features in ``physics_feature_names`` order.

    ``cells``: (n,) the pack's cell count per window (e.g. ``pack_cells[traj]``), or None when
    unknown (then the voltage features use V_b itself).
    """
    a = check_windows(x, channel_names)
    names = list(channel_names)
    missing = [c for c in PHYSICS_CHANNELS if c not in names]
    if missing:
        raise ValueError(f"physics features need channels {', '.join(missing)}; the windows have {', '.join(names)}")
    temps = temperature_channels(names)
    n = a.shape[0]
    ch = {c: a[:, :, names.index(c)] for c in names}  # name -> (n, W)
    v = ch["V_b"]
    if cells is not None:
        k = np.asarray(cells, dtype=np.float64)
        if k.shape != (n,) or not np.all(k >= 1):
            raise ValueError(f"cells must have shape ({n},) with values >= 1, found shape {k.shape}")
        v = v / k[:, None]
    thr = np.stack([ch[f"thr{i}"].mean(axis=1) for i in MOTORS], axis=1)  # (n, 4)
    mean_thr = thr.mean(axis=1, keepdims=True)
    ratio = thr / np.where(np.abs(mean_thr) > 1e-9, mean_thr, 1e-9)  # a window at zero command: huge, not inf
    temp = np.stack([ch[c] for c in temps], axis=2)  # (n, W, 4)
    dtemp = temp - temp.mean(axis=2, keepdims=True)
    dt_mean, dt_slope = dtemp.mean(axis=1), slope(dtemp)  # (n, 4) each
    cols = [internal_resistance(ch["V_b"], ch["I_b"])[:, None], v.mean(axis=1)[:, None], slope(v)[:, None],
            ratio, ratio.max(axis=1, keepdims=True) - 1.0,
            dt_mean, dt_slope, dt_mean.max(axis=1, keepdims=True), dt_slope.max(axis=1, keepdims=True)]
    for name in VIBRATION_CHANNELS:
        if name in ch:
            cols += [ch[name].mean(axis=1)[:, None], ch[name].max(axis=1)[:, None]]
    cols.append(slope(ch["SoC"])[:, None])
    return np.concatenate(cols, axis=1)
