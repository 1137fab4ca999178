"""The train-by-deploy matrix as jobs of ``core.executor``: one per trained model, one reference
solve per model, one job per matrix cell (model x deploy setting).

Three levels, each a sweep of independent jobs, run one after the other in one executor session:

1. ``matrix-train``: train one CNODE per ``solvers.matrix_train`` setting; the checkpoint (bytes)
   is the result, ``<run>/cache/matrix-train/<key>.bin``;
2. ``matrix-ref``: that model's float64 reference logits on the test split (``.npz``);
3. ``matrix-cell``: the model deployed with one ``solvers.matrix_deploy`` setting, compared with its
   reference (``.json``): a cell of the matrix.

A level's inputs (checkpoint, reference) are files hashed into the next level's keys, so a rerun
recomputes only what changed. Training and solves run with ``solvers.matrix_threads`` (or
``train.threads``) torch threads, as ``run_matrix`` does: the same numbers serial or distributed.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from quadfdi.core.config import Config
from quadfdi.core.executor import ExecSettings, Job, failures, run_jobs, session
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jobcache import cache_path, job_key, read_result
from quadfdi.core.rundir import RunDir
from quadfdi.models.threads import torch_threads

PACKAGES = ("sim", "train", "solverstudy")


def _n_threads(cfg: Config) -> int:
    return cfg.solvers.matrix_threads or cfg.train.threads


def _data(dataset: str, cfg: Config):
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.train.data import split_windows

    ds = load_dataset(dataset)
    return ds, split_windows(ds)


def train_matrix_model(dataset: str, cfg: Config, spec) -> bytes:
    """Level 1 (a job): train ``spec``'s CNODE; its checkpoint's bytes, with ``matrix_info``."""
    from quadfdi.solverstudy.matrix import matrix_epochs, subsample, train_variant
    from quadfdi.models.checkpoint import save_checkpoint

    ds, splits = _data(dataset, cfg)
    train = subsample(splits.train, cfg.solvers.matrix_max_train_windows, cfg.train.seed)
    with torch_threads(_n_threads(cfg)):
        model, info = train_variant(ds, cfg, spec, matrix_epochs(cfg), train, splits.validation, log=lambda _: None)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "model.pt"
        save_checkpoint(path, model, cfg.to_dict(), ds.channel_names, extra={"matrix_info": info})
        return path.read_bytes()


def reference_logits(dataset: str, cfg: Config, model_path: str, ref) -> dict:
    """Level 2 (a job): the model's reference logits on the whole test split."""
    from quadfdi.solverstudy.study import solve_batched
    from quadfdi.models.checkpoint import load_checkpoint

    _, splits = _data(dataset, cfg)
    model, _ = load_checkpoint(model_path, "cnode")
    with torch_threads(_n_threads(cfg)):
        logits, nfe = solve_batched(model, ref, splits.test.x, batch=cfg.solvers.matrix_batch)
    return {"logits": logits, "nfe": np.array(nfe, dtype=np.float64)}


def deploy_cell(dataset: str, cfg: Config, model_path: str, ref_path: str, deploy) -> dict:
    """Level 3 (a job): one cell, the model deployed with ``deploy`` against its reference."""
    from quadfdi.solverstudy.study import compare, solve_batched
    from quadfdi.models.checkpoint import load_checkpoint

    _, splits = _data(dataset, cfg)
    model, blob = load_checkpoint(model_path, "cnode")
    ref = read_result(ref_path)
    batch = cfg.solvers.matrix_batch
    t0 = time.perf_counter()
    if deploy.reference:
        logits, nfe = ref["logits"], float(ref["nfe"])
    else:
        with torch_threads(_n_threads(cfg)):
            logits, nfe = solve_batched(model, deploy, splits.test.x, batch=batch)
    return {"train": blob["matrix_info"]["label"], "deploy": deploy.label, **compare(logits, ref["logits"], splits.test.y),
            "nfe_per_window": float(nfe),
            "nfe_note": "exact" if deploy.is_fixed else f"per solve of a batch of up to {batch} windows (steps shared)",
            "n_windows": int(len(splits.test)), "seconds": time.perf_counter() - t0}


