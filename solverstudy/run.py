"""The solver study as a stage: read a run folder, write ``runs/<name>/solvers/`` and the figures.

    study_run(run, cfg, log, checkpoint=None, command=None) -> dict
        reads dataset.npz and cnode.pt; writes solvers/solvers.json, solvers/solvers.md,
        figures/solver_error_vs_nfe.png and figures/solver_f1_vs_latency.png
    matrix_run(run, cfg, log, reuse=False, command=None) -> dict
        reads dataset.npz, trains its own CNODEs (solvers/matrix_models/*.pt); writes
        solvers/solver_matrix.json, solvers/solver_matrix.md, figures/solver_matrix_f1.png and
        figures/solver_controls.png
    render(run_root, cfg, log) -> list[Path]
        redraws the markdown and figures from the JSON files alone (matched table recomputed
        with cfg.solvers.f1_tol and f1_two_sided)

What is measured comes from ``cfg.solvers`` (the [solvers] config section, docs/solvers.md); the
arguments here only say where and how to execute. Every file is written atomically after the
whole computation: an interrupted run leaves the previous outputs as they were.
"""

from __future__ import annotations

import hashlib
import re
import time
from pathlib import Path
from typing import Callable

from quadfdi.core.atomic import write_text
from quadfdi.core.config import Config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import write_json
from quadfdi.core.rundir import RunDir
from quadfdi.formats.solver_files import SolverFiles
from quadfdi.core.stage import stage
from quadfdi.models.threads import torch_threads
from quadfdi.solverstudy.matching import matched_tables
from quadfdi.formats.solver_files import read_outputs
from quadfdi.solverstudy.report import study_headline, matrix_markdown, ott_sentence, study_markdown

Log = Callable[[str], None]


def _test_windows(run: RunDir, cfg: Config, model_blob: dict | None = None):
    from quadfdi.formats.dataset import load_dataset, make_windows
    from quadfdi.models.checkpoint import check_dataset_matches
    from quadfdi.models.networks import check_windows

    if not run.dataset.is_file():
        raise QuadfdiError(f"{run.dataset} is missing: run `quadfdi sim --out {run.root}` first")
    ds = load_dataset(run.dataset)
    if model_blob is not None:  # the model's channel profile (paper: the dataset itself), as export's test windows
        from quadfdi.models.inputs import profile_of
        from quadfdi.train.vehicle_ref import profiled

        ds = profiled(ds, profile_of(model_blob))
        check_dataset_matches(model_blob, ds.channel_names, str(run.dataset))
    test = make_windows(ds, "test")
    if len(test) == 0:
        raise QuadfdiError(f"{run.dataset} has no test windows: raise sim.n_traj or sim.duration_s")
    try:
        check_windows(test.x, ds.n_channels, cfg.sim.window)
    except ValueError as exc:
        raise QuadfdiError(f"{run.dataset}: {exc}") from None
    return ds, test


def _trained_with(blob: dict) -> str:
    from quadfdi.models.solvers import FIXED_METHODS

    solver = blob.get("solver", {})
    if solver.get("method") in FIXED_METHODS:
        return f"trained with {solver.get('method')} N={solver.get('steps')}"
    return f"trained with {solver.get('method')} rtol={solver.get('rtol')}"


def study_run(run: RunDir, cfg: Config, log: Log = print, checkpoint: str | Path | None = None,
              command: str | None = None, settings=None) -> dict:
    """The fixed-vs-adaptive study of the run's CNODE (or ``checkpoint``); returns solvers.json's dict.
    With ``settings`` (a ``core.executor.ExecSettings``), one job per setting on that executor
    (``solverstudy.study_jobs``, cached in ``<run>/cache/solvers-task/``); without, in this process."""
    from quadfdi.solverstudy.plots import draw_study
    from quadfdi.solverstudy.study import run_study
    from quadfdi.models.checkpoint import load_checkpoint

    sections = cfg.to_dict()
    with stage(run.root, "solvers", {"sim": sections["sim"], "solvers": sections["solvers"]},
               targets=("solvers/solvers.json",)) as st:
        st.consume("dataset.npz", ("sim",))
        if checkpoint is None:
            st.consume("cnode.pt", ("sim",))
        ckpt = Path(checkpoint) if checkpoint else run.checkpoint("cnode")
        model, blob = load_checkpoint(ckpt, "cnode")
        _, test = _test_windows(run, cfg, blob)
        run_tasks, where = None, "this process"
        if settings is not None:
            from quadfdi.solverstudy.study_jobs import executor_tasks

            run_tasks, where = executor_tasks(run, cfg, ckpt, settings, log), executor_where(settings)
        with torch_threads(cfg.solvers.threads):
            study = run_study(model, test.x, test.y, cfg.solvers, log=log, run_tasks=run_tasks, where=where)
        study["meta"].update(checkpoint=str(ckpt), trained_with=_trained_with(blob),
                             command=command or f"quadfdi solvers study --run {run.root}")
        staged = SolverFiles(st.out)
        write_json(staged.study_json, study, indent=2)
        figs = [run.root / staged.rel(f) for f in draw_study(study, staged.figures)]
        write_text(staged.study_md, study_markdown(study, study["meta"]["command"]))
    files = SolverFiles(run.root)
    log(study_headline(study))
    log(f"wrote {files.study_json}, {files.study_md} and {', '.join(str(f) for f in figs)} "
        f"in {study['meta']['seconds']:.0f} s")
    return study


