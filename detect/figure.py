"""detect.png: the profile's channels over the flight, the availability of the model's inputs, the
fault probability per window, alarms shaded."""

from __future__ import annotations

from pathlib import Path


from quadfdi.core.plotting import pyplot, save_png

GROUPS = (("attitude, rad", ("roll", "pitch")), ("body rates, rad/s", ("p", "q", "r")),
          ("velocity (heading frame), m/s", ("vx_h", "vy_h", "vz")), ("per cell, V", ("v_cell",)),
          ("over hover", ("i_rel", "m1_rel", "m2_rel", "m3_rel", "m4_rel")), ("vibration, m/s^2", ("vib",)))


def draw(path: str | Path, result: dict) -> Path:
    plt = pyplot()
    fi, rec, arr = result["inputs"], result["record"], result["arrays"]
    groups = [(label, [c for c in chans if c in fi.channel_names]) for label, chans in GROUPS]
    groups = [g for g in groups if g[1]]
    fig, axes = plt.subplots(len(groups) + 2, 1, figsize=(10, 1.6 * (len(groups) + 2)), sharex=True)
    spans = [(a["start_s"], a["end_s"] if a["end_s"] is not None else fi.time[-1], a["class"]) for a in rec["alarms"]]
    for ax, (label, chans) in zip(axes, groups):
        for c in chans:
            ax.plot(fi.time, fi.x[:, fi.channel_names.index(c)], lw=0.7, label=c)
        ax.set_ylabel(label, fontsize=7)
        ax.legend(fontsize=6, loc="upper right", ncol=len(chans))
    ax = axes[-2]
    ax.fill_between(fi.time, 0, fi.used.astype(float), step="mid", alpha=0.4, label="inputs available")
    ax.axvline(fi.time[fi.hover.freeze], color="k", ls="--", lw=0.8, label="hover estimate frozen")
    ax.set_ylabel("available", fontsize=7)
    ax.legend(fontsize=6, loc="upper right")
    ax = axes[-1]
    p_fault = 1.0 - arr["proba"][:, list(arr["class_names"]).index("Healthy")]
    ax.plot(arr["t_end"], p_fault, ".-", lw=0.7, ms=3, label="p_fault (window end)")
    ax.axhline(rec["policy"]["threshold"], color="r", lw=0.6, ls=":", label="threshold")
    ax.set_ylim(-0.02, 1.02)
    ax.set_ylabel("p_fault", fontsize=7)
    ax.set_xlabel("time from log start, s")
    ax.legend(fontsize=6, loc="upper right")
    for a in axes:
        for s, e, _ in spans:
            a.axvspan(s, e, color="red", alpha=0.15)
    title = f"{rec['flight']}: {rec['net']} {rec['precision']} ({rec['runtime']}), profile {rec['profile']}: "
    title += f"{len(spans)} alarm(s)" + (": " + ", ".join(sorted({c for *_, c in spans})) if spans else "")
    axes[0].set_title(title, fontsize=8)
    fig.tight_layout()
    return save_png(fig, path)
