"""One trajectory drawn like the paper's Fig. 4 and Figs. 13-16: true states and fault variables."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfdi.core.plotting import pyplot, save_png


def _series(ds, row: int, name: str) -> np.ndarray | None:
    """The true state ``name`` of trajectory ``row`` (falls back to the measured channel)."""
    names = [str(s) for s in ds["state_names"]]
    if name in names:
        return ds["states"][row, :, names.index(name)]
    chans = ds.channel_names
    if name in chans:
        return ds["telemetry"][row, :, chans.index(name)]
    return None


def plot_groups(axes, ds, row: int, groups, t: np.ndarray) -> None:
    """One panel per (title, channel names, scale) group of trajectory ``row``, on ``axes`` in order."""
    for ax, (title, names, scale) in zip(axes, groups):
        for name in names:
            y = _series(ds, row, name)
            if y is not None:
                ax.plot(t, y * scale, lw=1, label=name)
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=7, loc="best")


def plot_trajectory(ds, row: int, out: str | Path) -> Path:
    """Draw trajectory ``row`` of dataset ``ds`` into the PNG ``out`` (atomic write)."""
    plt = pyplot()
    t = ds["time"]
    cls = int(ds["fault_class"][row])
    onset, det = float(ds["onset_s"][row]), float(ds["detectable_s"][row])
    panels = [
        ("position [m]", ["x", "y", "z"], 1.0),
        ("attitude [deg]", ["roll", "pitch", "yaw"], 180.0 / np.pi),
        ("state of charge [-]", ["SoC"], 1.0),
        ("bus voltage [V]", ["V_b"], 1.0),
        ("bus current [A]", ["I_b"], 1.0),
        ("motor temperature [°C]", ["T1", "T2", "T3", "T4"], 1.0),
        ("throttle command [-]", ["thr1", "thr2", "thr3", "thr4"], 1.0),
    ]
    fig, axes = plt.subplots(3, 3, figsize=(15, 10), sharex=True)
    axes = axes.ravel()
    plot_groups(axes, ds, row, panels, t)
    ax = axes[len(panels)]
    if "effectiveness" in ds.arrays:
        for m in range(4):
            ax.plot(t, ds["effectiveness"][row, :, m], lw=1, label=f"motor {m + 1}")
        ax.set_title("effectiveness c_i d_m [-]", fontsize=10)
    else:  # the realistic suite logs vibration metrics instead of recording effectiveness
        for name in ("vib_px4", "vib_ap"):
            if name in ds.channel_names:
                ax.plot(t, ds["telemetry"][row, :, ds.channel_names.index(name)], lw=1, label=name)
        ax.set_title("vibration metrics [m/s^2]", fontsize=10)
    ax.legend(fontsize=7)
    ax = axes[len(panels) + 1]
    ax.plot(t, ds["severity"][row], color="k", lw=1.2, label="severity s_k")
    ax.axhline(ds.severity_threshold, color="r", ls=":", lw=1, label="s_thr")
    ax.set_title("fault severity [-]", fontsize=10)
    ax.legend(fontsize=7)
    for ax in axes:
        if np.isfinite(onset) and cls:
            ax.axvline(onset, color="gray", ls=":", lw=0.8)
        if np.isfinite(det):
            ax.axvline(det, color="gray", ls="--", lw=0.8)
        ax.grid(alpha=0.3)
    for ax in axes[-3:]:
        ax.set_xlabel("time [s]")
    motor = int(ds["fault_motor"][row])
    extra = f", motor {motor + 1}" if motor >= 0 else ""
    det_txt = f", detectable {det:.2f} s" if np.isfinite(det) else ""
    on_txt = f", onset {onset:.2f} s" if cls else ""
    from quadfdi.formats.dataset import class_names

    fig.suptitle(f"trajectory {row}: {class_names(ds.arrays)[cls]}{extra}{on_txt}{det_txt} (dotted: onset, dashed: detectable)")
    fig.tight_layout()
    return save_png(fig, out)