def executor_where(settings) -> str:
    """Where the executor's jobs time their solves, for the study's latency note."""
    if settings.scheduler != "local":
        return f"the workers of the cluster at {settings.scheduler}, one setting per job"
    if settings.n_local == 1:
        return "this process, one setting per job"
    return f"{settings.n_local} single-threaded worker processes of a local cluster, one setting per job"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _slug(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9.]+", "_", label).strip("_")


def _reused(files: SolverFiles, specs: list, fingerprint: dict, log: Log) -> dict:
    """Matrix models saved earlier with the same label and fingerprint: {label: (model, info)}."""
    from quadfdi.models.checkpoint import load_checkpoint

    models = {}
    for spec in specs:
        path = files.matrix_models / f"{_slug(spec.label)}.pt"
        try:
            model, blob = load_checkpoint(path, "cnode")
        except QuadfdiError:
            continue
        info = blob.get("matrix_info")
        if (isinstance(info, dict) and info.get("label") == spec.label and info.get("fingerprint") == fingerprint
                and info.get("control") == model.control):
            models[spec.label] = (model, info)
            log(f"reuse {spec.label} from {files.matrix_models}")
    return models


def matrix_run(run: RunDir, cfg: Config, log: Log = print, reuse: bool = False, command: str | None = None,
               settings=None) -> dict:
    """Train the CNODEs of ``solvers.matrix_train``, deploy each with each of ``solvers.matrix_deploy``;
    with ``reuse``, models kept from an earlier matrix of the same data and settings are not retrained.
    With ``settings`` (a ``core.executor.ExecSettings``), the matrix runs as jobs on that executor
    (``solverstudy.jobs``: one per model, reference and cell), cached in ``<run>/cache/matrix-*/``."""
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.solverstudy.matrix import matrix_plan

    specs, deploys = matrix_plan(cfg)
    if not run.dataset.is_file():
        raise QuadfdiError(f"{run.dataset} is missing: run `quadfdi sim --out {run.root}` first")
    sections = cfg.to_dict()
    with stage(run.root, "solver-matrix", {k: sections[k] for k in ("sim", "train", "solvers")},
               targets=("solvers/solver_matrix.json",)) as st:
        ds = load_dataset(st.consume("dataset.npz", ("sim",)))
        if settings is not None:
            return _matrix_on_executor(run, cfg, SolverFiles(st.out), specs, deploys, settings, log, command)
        if reuse:
            st.carry_previous()  # the models not retrained stay published
        return _matrix_into(run, cfg, ds, SolverFiles(st.out), specs, deploys, log, reuse, command)


def _matrix_into(run: RunDir, cfg: Config, ds, staged: SolverFiles, specs, deploys, log: Log, reuse: bool,
                 command: str | None) -> dict:
    from quadfdi.solverstudy.matrix import run_matrix
    from quadfdi.solverstudy.plots import draw_matrix
    from quadfdi.models.checkpoint import save_checkpoint

    files = SolverFiles(run.root)
    fingerprint = _fingerprint(run, cfg)
    models = _reused(files, specs, fingerprint, log) if reuse else {}
    reused = sorted(models)

    def save(spec, model, info) -> None:
        info["fingerprint"] = fingerprint
        save_checkpoint(staged.matrix_models / f"{_slug(spec.label)}.pt", model, cfg.to_dict(), ds.channel_names,
                        extra={"matrix_info": info})

    t0 = time.perf_counter()
    with torch_threads(cfg.solvers.matrix_threads or cfg.train.threads):
        matrix = run_matrix(ds, cfg, specs, deploys, models=models, on_trained=save, log=log)
    matrix["meta"].update(command=command or f"quadfdi solvers matrix --run {run.root}", reused=reused,
                          seconds=time.perf_counter() - t0)
    write_json(staged.matrix_json, matrix, indent=2)
    figs = [run.root / staged.rel(f) for f in draw_matrix(matrix, staged.figures)]
    write_text(staged.matrix_md, matrix_markdown(matrix, matrix["meta"]["command"]))
    log(ott_sentence(matrix))
    log(f"wrote {files.matrix_json}, {files.matrix_md} and {', '.join(str(f) for f in figs)} "
        f"in {matrix['meta']['seconds']:.0f} s")
    return matrix


