"""``quadfdi sweep``: the pipeline (or chosen stages) over a grid of config values, one job per point.

    quadfdi sweep --config configs/paper.toml --grid train.latent=16,40 --grid export.steps=4,8 --out runs/sweep

Every point of the grid's cartesian product is a run folder ``<out>/points/<name>/`` made by the
chosen stages, and one job of ``core.executor`` (keyed by the point's whole config, the stages and
the code of the packages it runs; its metrics cached as ``<out>/cache/sweep/<key>.json``). Before
the points, the datasets: the distinct [sim] sections' shards run as jobs of their own into the
shared ``<out>/cache/sim/``, so points that differ only after sim share one simulation. The table
(``sweep.md``, ``sweep.json``) and the figure (``figures/sweep.png``) hold the chosen metrics, one
row per point; a point that failed 3 times is a row with its error.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
from pathlib import Path

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.config import Config, load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import ExecSettings, Job, JobResult, add_executor_args, run_jobs, session
from quadfdi.core.jobcache import cache_path, job_key
from quadfdi.core.jsonio import read_json
from quadfdi.core.rundir import RunDir, create_run

# The packages whose source a stage runs (hashed into a point's key; core always is).
PACKAGES = {"sim": ("sim",), "plots": ("sim",), "train": ("sim", "train"), "export": ("sim", "train", "export"),
            "parity": ("sim", "train", "export", "parity"), "solvers": ("sim", "train", "solverstudy"),
            "bench": ("sim", "train", "export", "bench"), "report": ("quadfdi",)}
DEFAULT_METRICS = ("train.cnode.macro_f1", "train.gru.macro_f1",
                   "export.verification.cnode_int8_vs_fp32.macro_f1_int8_points",
                   "export.models.cnode.macs_per_window")
KIND = "sweep"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="run the pipeline over a grid of config values; one table of metrics",
                       description=__doc__.splitlines()[0])
    add_config_args(p)
    p.add_argument("--grid", action="append", default=[], metavar="SECTION.KEY=V1,V2",
                   help="values of one config key; repeat for a cartesian product")
    p.add_argument("--stages", default="sim,train,export", help="stages run at each point, in pipeline order "
                   "(those of quadfdi run; default: %(default)s)")
    p.add_argument("--metrics", default=",".join(DEFAULT_METRICS),
                   help="dotted paths into each point's results (train.<metrics.json>, export.<manifest.json>, "
                        "parity.<parity.json>, bench.<bench.json>; history.<net>.val_macro_f1 and .best_epoch: the "
                        "validation score of the epoch kept); the first is drawn (default: %(default)s)")
    p.add_argument("--out", default=None, help="sweep folder (e.g. runs/sweep)")
    p.add_argument("--dataset-from", default=None, metavar="RUN",
                   help="reuse this run folder's dataset at every point instead of simulating (--stages without sim; "
                        "every point's [sim] must equal the run's but sim.window and sim.stride)")
    add_executor_args(p)
    p.set_defaults(func=run_sweep_cmd)
    acts = p.add_subparsers(dest="action", metavar="{bench}")
    from quadfdi.sweep_bench import add_bench_parser

    add_bench_parser(acts)


def split_values(text: str) -> list[str]:
    """``1,2,[0.1, 0.3]`` -> ['1', '2', '[0.1, 0.3]']: commas inside brackets belong to a value."""
    out, depth, cur = [], 0, ""
    for ch in text:
        depth += (ch == "[") - (ch == "]")
        if ch == "," and depth == 0:
            out.append(cur.strip())
            cur = ""
        else:
            cur += ch
    out.append(cur.strip())
    if any(v == "" for v in out):
        raise QuadfdiError(f"--grid values must not be empty: {text!r}")
    return out


def parse_grid(texts: list[str]) -> list[tuple[str, list[str]]]:
    if not texts:
        raise QuadfdiError("quadfdi sweep needs at least one --grid section.key=v1,v2")
    grid = []
    for t in texts:
        key, sep, values = t.partition("=")
        if not sep or "." not in key:
            raise QuadfdiError(f"--grid expects section.key=v1,v2,..., found {t!r}")
        if key.strip() in [k for k, _ in grid]:
            raise QuadfdiError(f"--grid names {key.strip()} twice")
        grid.append((key.strip(), split_values(values)))
    return grid


def grid_points(config: str, overrides: list[str], grid: list[tuple[str, list[str]]]) -> list[tuple[dict, Config]]:
    """(values, config) of every point, in the grid's order; every value checked as ``--set`` is."""
    keys = [k for k, _ in grid]
    points = []
    for combo in itertools.product(*[v for _, v in grid]):
        values = dict(zip(keys, combo))
        cfg = load_config(config, list(overrides) + [f"{k}={v}" for k, v in values.items()])
        points.append((values, cfg))
    return points


def parse_stages(text: str) -> tuple[str, ...]:
    order = stage_order()
    stages = tuple(s.strip() for s in text.split(",") if s.strip())
    bad = [s for s in stages if s not in order]
    if bad or not stages:
        raise QuadfdiError(f"--stages: unknown stage {bad[0] if bad else text!r}; valid: {', '.join(order)}")
    return tuple(s for s in order if s in stages)


def point_name(values: dict) -> str:
    return "_".join(f"{k.split('.')[-1]}-{v}" for k, v in values.items()).replace("/", "-").replace(" ", "")


def stage_order() -> tuple[str, ...]:
    from quadfdi.pipeline import STAGES

    return tuple(name for name, _ in STAGES)