def _level(jobs: list[Job], settings: ExecSettings, desc: str, log: Callable[[str], None]) -> list[str]:
    """Run one level; the labels of the jobs taken from the cache. A failed job stops the matrix
    (the next level needs its file), after every other job of the level has run and been cached."""
    results = run_jobs(jobs, settings, desc=desc, log=log)
    bad = failures(results)
    if bad:
        raise QuadfdiError(f"{len(bad)} of {len(jobs)} {desc} jobs failed ({bad[0].job.label}: {bad[0].error}); "
                           "the others are cached: run the same command again to resume")
    return [r.job.label for r in results if r.status == "cached"]


def _key(kind: str, cfg: Config, args: dict, inputs: dict) -> str:
    return job_key(kind, cfg.to_dict(), args, inputs, packages=PACKAGES)


def matrix_jobs_run(run: RunDir, cfg: Config, specs: list, deploys: list, settings: ExecSettings,
                    log: Callable[[str], None] = print) -> tuple[dict, dict[str, Path]]:
    """The matrix dict of ``run_matrix`` (``meta.reused``: models taken from the cache) and each
    model's cached checkpoint file, by label."""
    from quadfdi.solverstudy.matrix import matrix_epochs
    from quadfdi.solverstudy.settings import reference_setting

    deploys = list(deploys)
    if not any(d.reference for d in deploys):
        deploys.append(reference_setting())
    ref_setting = next(d for d in deploys if d.reference)
    ds_path = str(run.dataset)
    t0 = time.perf_counter()
    with session(settings, log):
        train = []
        for s in specs:
            k = _key("matrix-train", cfg, {"spec": s.setting.to_dict()}, {"dataset": run.dataset})
            train.append(Job("matrix-train", k, train_matrix_model, (ds_path, cfg, s),
                             cache_path(run.root, "matrix-train", k, "bin"), label=s.label, torch=True))
        reused = _level(train, settings, "matrix-train", log)
        refs = []
        for s, tj in zip(specs, train):
            k = _key("matrix-ref", cfg, {"ref": ref_setting.to_dict()}, {"dataset": run.dataset, "model": tj.out})
            refs.append(Job("matrix-ref", k, reference_logits, (ds_path, cfg, str(tj.out), ref_setting),
                            cache_path(run.root, "matrix-ref", k, "npz"), label=s.label, torch=True))
        _level(refs, settings, "matrix-ref", log)
        cells = []
        for s, tj, rj in zip(specs, train, refs):
            for d in deploys:
                k = _key("matrix-cell", cfg, {"deploy": d.to_dict()},
                         {"dataset": run.dataset, "model": tj.out, "ref": rj.out})
                cells.append(Job("matrix-cell", k, deploy_cell, (ds_path, cfg, str(tj.out), str(rj.out), d),
                                 cache_path(run.root, "matrix-cell", k, "json"), label=f"{s.label} -> {d.label}",
                                 torch=True))
        _level(cells, settings, "matrix-cell", log)
    matrix, models = _assemble(cfg, specs, deploys, train, cells, matrix_epochs(cfg), time.perf_counter() - t0)
    matrix["meta"]["reused"] = reused
    return matrix, models


def _assemble(cfg, specs, deploys, train, cells, epochs, seconds) -> tuple[dict, dict[str, Path]]:
    from quadfdi.models.checkpoint import load_checkpoint

    infos = [load_checkpoint(j.out, "cnode")[1]["matrix_info"] for j in train]
    sc = cfg.solvers
    cell_rows = [read_result(j.out) for j in cells]
    n_test = cell_rows[0]["n_windows"] if cell_rows else 0
    matrix = {
        "train": infos,
        "deploy": [d.to_dict() for d in deploys],
        "cells": cell_rows,
        "meta": {"epochs": int(epochs), "n_train_windows": int(infos[0]["n_train_windows"]) if infos else 0,
                 "n_test_windows": int(n_test), "batch": int(sc.matrix_batch), "break_tol": float(sc.break_tol),
                 "threads": int(_n_threads(cfg)), "seconds": seconds,
                 "train_seconds": float(sum(i["train_seconds"] for i in infos))},
    }
    from quadfdi.solverstudy.matrix import control_findings, ott_findings

    matrix["ott"] = ott_findings(matrix, sc.break_tol)
    matrix["controls"] = control_findings(matrix)
    return matrix, {s.label: j.out for s, j in zip(specs, train)}

