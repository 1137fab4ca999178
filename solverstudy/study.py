"""The fixed-vs-adaptive solver study of one trained CNODE (SPEC section 6, "Solvers").

Every solver setting is run on the SAME windows, one window per solve, and compared against a
float64 dopri5 reference at rtol 1e-9 restarted at every knot of the path:

- fixed steps (our ``models.solvers``: euler, midpoint, classic rk4) at N steps over [0, 1], with
  the point control (the model's own) and the step-average one (``models.variants``);
- adaptive torchdiffeq solvers (dopri5, bosh3) at several rtol (atol = rtol / 10), with and
  without the knots as ``jump_t``.

Why one window per solve: an adaptive solver's step sizes come from an error norm over the whole
state tensor, batch included, so a window's evaluation count (and its logits) depend on which
other windows share its batch. A deployed classifier sees one window at a time. Solving windows
one by one is slow (a few hundred ms each with ``jump_t``), so the study runs on a fixed seeded
sample of test windows (``solvers.sample``; 0 takes the whole split), and every record says
which. Fixed-step results do not depend on the batch, so their macro F1 on the whole test split is
also given (``split_macro_f1``, batched).

"Matches": ``solverstudy.matching``. Library only: returns dicts; ``solverstudy.run`` writes the files.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import torch
from sklearn.metrics import f1_score

from quadfdi.solverstudy.config import SolversConfig
from quadfdi.solverstudy.matching import matched_tables
from quadfdi.solverstudy.settings import ATOL_RATIO, LABELS, Setting, default_settings, reference_setting
from quadfdi.models.networks import CNODE
from quadfdi.models.variants import rebuild


def with_setting(model: CNODE, setting: Setting) -> CNODE:
    """A copy of ``model``'s weights in the class, dtype and solver of ``setting`` (model untouched)."""
    dtype = torch.float64 if setting.dtype == "float64" else torch.float32
    return rebuild(model, setting.spec(), setting.control, setting.restart, dtype)


# ------------------------------------------------------------------------------ running


def sample_indices(n: int, size: int, seed: int = 0) -> np.ndarray:
    """A fixed, sorted sample of ``size`` of ``n`` windows drawn from ``seed``; all when size <= 0 or >= n."""
    if size <= 0 or size >= n:
        return np.arange(n)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x501F,)))
    return np.sort(rng.choice(n, size=size, replace=False))


@dataclass
class Solves:
    """One window per solve: logits (n, K) float64, evaluations (n,) and seconds (n,) per window."""

    logits: np.ndarray
    nfe: np.ndarray
    seconds: np.ndarray


@torch.no_grad()
def solve_each(model: CNODE, setting: Setting, x: np.ndarray, warmup: int = 1) -> Solves:
    """Solve every window of ``x`` (n, W, C) raw on its own with ``setting``; time each solve.

    The timing is PyTorch eager at batch 1 in this process (whatever torch's thread count is):
    the cost of a solver here, not of a deployed runtime.
    """
    m = with_setting(model, setting)
    dt = torch.float64 if setting.dtype == "float64" else torch.float32
    xt = torch.from_numpy(np.ascontiguousarray(x)).to(dt)
    for i in range(min(warmup, len(xt))):
        m(xt[i:i + 1])
    logits = np.zeros((len(xt), m.n_classes))
    nfe = np.zeros(len(xt), dtype=np.int64)
    secs = np.zeros(len(xt))
    for i in range(len(xt)):
        t0 = time.perf_counter()
        out = m(xt[i:i + 1])
        secs[i] = time.perf_counter() - t0
        logits[i] = out[0].double().numpy()
        nfe[i] = m.nfe
    return Solves(logits, nfe, secs)


@torch.no_grad()
def solve_batched(model: CNODE, setting: Setting, x: np.ndarray, batch: int = 256) -> tuple[np.ndarray, float]:
    """Logits (n, K) float64 of ``x`` solved ``batch`` windows at a time, and the mean NFE per solve.

    Exact per window for fixed steps; for adaptive ones the steps are shared by each batch.
    """
    m = with_setting(model, setting)
    dt = torch.float64 if setting.dtype == "float64" else torch.float32
    outs, nfes = [], []
    for i in range(0, len(x), batch):
        outs.append(m(torch.from_numpy(np.ascontiguousarray(x[i:i + batch])).to(dt)).double().numpy())
        nfes.append(m.nfe)
    return (np.concatenate(outs) if outs else np.zeros((0, m.n_classes))), float(np.mean(nfes) if nfes else 0.0)


def macro_f1(y: np.ndarray, logits: np.ndarray) -> float:
    """Macro F1 over the four classes (as train.metrics: labels 0..3, zero_division 0)."""
    return float(f1_score(y, np.asarray(logits).argmax(1), labels=LABELS, average="macro", zero_division=0))


