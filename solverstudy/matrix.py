"""Train-solver by deploy-solver matrix, and the control-representation comparison.

Several CNODEs are trained on the same data with the same loop (``train.loop.train_model``), the
same initial weights and the same batches, differing only in the training solver and control:

- ``dopri5`` (told the knots, the training config's rtol/atol) and classic ``rk4`` at a few N,
  point-sampled control: Ott et al. (ICLR 2021) found that a model trained with a fixed step
  larger than a critical size stops being a proper ODE model -- it breaks when solved another
  way. The matrix shows whether ours do: each model is deployed with each solver and against
  its own float64 reference (dopri5, rtol 1e-9, restarted at every knot).
- ``rk4`` at N with the step-average control (``models.variants.AverageControlCNODE``), where
  even a coarse grid sees every sample. That changes the model, so it is trained that way and
  compared with the point-sampled model trained at the same N, at equal evaluations (4N).

Deploy solves run on the whole test split in batches (``batch`` windows; an adaptive solver's
steps are shared by a batch, which the record says). The point is accuracy, not cost: the
per-window costs are in the solver study (``solverstudy.study.run_study``).

What is trained and deployed, the epochs, the training subset, the batch and the break tolerance
come from the config's [solvers] section (``matrix_*``, ``break_tol``). Library only;
``solverstudy.run.matrix_run`` writes the files and keeps the trained models.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import torch

from quadfdi.core.config import Config, replace_section
from quadfdi.solverstudy.config import SolversConfig
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import Windows
from quadfdi.solverstudy.settings import Setting, parse_settings, reference_setting
from quadfdi.solverstudy.study import compare, solve_batched, with_setting
from quadfdi.train.data import class_weights, fit_normalisation, split_windows
from quadfdi.train.loop import train_model
from quadfdi.models.networks import CNODE, build_model

BREAK_TOL = SolversConfig.break_tol  # a model "breaks" when the reference's macro F1 is this far below its own solver's


@dataclass(frozen=True)
class TrainSpec:
    """How one matrix model is trained: a solver setting (its control included)."""

    setting: Setting

    @property
    def label(self) -> str:
        s = self.setting
        if s.is_fixed:
            return s.label
        return f"{s.method} {'jump' if s.jump_t else 'nojump'}"

    @staticmethod
    def parse(text: str, cfg: Config) -> "TrainSpec":
        """``dopri5`` (tolerances and jump_t from the training config), ``dopri5:1e-3[:nojump]``,
        ``rk4:8``, ``rk4:8:avg``."""
        t = text.strip()
        if t in ("dopri5", "bosh3"):
            tc = cfg.train
            return TrainSpec(Setting(t, rtol=tc.rtol, atol=tc.atol, jump_t=tc.jump_t))
        s = Setting.parse(t)
        if s.reference:
            raise ValueError("the reference is a deploy setting, not a training solver")
        return TrainSpec(s)


def matrix_plan(cfg: Config) -> tuple[list[TrainSpec], list[Setting]]:
    """The training specs and deploy settings of ``cfg.solvers``; QuadfdiError on a bad or repeated one."""
    try:
        specs = [TrainSpec.parse(t, cfg) for t in cfg.solvers.matrix_train]
    except ValueError as exc:
        raise QuadfdiError(f"solvers.matrix_train: {exc}") from None
    if len({s.label for s in specs}) != len(specs):
        raise QuadfdiError("solvers.matrix_train must not repeat a setting")
    return specs, parse_settings(cfg.solvers.matrix_deploy, "solvers.matrix_deploy")


def matrix_epochs(cfg: Config) -> int:
    """``solvers.matrix_epochs``, or ``train.epochs`` when it is 0."""
    return cfg.solvers.matrix_epochs or cfg.train.epochs


def subsample(w: Windows, n: int, seed: int = 0) -> Windows:
    """At most ``n`` windows of ``w`` (seeded, order kept); all when n <= 0."""
    if n <= 0 or n >= len(w):
        return w
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x7EA1,)))
    idx = np.sort(rng.choice(len(w), size=n, replace=False))
    return Windows(x=w.x[idx], y=w.y[idx], traj=w.traj[idx], start=w.start[idx], t_end=w.t_end[idx])


def train_variant(ds, cfg: Config, spec: TrainSpec, epochs: int, train: Windows, val: Windows,
                  log: Callable[[str], None] = print) -> tuple[CNODE, dict]:
    """Train one CNODE with ``spec``'s solver and control; same seed, init and batches for every spec."""
    s = spec.setting
    if s.is_fixed:
        tcfg = replace_section(cfg, "train", solver=s.method, steps=int(s.steps), epochs=int(epochs)).train
    else:
        tcfg = replace_section(cfg, "train", solver=s.method, rtol=float(s.rtol), atol=float(s.atol),
                               jump_t=bool(s.jump_t), epochs=int(epochs)).train
    torch.manual_seed(tcfg.seed)  # the same initial weights for every variant
    model = build_model("cnode", ds.n_channels, tcfg, window=cfg.sim.window)
    if s.control == "average":
        model = with_setting(model, s)  # same weights, the averaged-control class
    mean, std = fit_normalisation(ds)
    model.set_normalisation(mean, std)
    log(f"train {spec.label} ({epochs} epochs, {len(train)} windows):")
    t0 = time.perf_counter()
    hist = train_model(model, train, val, tcfg, class_weights(train.y), log)
    info = {
        "label": spec.label,
        **{k: v for k, v in s.to_dict().items() if k != "label"},
        "epochs": int(epochs),
        "n_train_windows": int(len(train)),
        "train_seconds": time.perf_counter() - t0,
        "epoch_seconds": [float(v) for v in hist.epoch_s],
        "nfe_per_forward_train": float(np.mean(hist.nfe_per_forward)) if hist.nfe_per_forward else None,
        "best_epoch": int(hist.best_epoch),
        "best_val_macro_f1": float(max(hist.val_macro_f1)) if hist.val_macro_f1 else None,
    }
    return model, info


