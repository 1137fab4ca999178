"""Three non-neural baselines under one tuning protocol.

- ``logreg_stats``: ``StandardScaler`` + multinomial ``LogisticRegression(class_weight="balanced")``
  on the window statistics (``train.features.stat_features``: mean, slope, std per channel; the
  features of train/baseline.py, the paper's baseline);
- ``logreg_physics``: the same on the physics features (``train.features.physics_features``:
  internal resistance from dV/dI, voltage per cell, motor command ratios, temperature differences
  and their slopes, vibration level, SoC slope);
- ``gbt``: ``HistGradientBoostingClassifier(class_weight="balanced")``, seeded, on statistics and
  physics features together;
- ``logreg_physics_ref``, ``gbt_ref`` (``REF_MODELS``, on a dataset whose vehicles have reference flights,
  train.features_ref): the same, the physics features that describe the airframe taken relative to the
  window's own vehicle's reference (train/vehicle_ref.py). They never read a reference flight: not in
  training (their features there are in-sample), not in the choice, not in their reported scores.

On such a dataset every model's choice reads the validation flights that are not reference flights: the
flights the evaluation scores (evaluate/load.py leaves reference flights out).

The tuning budget is the same for every baseline: ``N_CONFIGS`` hyperparameter configurations each
(``GRIDS``), every one fitted on the same training windows (a reference model's: those of the
non-reference flights, under the same cap) and scored by macro F1 on the VALIDATION windows; the best is kept (the first on a tie). Test and out-of-distribution windows
are only predicted, never scored for a choice. Training windows are subsampled without replacement
(seeded, ``MAX_TRAIN_WINDOWS``) so that the five fits of a baseline take about a minute on one
core at 5 configurations; every fit runs on one thread (``threadpool_limits(1)``).

``fit_baselines(ds, seed)`` returns, per model, the probabilities on every evaluation window
(split >= 1) of the dataset and the record of its choice (``BaselineResult``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.ensemble import HistGradientBoostingClassifier
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import f1_score
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from threadpoolctl import threadpool_limits

from quadfdi.formats.dataset import Dataset, class_names, make_windows, split_names, vehicle_columns
from quadfdi.train.features import physics_feature_names, physics_features, stat_feature_names, stat_features
from quadfdi.train.features_ref import ref_feature_names, ref_features
from quadfdi.train.vehicle_ref import VehicleRefs, has_vehicles, vehicle_refs

MODELS = ("logreg_stats", "logreg_physics", "gbt")
REF_MODELS = ("logreg_physics_ref", "gbt_ref")  # each with its reference-free twin's grid
N_CONFIGS = 24  # hyperparameter configurations tried per baseline: the networks' recipe search's budget
MAX_TRAIN_WINDOWS = 8000  # seeded subsample of the training windows (realistic suite: 31,680 in all)
MAX_ITER_LR = 3000
N_BINS = 255  # feature bins of the trees (sklearn's default max_bins), from training quantiles (QuantileBins)
CHUNK = 4096  # windows per feature batch (bounds the float64 copy to ~65 MB at W = 80, C = 25)
_LR_C = tuple(float(c) for c in np.logspace(-4.0, 4.0, N_CONFIGS))  # the inverse L2 strength, its only knob
# the trees: rate x leaves x L2, with the boosting rounds scaled to the rate (about 10 / rate)
_GBT = [{"learning_rate": lr, "max_iter": it, "max_leaf_nodes": leaves, "l2_regularization": l2}
        for lr, it in ((0.05, 200), (0.1, 100), (0.2, 50)) for leaves in (7, 15, 31, 63) for l2 in (0.0, 1.0)]
GRIDS: dict[str, list[dict[str, Any]]] = {
    "logreg_stats": [{"C": c} for c in _LR_C],
    "logreg_physics": [{"C": c} for c in _LR_C],
    "gbt": _GBT,
}
GRIDS.update({m: GRIDS[m[:-len("_ref")]] for m in REF_MODELS})
assert all(len(g) == N_CONFIGS for g in GRIDS.values()), "every baseline gets the same tuning budget"
_SUBSAMPLE_KEY = 0xBA5E  # spawn key of the training-window subsample's generator


@dataclass(frozen=True)
class Block:
    """Features and labels of a set of windows: ``stats`` (n, 3 C), ``physics`` (n, F), ``y``, ``traj``
    (n,) int64, ``t_end`` (n,) float64, ``split`` (n,) int8, ``ref_phys`` (n, G) the reference-relative
    physics features (G = 0 without vehicle references), ``ref_flight`` (n,) bool (a reference flight's)."""

    stats: np.ndarray
    physics: np.ndarray
    y: np.ndarray
    traj: np.ndarray
    t_end: np.ndarray
    split: np.ndarray
    ref_phys: np.ndarray
    ref_flight: np.ndarray

    def inputs(self, model: str) -> np.ndarray:
        if model == "logreg_stats":
            return self.stats
        if model == "logreg_physics":
            return self.physics
        if model == "logreg_physics_ref":
            return self.ref_phys
        if model == "gbt_ref":
            return np.concatenate([self.stats, self.ref_phys], axis=1)
        return np.concatenate([self.stats, self.physics], axis=1)

    def where(self, keep: np.ndarray) -> "Block":
        return Block(*(getattr(self, f)[keep] for f in BLOCK_FIELDS))


BLOCK_FIELDS = ("stats", "physics", "y", "traj", "t_end", "split", "ref_phys", "ref_flight")


@dataclass
class BaselineResult:
    """One baseline fitted on one dataset: ``proba`` (n_eval, K) on the evaluation windows and the record."""

    proba: np.ndarray
    record: dict[str, Any] = field(default_factory=dict)


def split_block(ds: Dataset, code: int, seed: int = 0, cap: int | None = None, refs: VehicleRefs | None = None,
                exclude_reference: bool = False) -> tuple[Block, int]:
    """The features of the windows of split ``code`` (a seeded subsample of at most ``cap`` of them
    when ``cap`` is given; of the non-reference flights' windows with ``exclude_reference``) and the
    number of windows it was drawn from; with ``refs``, the reference-relative features too."""
    w = make_windows(ds, split_names(ds.arrays)[code])
    ref_flight = vehicle_columns(ds.arrays)["reference_flight"][w.traj].astype(bool)
    pool = np.flatnonzero(~ref_flight) if exclude_reference else np.arange(len(w))
    idx = pool if cap is None else pool[train_subsample(len(pool), seed, cap)]
    names = ds.channel_names
    cells = ds.arrays.get("pack_cells")
    stats, phys, rel = [], [], []
    for s in range(0, len(idx), CHUNK):
        rows = idx[s:s + CHUNK]
        x = w.x[rows]  # (m, W, C)
        k = None if cells is None else cells[w.traj[rows]]
        stats.append(stat_features(x, names))
        phys.append(physics_features(x, names, k))
        if refs is not None:
            rel.append(ref_features(x, names, k, *refs.windows(w.traj[rows], w.start[rows], x.shape[1])))
    n_stat, n_phys = 3 * len(names), len(physics_feature_names(names))
    n_rel = 0 if refs is None else len(ref_feature_names(names))
    block = Block(stats=np.concatenate(stats) if stats else np.zeros((0, n_stat)),
                  physics=np.concatenate(phys) if phys else np.zeros((0, n_phys)),
                  y=w.y[idx], traj=w.traj[idx], t_end=w.t_end[idx], split=np.full(len(idx), code, np.int8),
                  ref_phys=np.concatenate(rel) if rel else np.zeros((len(idx), n_rel)), ref_flight=ref_flight[idx])
    return block, len(pool)


def train_subsample(n: int, seed: int, cap: int = MAX_TRAIN_WINDOWS) -> np.ndarray:
    """Sorted indices of at most ``cap`` of ``n`` training windows, drawn without replacement from ``seed``
    (every window when ``cap`` is 0)."""
    if cap <= 0 or n <= cap:
        return np.arange(n)
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(_SUBSAMPLE_KEY,)))
    return np.sort(rng.choice(n, size=cap, replace=False))