def compare(logits: np.ndarray, ref: np.ndarray, y: np.ndarray) -> dict:
    """Accuracy of ``logits`` (n, K) on labels y and their distance to the reference logits (n, K)."""
    logits, ref = np.asarray(logits, np.float64), np.asarray(ref, np.float64)
    if logits.shape != ref.shape:
        raise ValueError(f"logits {logits.shape} and reference {ref.shape} differ in shape")
    err = np.abs(logits - ref)
    return {
        "macro_f1": macro_f1(y, logits),
        "argmax_agreement": float(np.mean(logits.argmax(1) == ref.argmax(1))),
        "max_logit_err": float(err.max()) if err.size else 0.0,
        "mean_logit_err": float(err.mean()) if err.size else 0.0,
    }


def record(setting: Setting, solves: Solves, ref: np.ndarray, y: np.ndarray, sample_note: str,
           model: CNODE | None = None) -> dict:
    """The JSON record of one setting (see docs/solvers.md for every field)."""
    nfe_mean = float(solves.nfe.mean())
    out = {
        **setting.to_dict(),
        **compare(solves.logits, ref, y),
        "nfe_per_window": nfe_mean,
        "nfe_min": int(solves.nfe.min()),
        "nfe_max": int(solves.nfe.max()),
        "latency_us": float(np.median(solves.seconds) * 1e6),
        "n_windows": int(len(y)),
        "sample": sample_note,
        "split_macro_f1": None,
        "split_n_windows": None,
    }
    if model is not None:
        out["macs_per_window"] = int(round(model.macs_per_window(evals=nfe_mean)))
    return out


def _sample(x: np.ndarray, y: np.ndarray, size: int, seed: int) -> tuple[np.ndarray, str]:
    idx = sample_indices(len(y), size, seed)
    note = (f"all {len(y)} test windows, one window per solve" if len(idx) == len(y) else
            f"{len(idx)} of {len(y)} test windows (seeded sample, seed {seed}), one window per solve")
    return idx, note


def _meta(model: CNODE, cfg: SolversConfig, y: np.ndarray, idx: np.ndarray, note: str, check: dict | None,
          t_start: float, where: str) -> dict:
    threads = torch.get_num_threads()
    return {
        "reference_check": check,
        "n_test_windows": int(len(y)),
        "n_windows": int(len(idx)),
        "sample_seed": int(cfg.sample_seed),
        "sample": note,
        "sample_indices": [int(i) for i in idx],
        "atol_rule": f"atol = rtol * {ATOL_RATIO:g}",
        "f1_tol": float(cfg.f1_tol),
        "f1_two_sided": bool(cfg.f1_two_sided),
        "control": getattr(model, "control", "point"),
        "threads": int(threads),
        "latency_note": ("PyTorch eager, batch 1, median over the sample's one-window solves, measured in "
                         f"{where} with {threads} intra-op thread(s); a solver's cost "
                         "here, not a deployed runtime's (see the latency table for those)"),
        "versions": _versions(),
        "seconds": time.perf_counter() - t_start,
    }


SPLIT_BATCH = 256  # windows per batched solve of the whole split (an adaptive solver's steps are shared within one)


@dataclass(frozen=True)
class Task:
    """One unit of the study: ``setting`` solved on the sample's windows one by one (the first
    ``windows`` of them; 0: all), and, with ``split``, batched over the whole split for its macro F1.
    ``warmup``: untimed solves first (the reference check times nothing it reports)."""

    setting: Setting
    split: bool = False
    windows: int = 0
    warmup: int = 1


def run_task(model: CNODE, task: Task, x: np.ndarray, y: np.ndarray, idx: np.ndarray,
             batch: int | None = None) -> tuple[Solves, float | None]:
    """``task`` on windows x (n, W, C) with labels y: its one-by-one solves of x[idx] and its split macro F1
    (solved ``batch`` windows at a time, default ``SPLIT_BATCH``)."""
    xs = x[idx] if task.windows <= 0 else x[idx[:task.windows]]
    solves = solve_each(model, task.setting, xs, warmup=task.warmup)
    if not task.split:
        return solves, None
    return solves, macro_f1(y, solve_batched(model, task.setting, x, batch=batch or SPLIT_BATCH)[0])


def study_tasks(model: CNODE, settings: Sequence[Setting], cfg: SolversConfig, split_f1: bool,
                check_windows: int) -> list[Task]:
    """The study's tasks in order: the reference, its check (when ``check_windows``), then every setting."""
    tasks = [Task(reference_setting(cfg.ref_rtol), split=split_f1)]
    if check_windows > 0:
        tasks.append(Task(check_setting(model), windows=check_windows, warmup=0))
    # fixed steps: batching changes nothing, so the whole split is cheap; adaptive steps depend on the batch
    return tasks + [Task(s, split=split_f1 and s.is_fixed) for s in settings]