def evaluate_cells(model: CNODE, label: str, deploys: Sequence[Setting], test: Windows, batch: int = 96,
                   log: Callable[[str], None] = print) -> list[dict]:
    """Each deploy setting on the whole test split against ``model``'s own float64 reference."""
    ref_setting = next((d for d in deploys if d.reference), reference_setting())
    ref, ref_nfe = solve_batched(model, ref_setting, test.x, batch=batch)
    cells = []
    for d in deploys:
        t0 = time.perf_counter()
        logits, nfe = (ref, ref_nfe) if d == ref_setting else solve_batched(model, d, test.x, batch=batch)
        cell = {
            "train": label,
            "deploy": d.label,
            **compare(logits, ref, test.y),
            "nfe_per_window": float(nfe),
            "nfe_note": "exact" if d.is_fixed else f"per solve of a batch of up to {batch} windows (steps shared)",
            "n_windows": int(len(test)),
            "seconds": time.perf_counter() - t0,
        }
        cells.append(cell)
        log(f"  {label:16s} -> {d.label:28s} F1 {cell['macro_f1']:.4f}  max err {cell['max_logit_err']:.2e}")
    return cells


def run_matrix(ds, cfg: Config, train_specs: Sequence[TrainSpec], deploys: Sequence[Setting],
               models: dict | None = None, on_trained: Callable[[TrainSpec, CNODE, dict], None] | None = None,
               log: Callable[[str], None] = print) -> dict:
    """Train every spec (unless ``models`` already holds its label: (model, info)) and deploy each
    with each setting; epochs, training subset, batch and break tolerance from ``cfg.solvers``.
    Returns ``{"train": [...], "deploy": [...], "cells": [...], "ott": [...], "controls": [...],
    "meta": {...}}``; ``models`` (if given) is filled with the trained models.
    ``on_trained(spec, model, info)`` runs right after each training (``matrix_run`` saves the
    model there, so an interrupted matrix resumes with ``reuse``)."""
    t_start = time.perf_counter()
    sc, epochs = cfg.solvers, matrix_epochs(cfg)
    deploys = list(deploys)
    if not any(d.reference for d in deploys):
        deploys.append(reference_setting())
    splits = split_windows(ds)
    train = subsample(splits.train, sc.matrix_max_train_windows, cfg.train.seed)
    models = {} if models is None else models
    infos, cells = [], []
    for spec in train_specs:
        if spec.label not in models:
            models[spec.label] = train_variant(ds, cfg, spec, epochs, train, splits.validation, log)
            if on_trained is not None:
                on_trained(spec, *models[spec.label])
        model, info = models[spec.label]
        infos.append(info)
        cells += evaluate_cells(model, spec.label, deploys, splits.test, sc.matrix_batch, log)
    out = {
        "train": infos,
        "deploy": [d.to_dict() for d in deploys],
        "cells": cells,
        "meta": {
            "epochs": int(epochs),
            "n_train_windows": int(len(train)),
            "n_test_windows": int(len(splits.test)),
            "batch": int(sc.matrix_batch),
            "break_tol": float(sc.break_tol),
            "threads": int(torch.get_num_threads()),
            "seconds": time.perf_counter() - t_start,
            "train_seconds": float(sum(i["train_seconds"] for i in infos)),
        },
    }
    out["ott"] = ott_findings(out, sc.break_tol)
    out["controls"] = control_findings(out)
    return out