class QuantileBins(TransformerMixin, BaseEstimator):
    """Each feature replaced by its bin index among ``n_bins`` quantile bins of the training data.

    HistGradientBoostingClassifier bins its inputs itself, but with class weights it computes each
    threshold as a weighted percentile in Python (sklearn 1.9: about 95 % of a fit's time, 10 s per
    fit at 8,000 windows). Binned here, unweighted (the training windows' quantiles, as sklearn does
    without weights), every feature has at most ``n_bins`` distinct values and the trees' own binning
    takes its fast path; the class weights still weight the loss. Features (n, F) -> (n, F) float.
    """

    def __init__(self, n_bins: int = N_BINS):
        self.n_bins = n_bins

    def fit(self, X, y=None):
        q = np.linspace(0.0, 100.0, self.n_bins + 1)[1:-1]
        x = np.asarray(X, dtype=np.float64)
        self.edges_ = [np.unique(np.percentile(x[:, j], q, method="averaged_inverted_cdf")) for j in range(x.shape[1])]
        return self

    def transform(self, X):
        x = np.asarray(X, dtype=np.float64)
        if x.shape[1] != len(self.edges_):
            raise ValueError(f"features have shape {x.shape}, the bins were fitted on {len(self.edges_)} columns")
        return np.stack([np.searchsorted(e, x[:, j], side="left") for j, e in enumerate(self.edges_)], axis=1).astype(float)