def _run_stages(stages: tuple[str, ...], run: RunDir, cfg: Config, cache_root: Path, dataset: str | None = None) -> None:
    """The pipeline's own stage functions (``quadfdi.pipeline.STAGES``), except sim, which joins the
    shards the sweep's first step cached in ``cache_root`` (or, with ``dataset``, links that dataset:
    quadfdi.sweep_reuse). Their printout goes to the point's log.txt: on workers it would interleave in
    the sweep's terminal."""
    from quadfdi.pipeline import STAGES
    from quadfdi.sim.publish import generate_sharded

    funcs = dict(STAGES)
    with open(run.root / "log.txt", "w") as fh, contextlib.redirect_stdout(fh):
        if dataset is not None:
            from quadfdi.sweep_reuse import publish_linked

            publish_linked(run, cfg, Path(dataset))
        for stage in stages:
            if stage == "sim":
                generate_sharded(run, cfg, progress=False, cache_root=cache_root)
            else:
                funcs[stage](run, cfg)


def flatten(d, prefix: str = "") -> dict:
    """Numeric and boolean leaves of nested dicts as {dotted.path: value} (lists are skipped)."""
    out = {}
    for k, v in d.items():
        path = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, path + "."))
        elif isinstance(v, (int, float, bool)) or v is None:
            out[path] = v
    return out


def point_metrics(run: RunDir) -> dict:
    files = {"train": run.metrics, "export": run.export / "manifest.json", "parity": run.root / "parity" / "parity.json",
             "solvers": run.root / "solvers" / "solvers.json", "bench": run.root / "bench.json"}
    out = {}
    for name, path in files.items():
        if path.is_file():
            out.update(flatten(read_json(path, name), name + "."))
    hist = run.root / "history.json"  # the validation score of the epoch kept (train.loop), per network
    for kind, h in (read_json(hist, "training history") if hist.is_file() else {}).items():
        if isinstance(h, dict) and h.get("best_epoch", -1) >= 0:
            out[f"history.{kind}.val_macro_f1"] = h["val_macro_f1"][h["best_epoch"]]
            out[f"history.{kind}.best_epoch"] = h["best_epoch"]
    return out


def run_point(point_dir: str, cfg: Config, stages: tuple[str, ...], cache_root: str, dataset: str | None = None) -> dict:
    """One grid point (a job): run ``stages`` into ``point_dir``; return every numeric result."""
    run = create_run(point_dir, cfg)
    _run_stages(stages, run, cfg, Path(cache_root), dataset)
    return point_metrics(run)


def point_jobs(out: Path, points: list[tuple[dict, Config]], stages: tuple[str, ...],
               datasets: list[Path] | None = None) -> list[Job]:
    """One job per point; ``datasets``: each point's dataset to reuse (quadfdi.sweep_reuse), or None."""
    packages = tuple(sorted({p for s in stages for p in PACKAGES[s]} | {"quadfdi"}))
    jobs = []
    for i, (values, cfg) in enumerate(points):
        dataset = None if datasets is None else datasets[i]
        inputs = {"dataset": dataset} if dataset is not None else None
        src = str(dataset) if dataset is not None else None
        key = job_key(KIND, cfg.to_dict(), {"stages": list(stages)}, inputs=inputs, packages=packages)
        jobs.append(Job(KIND, key, run_point, (str(out / "points" / point_name(values)), cfg, stages, str(out), src),
                        cache_path(out, KIND, key, "json"), label=point_name(values), torch=stages != ("sim",)))
    return jobs


def run_sweep(out: Path, points: list[tuple[dict, Config]], stages: tuple[str, ...], settings: ExecSettings,
              progress: bool = True, datasets: list[Path] | None = None) -> list[JobResult]:
    """The datasets' shards (each distinct [sim] section once), then one job per point."""
    from quadfdi.sim.shards import shard_jobs

    if {"parity", "bench"} & set(stages) and not settings.in_process(2):
        raise QuadfdiError("the parity and bench stages build C++ in one shared folder and time the machine: "
                           "sweep them with --workers 1")
    with session(settings):
        if "sim" in stages:
            shards = {j.out: j for _, cfg in points for j in shard_jobs(RunDir(out), cfg)}
            bad = [r for r in run_jobs(list(shards.values()), settings, desc="sweep sim shards", progress=progress)
                   if not r.ok]
            if bad:
                raise QuadfdiError(f"{len(bad)} simulation shards failed ({bad[0].job.label}: {bad[0].error}); "
                                   "run the same command again to resume")
        return run_jobs(point_jobs(out, points, stages, datasets), settings, desc="sweep points", progress=progress)


def run_sweep_cmd(args: argparse.Namespace) -> int:
    from quadfdi.sweep_report import write_sweep_report

    if args.out is None:
        raise QuadfdiError("quadfdi sweep needs --out <sweep folder>")
    settings = ExecSettings.from_args(args)
    grid = parse_grid(args.grid)
    stages = parse_stages(args.stages)
    if ("sim" in stages) == (args.dataset_from is not None):
        raise QuadfdiError("--stages must include sim, or leave it out and name a run whose dataset every point "
                           "reuses with --dataset-from RUN")
    metrics = [m.strip() for m in args.metrics.split(",") if m.strip()]
    points = grid_points(args.config, args.overrides, grid)
    out = Path(args.out)
    datasets = None
    if args.dataset_from is not None:
        from quadfdi.sweep_reuse import source_datasets

        datasets = source_datasets(args.dataset_from, points, out)
    create_run(out, load_config(args.config, args.overrides))  # the sweep's base config, beside its table
    results = run_sweep(out, points, stages, settings, datasets=datasets)
    paths = write_sweep_report(out, grid, points, results, metrics, stages)
    failed = sum(not r.ok for r in results)
    print(f"sweep: {len(results) - failed} of {len(results)} points done" + (f", {failed} failed" if failed else ""))
    for p in paths:
        print(f"wrote {p}")
    return 0