def _cell(matrix: dict, train: str, deploy: str) -> dict | None:
    return next((c for c in matrix["cells"] if c["train"] == train and c["deploy"] == deploy), None)


def _own_deploy(info: dict, deploys: list[dict]) -> str | None:
    """The deploy label equal to a model's training solver (rk4 N=8 -> rk4 N=8), if deployed."""
    for d in deploys:
        if d.get("reference") or d["method"] != info["method"] or d["control"] != info["control"]:
            continue
        if d["steps"] is not None:
            if d["steps"] == info["steps"]:
                return d["label"]
        elif d["jump_t"] == info["jump_t"] and np.isclose(d["rtol"], info["rtol"]):
            return d["label"]
    return None


def ott_findings(matrix: dict, tol: float = BREAK_TOL) -> list[dict]:
    """Per trained model: macro F1 under its own training solver and under the reference.

    ``breaks`` when the reference's F1 is more than ``tol`` below the own solver's: the model
    learnt its discretisation rather than an ODE (Ott et al., 2021). ``max_logit_err_own`` is the
    distance between what was trained (the discrete model) and the ODE it stands for.
    """
    ref_label = next(d["label"] for d in matrix["deploy"] if d.get("reference"))
    out = []
    for info in matrix["train"]:
        own = _own_deploy(info, matrix["deploy"])
        c_own, c_ref = (_cell(matrix, info["label"], own) if own else None), _cell(matrix, info["label"], ref_label)
        if c_own is None or c_ref is None:
            continue
        drop = c_own["macro_f1"] - c_ref["macro_f1"]
        others = [c for c in matrix["cells"] if c["train"] == info["label"]]
        out.append({
            "train": info["label"],
            "step": (1.0 / info["steps"]) if info["steps"] else None,
            "control": info["control"],
            "own_deploy": own,
            "macro_f1_own": c_own["macro_f1"],
            "macro_f1_ref": c_ref["macro_f1"],
            "f1_drop_to_ref": drop,
            "max_logit_err_own": c_own["max_logit_err"],
            "worst_deploy": min(others, key=lambda c: c["macro_f1"])["deploy"],
            "worst_macro_f1": min(c["macro_f1"] for c in others),
            "breaks": bool(drop > tol),
        })
    return out


def control_findings(matrix: dict) -> list[dict]:
    """Point-sampled against step-average control, each trained and deployed at the same N (4N evaluations)."""
    infos = {i["label"]: i for i in matrix["train"]}
    out = []
    for info in matrix["train"]:
        if info["control"] != "average" or info["steps"] is None:
            continue
        point = next((i for i in infos.values() if i["control"] == "point" and i["method"] == info["method"]
                      and i["steps"] == info["steps"]), None)
        row = {"method": info["method"], "steps": info["steps"], "nfe_per_window": None,
               "average": info["label"], "point": point["label"] if point else None}
        for name, i in (("average", info), ("point", point)):
            own = _own_deploy(i, matrix["deploy"]) if i else None
            c = _cell(matrix, i["label"], own) if own else None
            row[f"{name}_macro_f1"] = c["macro_f1"] if c else None
            row[f"{name}_max_logit_err"] = c["max_logit_err"] if c else None
            if c:
                row["nfe_per_window"] = c["nfe_per_window"]
        out.append(row)
    return out