def make_estimator(model: str, params: dict[str, Any], seed: int):
    if model not in GRIDS:
        raise ValueError(f"unknown baseline {model!r}; valid: {', '.join(MODELS + REF_MODELS)}")
    if model in ("gbt", "gbt_ref"):
        return Pipeline([("bins", QuantileBins(N_BINS)),
                         ("clf", HistGradientBoostingClassifier(**params, class_weight="balanced", early_stopping=False,
                                                                max_bins=N_BINS, random_state=int(seed)))])
    return Pipeline([("scale", StandardScaler()),
                     ("clf", LogisticRegression(**params, class_weight="balanced", max_iter=MAX_ITER_LR,
                                                random_state=int(seed)))])


def full_proba(est, x: np.ndarray, n_classes: int) -> np.ndarray:
    """(n, K) probabilities in label order; 0 for a class the estimator never saw in training."""
    out = np.zeros((x.shape[0], n_classes))
    out[:, np.asarray(est.classes_, dtype=np.int64)] = est.predict_proba(x)
    return out


def macro_f1(y: np.ndarray, proba: np.ndarray) -> float:
    k = proba.shape[1]
    return float(f1_score(y, proba.argmax(axis=1), labels=list(range(k)), average="macro", zero_division=0))


def tune(model: str, train: Block, val: Block, n_classes: int, seed: int) -> tuple[Any, dict[str, Any]]:
    """Fit every configuration of ``GRIDS[model]`` on ``train``; keep the best by validation macro F1."""
    x_tr, x_val = train.inputs(model), val.inputs(model)
    best, scores, seconds, cpu = None, [], [], []
    with threadpool_limits(1):
        for params in GRIDS[model]:
            t0, c0 = time.perf_counter(), time.process_time()
            est = make_estimator(model, params, seed).fit(x_tr, train.y)
            seconds.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            scores.append(macro_f1(val.y, full_proba(est, x_val, n_classes)))
            if best is None or scores[-1] > scores[best[0]]:
                best = (len(scores) - 1, est)
    chosen, est = best
    record = {"grid": GRIDS[model], "validation_macro_f1": scores, "fit_seconds": seconds, "fit_cpu_seconds": cpu,
              "chosen": chosen, "params": GRIDS[model][chosen], "tuning_seconds": float(sum(seconds)),
              "tuning_cpu_seconds": float(sum(cpu))}
    return est, record


