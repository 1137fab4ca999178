"""The realism table (markdown + JSON) and one overlay figure per channel group, into <run>/realism/."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfdi.core.atomic import write_text
from quadfdi.core.jsonio import write_json
from quadfdi.core.plotting import pyplot, save_png
from quadfdi.core.tables import md_table
from quadfdi.core.channels import CHANNEL_UNITS
from quadfdi.realism.compare import COMPARED, MIN_STEADY_S

GROUPS = {"position": ("x", "y", "z"), "velocity": ("vx", "vy", "vz"), "attitude": ("roll", "pitch", "yaw"),
          "rates": ("p", "q", "r"), "battery": ("V_b", "I_b"), "motors": ("thr1", "thr2", "thr3", "thr4")}


def _median(vals) -> float:
    v = [x for x in vals if x is not None and np.isfinite(x)]
    return float(np.median(v)) if v else float("nan")


def _ratio(a: float, b: float) -> float:
    return a / b if np.isfinite(a) and np.isfinite(b) and b > 0 else float("nan")


def table(res: dict) -> list[dict]:
    """One row per channel: real (median over logs with a steady segment) vs simulated."""
    rows = []
    for c in COMPARED:
        rc = [r["channels"][c] for r in res["real"] if c in r.get("channels", {})]
        s = res["sim"]["channels"][c]
        real_noise, real_hf = _median(x["noise"] for x in rc), _median(x["hf_rms"] for x in rc)
        rows.append({"channel": c, "unit": CHANNEL_UNITS[c], "logs": len(rc),
                     "real_rate_hz": _median(x["rate_hz"] for x in rc), "sim_rate_hz": s["rate_hz"],
                     "real_dt_jitter_ms": _median(x["dt_jitter_ms"] for x in rc),
                     "real_noise": real_noise, "sim_noise": s["noise"], "noise_ratio": _ratio(s["noise"], real_noise),
                     "real_hf_rms": real_hf, "sim_hf_rms": s["hf_rms"], "hf_ratio": _ratio(s["hf_rms"], real_hf)})
    return rows


def _fmt(x, digits=3) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


def markdown(res: dict, rows: list[dict], command: str) -> str:
    sim = res["sim"]
    lines = ["# Realism: simulator vs real flights", "", f"Command: `{command}`", "",
             f"Steady segments: real flights >= {MIN_STEADY_S:g} s (hover or constant velocity, found "
             f"automatically); simulated healthy trajectories >= {sim['min_steady_s']:.1f} s "
             f"({sim['trajectories']} trajectories: a simulated flight is shorter than {MIN_STEADY_S:g} s). "
             "Simulated channels are logged at the real median rate (zero-order hold, capped at 25 Hz) and "
             "resampled like real logs. noise = std of the first-difference high-pass / sqrt(2) at the logged "
             "rate; hf_rms = RMS of the 25 Hz grid signal in 1-10 Hz (Welch).", "", "## Segments", ""]
    seg_rows = []
    for r in res["real"]:
        if r.get("refused"):
            seg_rows.append([r["log"], "refused: " + r["refused"], ""])
        elif not r["segments"]:
            seg_rows.append([r["log"], "no qualifying segment", ""])
        for s in r["segments"]:
            seg_rows.append([r["log"], f"{s['start_s']:.1f}-{s['end_s']:.1f} s ({s['end_s'] - s['start_s']:.1f} s)", s["kind"]])
    lines += md_table(["log", "steady segment", "kind"], seg_rows)
    lines += ["## Channels (ratio = sim / real)", ""]
    lines += md_table(["channel", "unit", "logs", "real rate Hz", "sim rate Hz", "real dt jitter ms", "real noise",
                       "sim noise", "noise ratio", "real hf_rms", "sim hf_rms", "hf ratio"],
                      [[r["channel"], r["unit"], r["logs"], _fmt(r["real_rate_hz"]), _fmt(r["sim_rate_hz"]),
                        _fmt(r["real_dt_jitter_ms"]), _fmt(r["real_noise"]), _fmt(r["sim_noise"]),
                        _fmt(r["noise_ratio"]), _fmt(r["real_hf_rms"]), _fmt(r["sim_hf_rms"]), _fmt(r["hf_ratio"])]
                       for r in rows])
    lines += ["## Hover", ""]
    hov = [[r["log"], _fmt(r["hover"].get("thr")), _fmt(r["hover"].get("current_a")),
            f"{r['hover']['mass_kg']:g} kg (--mass): {_fmt(r['hover'].get('current_per_kg'))} A/kg"
            if r["hover"].get("mass_kg") else "unknown (no log records it; --mass LOG=KG)"]
           for r in res["real"] if r.get("segments")]
    hs = sim["hover"]
    hov.append(["simulator", _fmt(hs["thr"]), _fmt(hs["current_a"]),
                f"{hs['mass_kg']:g} kg: {_fmt(hs['current_per_kg'])} A/kg"])
    lines += md_table(["flight", "hover motor command", "hover current A", "mass, current per kg"], hov)
    return "\n".join(lines)


def figures(res: dict, out: Path) -> list[Path]:
    plt = pyplot()
    paths = []
    for group, chans in GROUPS.items():
        fig, axes = plt.subplots(1, len(chans), figsize=(4 * len(chans), 3.2), squeeze=False)
        for ax, c in zip(axes[0], chans):
            for r in res["real"]:
                spec = r.get("channels", {}).get(c, {}).get("psd")
                if spec is not None:
                    ax.semilogy(spec[0][1:], spec[1][1:], lw=1, label=r["log"][:28])
            spec = res["sim"]["channels"][c]["psd"]
            if spec is not None:
                ax.semilogy(spec[0][1:], spec[1][1:], "k", lw=2, label="simulator")
            ax.set_title(f"{c} [{CHANNEL_UNITS[c]}]")
            ax.set_xlabel("Hz")
        axes[0][0].set_ylabel("PSD (unit^2/Hz), steady segments")
        axes[0][-1].legend(fontsize=6)
        fig.tight_layout()
        paths.append(save_png(fig, out / f"realism_{group}.png"))
    return paths


def _without_psd(side: dict) -> dict:
    """A real or simulated result with its spectra left out (they go to the figures, not the JSON)."""
    chans = {c: {k: v for k, v in d.items() if k != "psd"} for c, d in side.get("channels", {}).items()}
    return {**{k: v for k, v in side.items() if k != "channels"}, "channels": chans}


def write(res: dict, out: Path, command: str) -> list[Path]:
    rows = table(res)
    write_json(out / "realism.json", {"real": [_without_psd(r) for r in res["real"]], "sim": _without_psd(res["sim"]),
                                      "rates": res["rates"], "table": rows, "command": command})
    write_text(out / "realism.md", markdown(res, rows, command) + "\n")
    return [out / "realism.json", out / "realism.md", *figures(res, out)]


HEADING = "## Realism: simulated telemetry against real flights"


def report_section(root: Path) -> list[str]:
    """report.md's section: realism/realism.md under one heading (its own title dropped)."""
    from quadfdi.core.reportmd import demote, not_run

    md = Path(root) / "realism" / "realism.md"
    if not md.is_file():
        return not_run(HEADING, "no realism/realism.md ([run] realism_logs, or quadfdi realism --run RUN --logs ...)")
    body = md.read_text().splitlines()
    text = "\n".join(body[1:] if body and body[0].startswith("# ") else body)
    return [HEADING, ""] + demote(text.replace("](realism_", "](realism/realism_"), 1)


def headline(root: Path) -> list[str]:
    return []
