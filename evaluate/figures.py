"""The validation sweep figure: false alarms per flight-hour against mean detection delay."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.plotting import pyplot, save_png

SWEEP_PNG = "alarm_sweep.png"


def sweep_figure(models: dict, target_fa_per_h: float, path: Path) -> Path:
    """One series per model (every grid policy), its chosen policy circled; the rule's target dashed."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    for i, (name, m) in enumerate(sorted(models.items())):
        pts = [(r["delay_onset_s"], r["fa_per_h"]) for r in m["sweep"]
               if r["delay_onset_s"] is not None and r["fa_per_h"] is not None]
        if not pts:
            continue
        color = f"C{i % 10}"
        ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=14, color=color, alpha=0.6, label=name)
        c = m["policy"]
        pick = [r for r in m["sweep"] if all(r[k] == c[k] for k in c)]
        if pick and pick[0]["delay_onset_s"] is not None:
            ax.scatter([pick[0]["delay_onset_s"]], [pick[0]["fa_per_h"]], s=120, facecolors="none", edgecolors=color,
                       linewidths=2)
    ax.axhline(target_fa_per_h, color="k", ls="--", lw=1, label=f"target {target_fa_per_h:g} / h")
    ax.set_yscale("symlog", linthresh=1.0)  # 0 alarms stays on the plot; the grid spans 0 to hundreds per hour
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("mean detection delay from fault onset (s), validation flights")
    ax.set_ylabel("false alarms per healthy flight-hour, validation flights")
    ax.set_title("Alarm policy grid on validation (circled: chosen by the rule)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save_png(fig, path)