# (tasks, sample indices, windows x, labels y) -> each task's solves and split macro F1, in order
RunTasks = Callable[[list[Task], np.ndarray, np.ndarray, np.ndarray], list[tuple[Solves, float | None]]]


def run_here(model: CNODE, log: Callable[[str], None]) -> RunTasks:
    """The study's tasks one after the other in this process (what ``run_study`` does by default)."""
    def run_all(tasks: list[Task], idx: np.ndarray, x: np.ndarray, y: np.ndarray) -> list[tuple[Solves, float | None]]:
        out = []
        for t in tasks:
            t0 = time.perf_counter()
            out.append(run_task(model, t, x, y, idx))
            log(f"  {t.setting.label:28s} solved in {time.perf_counter() - t0:.1f} s")
        return out
    return run_all


def run_study(model: CNODE, x: np.ndarray, y: np.ndarray, cfg: SolversConfig | None = None,
              settings: Sequence[Setting] | None = None, split_f1: bool = True, check_windows: int = 8,
              log: Callable[[str], None] = print, run_tasks: RunTasks | None = None,
              where: str = "this process") -> dict:
    """The solver study of one CNODE on test windows x (n, W, C) raw with labels y (n,).

    ``cfg`` ([solvers], default its defaults) gives the sample, the reference tolerance and the
    matching rule, and the grid unless ``settings`` is given. ``run_tasks`` solves ``study_tasks``
    (default: ``run_here``; ``solverstudy.study_jobs``: as executor jobs, the same numbers; ``where``
    says where they were timed). Returns
    ``{"solvers": [record, ...], "matched": [...], "matched_any_control": [...] or None,
    "reference": record, "meta": {...}}``; the reference's own record comes first in ``solvers``
    (error 0 by definition).
    """
    cfg = SolversConfig() if cfg is None else cfg
    x, y = np.asarray(x), np.asarray(y)
    if x.ndim != 3 or len(x) != len(y) or len(y) == 0:
        raise ValueError(f"need windows (n, W, C) and labels (n,), found {x.shape} and {y.shape}")
    settings = list(default_settings(cfg) if settings is None else settings)
    t_start = time.perf_counter()
    idx, note = _sample(x, y, cfg.sample, cfg.sample_seed)
    log(f"solver study: {len(settings)} settings on {note}")
    tasks = study_tasks(model, settings, cfg, split_f1, check_windows)
    results = (run_tasks or run_here(model, log))(tasks, idx, x, y)
    (ref_solves, ref_split), rest = results[0], results[1:]
    ref = ref_solves.logits
    records = [_with_split(record(tasks[0].setting, ref_solves, ref, y[idx], note, model), ref_split, y)]
    log(f"  {tasks[0].setting.label}: {records[0]['nfe_per_window']:.0f} NFE/window")
    check = None
    if check_windows > 0:
        (check_solves, _), rest = rest[0], rest[1:]
        check = {"against": tasks[1].setting.label, "n_windows": int(len(check_solves.logits)),
                 "max_abs_logit_diff": float(np.abs(check_solves.logits - ref[:check_windows]).max())}
        log(f"  reference vs {check['against']}: max logit difference {check['max_abs_logit_diff']:.1e} "
            f"on {check['n_windows']} windows")
    for s, (solves, split) in zip(settings, rest):
        rec = _with_split(record(s, solves, ref, y[idx], note, model), split, y)
        records.append(rec)
        log(f"  {s.label:28s} F1 {rec['macro_f1']:.4f}  max err {rec['max_logit_err']:.2e}  "
            f"{rec['nfe_per_window']:7.1f} NFE  {rec['latency_us'] / 1e3:8.2f} ms")
    return {
        "solvers": records,
        **matched_tables(records, cfg.f1_tol, cfg.f1_two_sided),
        "reference": records[0],
        "meta": _meta(model, cfg, y, idx, note, check, t_start, where),
    }


def _with_split(rec: dict, split: float | None, y: np.ndarray) -> dict:
    if split is not None:
        rec["split_macro_f1"] = split
        rec["split_n_windows"] = int(len(y))
    return rec


def check_setting(model: CNODE) -> Setting:
    """The reference's independent check: float64 classic RK4 with 8 steps per segment.

    RK4 at N = 8 (W - 1) puts its stage times on the knots, so on each linear piece of the path
    it is a plain 4th-order solve of a smooth ODE (error ~1e-10 here), with no step control
    and no torchdiffeq involved. The study's errors are only meaningful well above this value.
    """
    return Setting("rk4", steps=8 * (model.window - 1), dtype="float64")


def _versions() -> dict:
    import torchdiffeq

    return {"torch": torch.__version__, "torchdiffeq": getattr(torchdiffeq, "__version__", "?")}


