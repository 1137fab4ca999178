"""bench's figures: figures/bench_latency.png and figures/bench_throughput.png, from bench.json."""

from __future__ import annotations

from pathlib import Path

from quadfdi.bench.report_fmt import RUNTIME_ORDER, setting
from quadfdi.core.plotting import pyplot, save_png


def _save(fig, path: Path) -> None:
    save_png(fig, path, bbox_inches="tight")


def draw_bench_figures(bench: dict, fig_dir: Path) -> list[Path]:
    """figures/bench_latency.png (batch-1 p50 with p90-p99 whiskers and each floor) and
    figures/bench_throughput.png (batch-96 windows per second)."""
    plt = pyplot()
    written = []
    recs1 = [r for r in bench["latency"] if r["batch"] == 1]
    recsn = [r for r in bench["latency"] if r["batch"] != 1]
    if not recs1:
        return written
    colors = {"cpp": "tab:green", "ort": "tab:blue", "torch": "tab:orange"}
    for name, recs, value, xlabel in (
            ("bench_latency.png", recs1, "p50_us", "batch-1 latency per window (us, log scale): p50 bar, p90-p99 line"),
            ("bench_throughput.png", recsn, "throughput_wps", "batch-96 throughput (windows per second, log scale)")):
        if not recs:
            continue
        fig, axes = plt.subplots(1, 2, figsize=(13, 0.32 * max(len(recs) // 2, 6) + 1.5), sharex=True)
        for ax, model in zip(axes, ("cnode", "gru")):
            rs = sorted((r for r in recs if r["model"] == model),
                        key=lambda r: (RUNTIME_ORDER.get(r["runtime"], 9), r["precision"], r["solver"], r["threads"],
                                       bool(r.get("spinning"))))
            ys = list(range(len(rs)))
            ax.barh(ys, [r[value] for r in rs], color=[colors.get(r["runtime"], "grey") for r in rs])
            if value == "p50_us":
                for y, r in zip(ys, rs):
                    ax.plot([r["p90_us"], r["p99_us"]], [y, y], color="black", lw=1)
                for f in bench.get("floors", []):
                    if f["model"] == model:
                        ax.axvline(f["floor_us"], ls="--" if f["precision"] == "fp32" else ":", color="red",
                                   label=f"floor {f['precision']} {f['floor_us']:.2f} us")
                ax.legend(loc="lower right", fontsize=8)
            ax.set_yticks(ys)
            ax.set_yticklabels([f"{r['runtime']} {r['precision']} {r['solver']} {setting(r)}" for r in rs], fontsize=8)
            ax.invert_yaxis()
            ax.set_xscale("log")
            ax.set_title("CNODE" if model == "cnode" else "GRU")
            ax.set_xlabel(xlabel, fontsize=9)
            ax.grid(axis="x", alpha=0.3)
        fig.tight_layout()
        path = Path(fig_dir) / name
        _save(fig, path)
        written.append(path)
    return written
