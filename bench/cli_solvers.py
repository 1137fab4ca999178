"""Thin CLI of the solver study and of the train-solver by deploy-solver matrix.

Two commands, meant to be wired into ``quadfdi bench`` (``add_solver_args``/``run_solvers`` and
``add_matrix_args``/``run_matrix_cmd``); until then also ``python -m bench.cli_solvers
{solvers,matrix} --run runs/<name> ...``.

- solvers: reads ``<run>/dataset.npz`` and ``<run>/cnode.pt``; writes ``<run>/bench/solvers.json``,
  ``<run>/bench/solvers.md``, ``<run>/figures/solver_error_vs_nfe.png`` and
  ``solver_f1_vs_latency.png``.
- render: redraws the figures and markdown from the JSON files alone (``add_render_args``/``run_render``);
  ``solver_section(run)`` returns the markdown of both for the lead's report.md.
- matrix: reads ``<run>/dataset.npz``, trains its own CNODEs (kept in
  ``<run>/bench/solver_matrix/*.pt``, reused with ``--reuse``); writes
  ``<run>/bench/solver_matrix.json``, ``solver_matrix.md``, ``<run>/figures/solver_matrix_f1.png``
  and ``solver_controls.png``.

All files are written atomically, after the whole computation: an interrupted run leaves the
previous outputs as they were.
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import sys
import time
from pathlib import Path

from core.errors import QuadfdiError


def _csv(kind, what: str):
    def parse(text: str):
        try:
            return [kind(v) for v in text.split(",") if v.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what}: expected comma-separated values, found {text!r}") from None
    return parse


def _overrides(p: argparse.ArgumentParser) -> None:
    if not any(a.dest == "overrides" for a in p._actions):
        p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                       help="override one config value; repeatable")


def add_solver_args(p: argparse.ArgumentParser) -> None:
    """Options of the solver study (``quadfdi bench solvers``)."""
    if not any(a.dest == "run" for a in p._actions):
        p.add_argument("--run", required=True, help="run folder holding dataset.npz and cnode.pt")
    p.add_argument("--checkpoint", default=None, help="CNODE checkpoint (default: <run>/cnode.pt)")
    p.add_argument("--sample", type=int, default=128,
                   help="test windows solved one by one (seeded sample); 0 = the whole split (default: %(default)s)")
    p.add_argument("--sample-seed", type=int, default=0, help="seed of the window sample (default: %(default)s)")
    p.add_argument("--fixed-methods", type=_csv(str, "--fixed-methods"), default=["euler", "midpoint", "rk4"])
    p.add_argument("--steps", type=_csv(int, "--steps"), default=[1, 2, 4, 8, 16, 32, 79],
                   help="fixed-step N values (default: 1,2,4,8,16,32,79)")
    p.add_argument("--adaptive-methods", type=_csv(str, "--adaptive-methods"), default=["dopri5", "bosh3"])
    p.add_argument("--rtols", type=_csv(float, "--rtols"), default=[1e-2, 1e-3, 1e-4, 1e-5, 1e-6],
                   help="adaptive rtol values, atol = rtol/10 (default: 1e-2,...,1e-6)")
    p.add_argument("--jump", choices=("both", "on", "off"), default="both",
                   help="adaptive solvers with the knots as jump_t, without, or both (default: %(default)s)")
    p.add_argument("--controls", type=_csv(str, "--controls"), default=["point", "average"],
                   help="control representations of the fixed steps: point (the model's own) and average "
                        "(step mean; the same ODE only as N grows) (default: point,average)")
    p.add_argument("--ref-rtol", type=float, default=1e-9, help="reference dopri5 rtol, float64 (default: %(default)s)")
    p.add_argument("--f1-two-sided", action="store_true",
                   help="match only fixed settings whose macro F1 is within 0.2 point either side "
                        "(default: at most 0.2 point below)")
    p.add_argument("--threads", type=int, default=1, help="torch intra-op threads (default: %(default)s)")
    _overrides(p)


def add_matrix_args(p: argparse.ArgumentParser) -> None:
    """Options of the train-solver by deploy-solver matrix (``quadfdi bench solver-matrix``)."""
    from bench.solver_matrix import DEFAULT_DEPLOY, DEFAULT_TRAIN

    if not any(a.dest == "run" for a in p._actions):
        p.add_argument("--run", required=True, help="run folder holding dataset.npz")
    p.add_argument("--train", type=_csv(str, "--train"), default=list(DEFAULT_TRAIN),
                   help="training solvers: dopri5 (train config tolerances), rk4:N, rk4:N:avg (default: %(default)s)")
    p.add_argument("--deploy", type=_csv(str, "--deploy"), default=list(DEFAULT_DEPLOY),
                   help="deploy solvers: dopri5:RTOL[:nojump], rk4:N[:avg], ref (default: %(default)s)")
    p.add_argument("--epochs", type=int, default=None, help="training epochs of every model (default: train.epochs)")
    p.add_argument("--max-train-windows", type=int, default=0,
                   help="train on a seeded sample of at most this many windows; 0 = all (default)")
    p.add_argument("--batch", type=int, default=96, help="deploy batch size (default: %(default)s)")
    p.add_argument("--reuse", action="store_true",
                   help="reuse models in <run>/bench/solver_matrix/ trained with the same solver, epochs and windows")
    p.add_argument("--threads", type=int, default=None, help="torch intra-op threads (default: train.threads)")
    _overrides(p)


def _command(default: str) -> str:
    """The command line that made an output, as the user typed it (for the report)."""
    if len(sys.argv) <= 1:
        return default
    prog = "python -m bench.cli_solvers" if sys.argv[0].endswith("cli_solvers.py") else "quadfdi"
    return prog + " " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def _write_json(path: Path, obj: dict) -> None:
    from core.atomic import write_text
    from core.jsonio import write_json

    write_json(path, obj, indent=2)


def _test_windows(run, cfg, model_blob=None):
    from sim.dataset import load_dataset, make_windows
    from train.checkpoint import check_dataset_matches
    from train.models import check_windows

    ds = load_dataset(run.dataset)
    if model_blob is not None:
        check_dataset_matches(model_blob, ds.channel_names, str(run.dataset))
    test = make_windows(ds, "test")
    if len(test) == 0:
        raise QuadfdiError(f"{run.dataset} has no test windows: raise sim.n_traj or sim.duration_s")
    try:
        check_windows(test.x, ds.n_channels, cfg.sim.window)
    except ValueError as exc:
        raise QuadfdiError(f"{run.dataset}: {exc}") from None
    return ds, test


def run_solvers(args: argparse.Namespace) -> int:
    """``quadfdi bench solvers``: the fixed-vs-adaptive study of one trained CNODE."""
    import torch

    from bench.solver_plots import draw_study
    from bench.solver_report import headline, study_markdown
    from bench.solvers import ADAPTIVE_METHODS, CONTROLS, FIXED_METHODS, default_settings, run_study
    from core.atomic import write_text
    from core.rundir import open_run
    from train.checkpoint import load_checkpoint

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    for name, given, valid in (("--fixed-methods", args.fixed_methods, FIXED_METHODS),
                               ("--adaptive-methods", args.adaptive_methods, ADAPTIVE_METHODS)):
        bad = [m for m in given if m not in valid]
        if bad:
            raise QuadfdiError(f"{name}: unknown method {bad[0]!r}; valid: {', '.join(valid)}")
    bad = [c for c in args.controls if c not in CONTROLS] or ([] if args.controls else [""])
    if bad:
        raise QuadfdiError(f"--controls: unknown control {bad[0]!r}; valid: {', '.join(CONTROLS)}")
    if any(n < 1 for n in args.steps) or any(not r > 0 for r in args.rtols) or not args.ref_rtol > 0:
        raise QuadfdiError("--steps must be positive integers, --rtols and --ref-rtol positive numbers")
    if args.threads < 1:
        raise QuadfdiError(f"--threads must be at least 1, found {args.threads}")
    ckpt = Path(args.checkpoint) if args.checkpoint else run.checkpoint("cnode")
    model, blob = load_checkpoint(ckpt, "cnode")
    ds, test = _test_windows(run, cfg, blob)
    torch.set_num_threads(args.threads)
    jump = {"both": (True, False), "on": (True,), "off": (False,)}[args.jump]
    settings = default_settings(args.fixed_methods, args.steps, args.adaptive_methods, args.rtols, jump, args.controls)
    study = run_study(model, test.x, test.y, settings, sample=args.sample, seed=args.sample_seed, ref_rtol=args.ref_rtol,
                      f1_two_sided=args.f1_two_sided)
    solver = blob.get("solver", {})
    study["meta"]["checkpoint"] = str(ckpt)
    study["meta"]["trained_with"] = (f"trained with {solver.get('method')} N={solver.get('steps')}"
                                     if solver.get("method") in FIXED_METHODS else
                                     f"trained with {solver.get('method')} rtol={solver.get('rtol')}")
    command = _command(f"quadfdi bench solvers --run {run.root}")
    study["meta"]["command"] = command
    bench = run.root / "bench"
    _write_json(bench / "solvers.json", study)
    figs = draw_study(study, run.figures)
    write_text(bench / "solvers.md", study_markdown(study, command))
    print(headline(study))
    print(f"wrote {bench / 'solvers.json'}, {bench / 'solvers.md'} and {', '.join(str(f) for f in figs)} "
          f"in {study['meta']['seconds']:.0f} s")
    return 0


def _sha256(path: Path) -> str:
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _slug(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9.]+", "_", label).strip("_")


def run_matrix_cmd(args: argparse.Namespace) -> int:
    """``quadfdi bench solver-matrix``: train with several solvers, deploy each with each."""
    import torch

    from bench.solver_matrix import TrainSpec, load_variant, run_matrix, save_variant
    from bench.solver_plots import draw_matrix
    from bench.solver_report import matrix_markdown, ott_sentence
    from bench.solvers import Setting
    from core.atomic import write_text
    from core.rundir import open_run
    from sim.dataset import load_dataset

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    epochs = cfg.train.epochs if args.epochs is None else args.epochs
    if epochs < 1 or args.batch < 1:
        raise QuadfdiError(f"--epochs and --batch must be at least 1, found {epochs} and {args.batch}")
    try:
        specs = [TrainSpec.parse(t, cfg) for t in args.train]
        deploys = [Setting.parse(t) for t in args.deploy]
    except ValueError as exc:
        raise QuadfdiError(str(exc)) from None
    labels = [s.label for s in specs]
    if len(set(labels)) != len(labels) or len({d.label for d in deploys}) != len(deploys):
        raise QuadfdiError("--train and --deploy must not repeat a setting")
    torch.set_num_threads(args.threads or cfg.train.threads)
    ds = load_dataset(run.dataset)
    store = run.root / "bench" / "solver_matrix"
    # what a reused model must share with this run besides its solver: data, windows, training
    fingerprint = {"dataset_sha256": _sha256(run.dataset), "epochs": epochs, "max_train_windows": args.max_train_windows,
                   **{k: getattr(cfg.train, k) for k in ("seed", "lr", "batch_size", "latent", "hidden", "log_eps")}}
    models = {}
    if args.reuse:
        for spec in specs:
            got = load_variant(store / f"{_slug(spec.label)}.pt")
            if got and got[1].get("label") == spec.label and got[1].get("fingerprint") == fingerprint:
                models[spec.label] = got
                print(f"reuse {spec.label} from {store}")
    reused = set(models)

    def save(spec, model, info):
        info["fingerprint"] = fingerprint
        save_variant(store / f"{_slug(spec.label)}.pt", model, info, cfg, ds.channel_names)

    t0 = time.perf_counter()
    matrix = run_matrix(ds, cfg, specs, deploys, epochs, args.max_train_windows, args.batch, models=models,
                        on_trained=save)
    command = _command(f"quadfdi bench solver-matrix --run {run.root}")
    matrix["meta"]["command"] = command
    matrix["meta"]["reused"] = sorted(reused)
    matrix["meta"]["seconds"] = time.perf_counter() - t0
    bench = run.root / "bench"
    _write_json(bench / "solver_matrix.json", matrix)
    figs = draw_matrix(matrix, run.figures)
    write_text(bench / "solver_matrix.md", matrix_markdown(matrix, command))
    print(ott_sentence(matrix))
    print(f"wrote {bench / 'solver_matrix.json'}, {bench / 'solver_matrix.md'} and "
          f"{', '.join(str(f) for f in figs)} in {matrix['meta']['seconds']:.0f} s")
    return 0


def _read_json(path: Path) -> dict | None:
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise QuadfdiError(f"{path} cannot be read as JSON (truncated or foreign file?): {exc}") from None


def solver_section(run_root: str | Path) -> str:
    """The markdown of whatever solver outputs ``<run>/bench`` holds, for the lead's report.md
    (figure links relative to the run folder)."""
    from bench.solver_report import matrix_markdown, study_markdown

    bench = Path(run_root) / "bench"
    parts = []
    study, matrix = _read_json(bench / "solvers.json"), _read_json(bench / "solver_matrix.json")
    if study:
        parts.append(study_markdown(study, study["meta"].get("command"), figures="figures"))
    if matrix:
        parts.append(matrix_markdown(matrix, matrix["meta"].get("command"), figures="figures"))
    return "\n".join(parts)


def add_render_args(p: argparse.ArgumentParser) -> None:
    if not any(a.dest == "run" for a in p._actions):
        p.add_argument("--run", required=True, help="run folder holding bench/solvers.json or solver_matrix.json")
    p.add_argument("--f1-two-sided", action="store_true", help="recompute the matched table with the two-sided F1 rule")


def run_render(args: argparse.Namespace) -> int:
    """Redraw the solver figures and markdown from the JSON files alone (no solving, no training);
    the matched table is recomputed from the records with the current rule."""
    from bench.solver_plots import draw_matrix, draw_study
    from bench.solver_report import matrix_markdown, study_markdown
    from bench.solvers import CONTROLS, F1_TOL, matched_table
    from core.atomic import write_text

    root = Path(args.run)
    bench = root / "bench"
    study, matrix = _read_json(bench / "solvers.json"), _read_json(bench / "solver_matrix.json")
    if study is None and matrix is None:
        raise QuadfdiError(f"{bench} holds neither solvers.json nor solver_matrix.json: run the solver commands first")
    written = []
    if study is not None:
        tol = study["meta"].get("f1_tol", F1_TOL)
        study["matched"] = matched_table(study["solvers"], tol, args.f1_two_sided)
        study["matched_any_control"] = (matched_table(study["solvers"], tol, args.f1_two_sided, CONTROLS)
                                        if any(r["control"] != "point" for r in study["solvers"]) else None)
        study["meta"]["f1_two_sided"] = bool(args.f1_two_sided)
        _write_json(bench / "solvers.json", study)
        written += draw_study(study, root / "figures")
        write_text(bench / "solvers.md", study_markdown(study, study["meta"].get("command")))
        written += [bench / "solvers.json", bench / "solvers.md"]
    if matrix is not None:
        written += draw_matrix(matrix, root / "figures")
        write_text(bench / "solver_matrix.md", matrix_markdown(matrix, matrix["meta"].get("command")))
        written.append(bench / "solver_matrix.md")
    print("wrote " + ", ".join(str(w) for w in written))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.cli_solvers", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    ps = sub.add_parser("solvers", help="fixed against adaptive solvers on one trained CNODE")
    add_solver_args(ps)
    ps.set_defaults(func=run_solvers)
    pm = sub.add_parser("matrix", help="train-solver by deploy-solver matrix and control representations")
    add_matrix_args(pm)
    pm.set_defaults(func=run_matrix_cmd)
    pr = sub.add_parser("render", help="redraw the solver figures and markdown from the JSON files")
    add_render_args(pr)
    pr.set_defaults(func=run_render)
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except QuadfdiError as exc:
        print(f"{parser.prog} {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
