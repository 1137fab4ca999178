"""The sweep's table (``sweep.md``, ``sweep.json``) and figure (``figures/sweep.png``)."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.atomic import write_text
from quadfdi.core.config import Config
from quadfdi.core.executor import JobResult
from quadfdi.core.jobcache import read_result
from quadfdi.core.jsonio import write_json
from quadfdi.core.plotting import pyplot, save_png
from quadfdi.core.tables import md_table

SEED_KEY = "train.seed"  # a grid key whose values are replicates of one configuration, not configurations


def sweep_rows(grid: list[tuple[str, list[str]]], points: list[tuple[dict, Config]], results: list[JobResult],
               metrics: list[str]) -> list[dict]:
    """One row per point: its grid values, status, chosen metrics (None where absent), error."""
    rows = []
    for (values, _), r in zip(points, results):
        got = read_result(r.job.out) if r.ok else {}
        rows.append({"point": r.job.label, "values": values, "status": "failed" if not r.ok else "done",
                     "metrics": {m: got.get(m) for m in metrics}, "error": r.error})
    return rows


def _fmt(v) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def sweep_markdown(grid, rows: list[dict], metrics: list[str], stages: tuple[str, ...]) -> str:
    keys = [k for k, _ in grid]
    head = [*keys, *metrics, "status"]
    body = [[*(r["values"][k] for k in keys), *(_fmt(r["metrics"][m]) for m in metrics),
             r["status"] if r["error"] is None else f"failed: {r['error']}"] for r in rows]
    over = " x ".join(f"{k} in {{{', '.join(v)}}}" for k, v in grid)
    lines = [f"Sweep over {over}; stages "
             f"{', '.join(stages)}; one run folder per point in points/.", "", *md_table(head, body),
             *seed_means_markdown(grid, seed_means(grid, rows, metrics), metrics)]
    return "\n".join(lines)


def seed_means(grid, rows: list[dict], metrics: list[str]) -> list[dict]:
    """With ``train.seed`` a grid key of two or more values: one entry per configuration of the other keys (in grid
    order), the seeds whose point is done, and each numeric metric's mean, min and max over them (None where no seed
    has a number); empty otherwise. A seed-replicated search chooses on these means, not on one seed's score."""
    seeds = dict(grid).get(SEED_KEY, [])
    if len(seeds) < 2:
        return []
    others = [k for k, _ in grid if k != SEED_KEY]
    configs: dict[tuple, list[dict]] = {}
    for r in rows:
        configs.setdefault(tuple(r["values"][k] for k in others), []).append(r)
    out = []
    for combo, group in configs.items():
        done = [r for r in group if r["status"] == "done"]
        stats = {}
        for m in metrics:
            xs = [float(r["metrics"][m]) for r in done
                  if isinstance(r["metrics"][m], (int, float)) and not isinstance(r["metrics"][m], bool)]
            stats[m] = {"mean": sum(xs) / len(xs), "min": min(xs), "max": max(xs), "n": len(xs)} if xs else None
        out.append({"values": dict(zip(others, combo)), "seeds_done": sorted(r["values"][SEED_KEY] for r in done),
                    "seeds": len(group), "metrics": stats})
    return out


def seed_means_markdown(grid, means: list[dict], metrics: list[str]) -> list[str]:
    """The table of ``seed_means``: each metric as mean [min, max] over the seeds done."""
    if not means:
        return []
    others = [k for k, _ in grid if k != SEED_KEY]
    seeds = ", ".join(dict(grid)[SEED_KEY])
    head = [*others, "seeds done", *(f"{m} mean [min, max]" for m in metrics)]
    body = [[*(e["values"][k] for k in others), f"{len(e['seeds_done'])} of {e['seeds']}",
             *("n/a" if e["metrics"][m] is None else
               f"{_fmt(e['metrics'][m]['mean'])} [{_fmt(e['metrics'][m]['min'])}, {_fmt(e['metrics'][m]['max'])}]"
               for m in metrics)] for e in means]
    return [f"Per configuration over {SEED_KEY} in {{{seeds}}}, in grid order:", "", *md_table(head, body)]


def sweep_figure(grid, rows: list[dict], metric: str, path: Path) -> Path:
    """The first metric against the first grid key; one line per value of the other keys."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    xkey, others = grid[0][0], [k for k, _ in grid[1:]]
    xs = grid[0][1]
    lines: dict[tuple, dict] = {}
    for r in rows:
        lines.setdefault(tuple(r["values"][k] for k in others), {})[r["values"][xkey]] = r["metrics"][metric]
    for combo, ys in lines.items():
        label = ", ".join(f"{k}={v}" for k, v in zip(others, combo)) or metric
        pts = [(i, ys[x]) for i, x in enumerate(xs) if ys.get(x) is not None]
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", label=label)
    ax.set_xticks(range(len(xs)), xs)
    ax.set_xlabel(xkey)
    ax.set_ylabel(metric)
    ax.grid(alpha=0.3)
    if others:
        ax.legend(fontsize=8)
    fig.tight_layout()
    return save_png(fig, path)


def write_sweep_report(out: Path, grid, points, results: list[JobResult], metrics: list[str],
                       stages: tuple[str, ...]) -> list[Path]:
    rows = sweep_rows(grid, points, results, metrics)
    md, js, png = out / "sweep.md", out / "sweep.json", out / "figures" / "sweep.png"
    write_text(md, sweep_markdown(grid, rows, metrics, stages))
    write_json(js, {"grid": {k: v for k, v in grid}, "stages": list(stages), "metrics": metrics, "rows": rows,
                    "over_seeds": seed_means(grid, rows, metrics)})
    sweep_figure(grid, rows, metrics[0], png)
    return [md, js, png]