def _fingerprint(run: RunDir, cfg: Config) -> dict:
    """What a reused model must share with this run besides its solver: data, windows, training."""
    from quadfdi.solverstudy.matrix import matrix_epochs

    return {"dataset_sha256": _sha256(run.dataset), "epochs": matrix_epochs(cfg),
            "max_train_windows": cfg.solvers.matrix_max_train_windows,
            **{k: getattr(cfg.train, k) for k in ("seed", "lr", "batch_size", "latent", "hidden", "log_eps")}}


def _matrix_on_executor(run: RunDir, cfg: Config, files: SolverFiles, specs, deploys, settings, log: Log,
                        command: str | None) -> dict:
    """The matrix as jobs on ``settings``' executor; ``files``: the stage's staging folder."""
    from quadfdi.solverstudy.jobs import matrix_jobs_run
    from quadfdi.solverstudy.plots import draw_matrix
    from quadfdi.models.checkpoint import load_checkpoint, save_checkpoint

    matrix, models = matrix_jobs_run(run, cfg, specs, deploys, settings, log)
    fingerprint = _fingerprint(run, cfg)
    for info in matrix["train"]:
        info["fingerprint"] = fingerprint  # as the in-process path records it
    for label, path in models.items():  # where --reuse and a reader of the run expect the models
        model, blob = load_checkpoint(path, "cnode")
        save_checkpoint(files.matrix_models / f"{_slug(label)}.pt", model, blob["config"], blob["channel_names"],
                        extra={"matrix_info": {**blob["matrix_info"], "fingerprint": fingerprint}})
    matrix["meta"]["command"] = command or f"quadfdi solvers matrix --run {run.root}"
    write_json(files.matrix_json, matrix, indent=2)
    figs = draw_matrix(matrix, files.figures)
    write_text(files.matrix_md, matrix_markdown(matrix, matrix["meta"]["command"]))
    log(f"wrote {files.matrix_json.name}, {files.matrix_md.name} and {len(figs)} figures")
    log(ott_sentence(matrix))
    return matrix


def render(run_root: str | Path, cfg: Config, log: Log = print) -> list[Path]:
    """Redraw the solver figures and markdown from the JSON files alone (no solving, no training);
    the study's matched tables are recomputed with ``cfg.solvers.f1_tol`` and ``f1_two_sided``."""
    from quadfdi.solverstudy.plots import draw_matrix, draw_study

    files = SolverFiles(Path(run_root))
    study, matrix = read_outputs(files.root)
    if study is None and matrix is None:
        raise QuadfdiError(f"{files.dir} holds neither solvers.json nor solver_matrix.json: "
                           "run `quadfdi solvers study` or `quadfdi solvers matrix` first")
    written: list[Path] = []
    if study is not None:  # republished as the stage that made the files (core.stage redo)
        with stage(files.root, "solvers", {}) as st:
            st.redo_previous((files.rel(files.study_json),))
            staged, sc = SolverFiles(st.out), cfg.solvers
            study.update(matched_tables(study["solvers"], sc.f1_tol, sc.f1_two_sided))
            study["meta"].update(f1_tol=float(sc.f1_tol), f1_two_sided=bool(sc.f1_two_sided))
            write_json(staged.study_json, study, indent=2)
            written += [files.root / staged.rel(f) for f in draw_study(study, staged.figures)]
            write_text(staged.study_md, study_markdown(study, study["meta"].get("command")))
        written += [files.study_json, files.study_md]
    if matrix is not None:
        with stage(files.root, "solver-matrix", {}) as st:
            st.redo_previous((files.rel(files.matrix_json),))
            staged = SolverFiles(st.out)
            written += [files.root / staged.rel(f) for f in draw_matrix(matrix, staged.figures)]
            write_text(staged.matrix_md, matrix_markdown(matrix, matrix["meta"].get("command")))
        written.append(files.matrix_md)
    log("wrote " + ", ".join(str(w) for w in written))
    return written