def eval_codes(ds: Dataset) -> list[int]:
    """Every split code >= 1 present in the dataset (validation, test, out-of-distribution sets)."""
    return sorted(int(c) for c in np.unique(ds["split"]) if int(c) >= 1)


def usable_models(ds: Dataset, models: Sequence[str]) -> list[str]:
    """``models`` less the reference models when the dataset's vehicles have no reference flights."""
    return [m for m in models if m not in REF_MODELS or has_vehicles(ds.arrays)]


def fit_baselines(ds: Dataset, seed: int, models: Sequence[str] = MODELS,
                  cap: int = MAX_TRAIN_WINDOWS) -> tuple[Block, dict[str, BaselineResult]]:
    """Fit ``models`` on ``ds`` (tuned on validation); the evaluation windows and each model's result.
    A reference model is refused (ValueError) on a dataset without vehicle references (``usable_models``)."""
    classes = class_names(ds.arrays)
    codes = eval_codes(ds)
    if 0 not in set(np.unique(ds["split"]).tolist()) or 1 not in codes:
        raise ValueError(f"{ds.path}: the baselines need training (0) and validation (1) flights")
    if list(usable_models(ds, models)) != list(models):
        raise ValueError(f"{ds.path}: {', '.join(REF_MODELS)} need vehicles with reference flights (a fleet dataset)")
    refs = vehicle_refs(ds.arrays, ds.path.name if ds.path else "dataset") if set(models) & set(REF_MODELS) else None
    trains = {False: split_block(ds, 0, seed, cap, refs)}
    if refs is not None:
        trains[True] = split_block(ds, 0, seed, cap, refs, exclude_reference=True)
    if len(np.unique(trains[False][0].y)) < 2:
        raise ValueError(f"{ds.path}: the training windows hold a single class")
    blocks = [split_block(ds, c, refs=refs)[0] for c in codes]
    order = np.lexsort((np.concatenate([b.t_end for b in blocks]), np.concatenate([b.traj for b in blocks])))
    evals = Block(*(np.concatenate([getattr(b, f) for b in blocks])[order] for f in BLOCK_FIELDS))
    val = blocks[0].where(~blocks[0].ref_flight)  # the flights the evaluation scores
    scored = ~evals.ref_flight
    out = {}
    for model in models:
        train, n_train = trains[model in REF_MODELS]
        est, record = tune(model, train, val, len(classes), seed)
        with threadpool_limits(1):
            proba = full_proba(est, evals.inputs(model), len(classes))
        record.update(report_scores(evals.where(scored), proba[scored], codes, split_names(ds.arrays), classes))
        record.update(n_train_windows=len(train.y), n_train_available=n_train, max_train_windows=int(cap),
                      features=feature_names(model, ds.channel_names))
        out[model] = BaselineResult(proba=proba, record=record)
    return evals, out


def report_scores(evals: Block, proba: np.ndarray, codes: Sequence[int], splits: Sequence[str],
                  classes: Sequence[str]) -> dict[str, Any]:
    """Macro F1 and per-class F1 on every evaluation split: reported only, the choice used validation."""
    macro, per_class = {}, {}
    for c in codes:
        m = evals.split == c
        macro[splits[c]] = macro_f1(evals.y[m], proba[m])
        f = f1_score(evals.y[m], proba[m].argmax(axis=1), labels=list(range(len(classes))), average=None,
                     zero_division=0)
        per_class[splits[c]] = dict(zip(classes, (float(v) for v in f)))
    return {"macro_f1_by_split": macro, "f1_per_class_by_split": per_class}


def feature_names(model: str, channel_names: Sequence[str]) -> list[str]:
    names = list(channel_names)
    if model == "logreg_stats":
        return stat_feature_names(names)
    if model == "logreg_physics":
        return physics_feature_names(names)
    if model == "logreg_physics_ref":
        return ref_feature_names(names)
    if model == "gbt_ref":
        return stat_feature_names(names) + ref_feature_names(names)
    return stat_feature_names(names) + physics_feature_names(names)
