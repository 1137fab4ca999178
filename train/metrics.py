"""Test-set metrics of a window classifier (paper Eq. 13; ``metrics.json`` in docs/formats.md).

Inputs are the columns of ``predictions_<model>.npz``: ``y_true`` (n,) int labels 0..K-1,
``proba`` (n, K) class probabilities (columns in ``class_names`` order -- the data's classes, the
paper's four ``CLASS_NAMES`` by default; Healthy is label 0 in every suite -- rows summing to 1
within 1e-4; they are renormalised in float64 so that a float32 softmax passes scikit-learn's
sum-to-one check -- a change of order 1e-7 that leaves every arg-max and ranking unchanged),
``traj`` (n,) index of each window's trajectory into the dataset's per-trajectory arrays and
``t_end`` (n,) the window's end time in s; plus two per-trajectory arrays of the dataset: the
trajectory's fault class (0 = Healthy) and its detectable time t_det in s (NaN when healthy).

``compute_metrics`` returns a dict with exactly the keys of ``METRIC_KEYS``. Where scikit-learn
defines a metric, its value is scikit-learn's (computed by calling it, not re-derived):

- ``accuracy``, ``balanced_accuracy``: ``accuracy_score``, ``balanced_accuracy_score`` of the
  arg-max decision. Balanced accuracy averages the recall of the classes present in ``y_true``
  (scikit-learn's definition; a class absent from ``y_true`` is left out, not scored 0).
- ``macro_precision``, ``macro_recall``, ``macro_f1``, ``per_class``:
  ``precision_recall_fscore_support(labels=0..K-1, zero_division=0)``, so a class with no
  predicted (precision) or no true (recall) window scores 0 and still counts in the macro mean.
- ``weighted_f1``: ``f1_score(average="weighted")``, same labels and ``zero_division``.
- ``mcc``: ``matthews_corrcoef`` (multiclass); scikit-learn returns 0.0 when it is 0/0.
- ``macro_specificity`` (no scikit-learn function): from ``confusion_matrix(labels=0..K-1)``,
  specificity_k = TN_k / (TN_k + FP_k) where TN_k + FP_k is the number of windows whose true
  class is not k. A class with no negatives (every window is of class k) has 0/0 and is skipped;
  the macro value is the mean over the remaining classes (NaN if none remains).
- ``roc_auc_ovr``, ``pr_auc_ovr``: one-vs-rest, macro. For class k the binary problem is
  ``y_true == k`` scored by ``proba[:, k]``; ``roc_auc_score`` / ``average_precision_score``
  (average="macro") on the ``label_binarize`` indicator. Only classes with both positives and
  negatives in ``y_true`` enter the mean: ROC-AUC is undefined otherwise, and average precision
  is undefined without positives and trivially 1 without negatives. NaN if no class qualifies
  (``y_true`` of a single class). With all K classes present this equals
  ``roc_auc_score(y_true, proba, multi_class="ovr", average="macro")`` and
  ``average_precision_score(y_true, proba, average="macro")``.
- ``brier``: scikit-learn's multiclass Brier score,
  ``brier_score_loss(y_true, proba, labels=0..K-1)`` = mean over windows of the sum over
  the K classes of (p_k - onehot_k)^2, range [0, 2]. Relative to the paper's per-class
  Eq. 13 this is the SUM over classes of Brier_k (Brier_k = ``brier_score_loss(y_true == k,
  proba[:, k])``), not their mean: divide by K for the mean per-class Brier score. This
  normalisation is chosen because the project's rule is that a metric scikit-learn defines takes
  scikit-learn's value, and scikit-learn (>= 1.7) defines the multiclass Brier score this way.
- ``any_fault_f1``, ``any_fault_roc_auc``: the any-fault score of a window is
  1 - p(Healthy) (the sum of the K - 1 fault probabilities); its decision is positive when the
  score is > 0.5. ``f1_score(y_true != 0, decision, zero_division=0)`` and
  ``roc_auc_score(y_true != 0, score)`` (NaN when ``y_true`` is all healthy or all faulty).

Trajectory-level detection (``detection_metrics``; no scikit-learn counterpart), over the
trajectories that appear in ``traj``:

- ``mean_detection_delay_s``: for each fault trajectory (class != 0), the delay is the end time
  of the first window (in time order) ending at or after t_det whose any-fault decision is
  positive, minus t_det. Alarms of windows ending before t_det are ignored. "At or after" uses a
  tolerance of ``T_TOL_S`` = 1e-6 s (far below the 0.04 s sample period) so that a window ending
  exactly at t_det is not lost to float rounding; such a delay is clipped to 0. The mean is over
  detected fault trajectories, NaN if none was detected.
- ``missed_faults``: the number (int) of fault trajectories with no such window.
- ``false_alarm_rate``: the share of HEALTHY trajectories (class 0) with at least one positive
  window (NaN if no healthy trajectory is evaluated). A detector that always alarms scores 1.0.
  The windows of a fault trajectory that end before its t_det carry the label Healthy in the
  dataset, but they belong to a fault trajectory: an alarm there is not counted in this
  trajectory-level rate (it still counts as a window-level error in the classification metrics).

Undefined values are NaN, never an exception; ``to_jsonable`` turns them into JSON null.
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from sklearn.exceptions import UndefinedMetricWarning
from sklearn.metrics import (
    accuracy_score,
    average_precision_score,
    balanced_accuracy_score,
    brier_score_loss,
    confusion_matrix,
    f1_score,
    matthews_corrcoef,
    precision_recall_fscore_support,
    roc_auc_score,
)
from sklearn.preprocessing import label_binarize

from quadfdi.core.contracts import CLASS_NAMES, HEALTHY

THRESHOLD = 0.5  # any-fault decision: 1 - p(Healthy) > THRESHOLD
T_TOL_S = 1e-6  # tolerance of "window ending at or after t_det"

CLASSIFICATION_KEYS = (
    "accuracy",
    "balanced_accuracy",
    "macro_precision",
    "macro_recall",
    "macro_specificity",
    "macro_f1",
    "weighted_f1",
    "mcc",
    "roc_auc_ovr",
    "pr_auc_ovr",
    "brier",
    "any_fault_f1",
    "any_fault_roc_auc",
)
DETECTION_KEYS = ("mean_detection_delay_s", "missed_faults", "false_alarm_rate")
PER_CLASS_KEYS = ("precision", "recall", "f1")
METRIC_KEYS = CLASSIFICATION_KEYS + DETECTION_KEYS + ("per_class",)


# ----------------------------------------------------------------------------- validation


def _check_proba(proba: Any, k: int | None = None) -> np.ndarray:
    """``proba`` checked; ``k``: its number of columns (None: any, at least 2)."""
    p = np.asarray(proba, dtype=np.float64)
    if p.ndim != 2 or (p.shape[1] != k if k is not None else p.shape[1] < 2):
        raise ValueError(f"proba must have shape (n, {k if k is not None else 'K >= 2'}), found {p.shape}")
    if p.shape[0] == 0:
        raise ValueError("proba is empty: no window to evaluate")
    if not np.all(np.isfinite(p)):
        raise ValueError("proba contains NaN or inf")
    if p.min() < -1e-6 or p.max() > 1 + 1e-6:
        raise ValueError(f"proba must lie in [0, 1], found range [{p.min():.6g}, {p.max():.6g}]")
    worst = float(np.abs(p.sum(axis=1) - 1.0).max())
    if worst > 1e-4:
        raise ValueError(f"proba rows must sum to 1 (softmax output), worst row is off by {worst:.3g}")
    p = np.clip(p, 0.0, 1.0)
    return p / p.sum(axis=1, keepdims=True)  # exact in float64 (float32 softmax is off by ~1e-7)


def _check_labels(y_true: Any, n: int, k: int) -> np.ndarray:
    y = np.asarray(y_true)
    if y.shape != (n,):
        raise ValueError(f"y_true must have shape ({n},), found {y.shape}")
    if y.dtype.kind not in "iub":
        if y.dtype.kind == "f" and np.all(np.isfinite(y)) and np.all(y == np.round(y)):
            y = y.astype(np.int64)
        else:
            raise ValueError(f"y_true must hold integer class labels, found dtype {y.dtype}")
    y = y.astype(np.int64)
    if y.min() < 0 or y.max() >= k:
        raise ValueError(f"y_true labels must be in 0..{k - 1}, found range [{y.min()}, {y.max()}]")
    return y


# The warnings scikit-learn raises for the undefined cases this module handles and documents.
_QUIET = (
    (UndefinedMetricWarning, ""),
    (UserWarning, re.escape("y_pred contains classes not in y_true")),
)


class _quiet_sklearn(warnings.catch_warnings):
    def __enter__(self):
        out = super().__enter__()
        for category, message in _QUIET:
            warnings.filterwarnings("ignore", message=message, category=category)
        return out


# ----------------------------------------------------------------------------- classification


def any_fault_score(proba: Any) -> np.ndarray:
    """1 - p(Healthy) per window: the summed probability of the fault classes."""
    p = _check_proba(proba)
    return 1.0 - p[:, HEALTHY]


def any_fault_decision(proba: Any) -> np.ndarray:
    """Boolean any-fault decision per window: 1 - p(Healthy) > 0.5."""
    return any_fault_score(proba) > THRESHOLD


def macro_specificity(y_true: Any, y_pred: Any, n_classes: int = len(CLASS_NAMES)) -> float:
    """Mean over classes of TN/(TN+FP) from the K x K confusion matrix; 0/0 classes skipped (NaN if all)."""
    cm = confusion_matrix(y_true, y_pred, labels=list(range(n_classes)))
    n = cm.sum()
    spec = []
    for k in range(n_classes):
        fp = cm[:, k].sum() - cm[k, k]
        negatives = n - cm[k, :].sum()  # TN + FP: windows whose true class is not k
        if negatives == 0:
            continue
        tn = negatives - fp
        spec.append(tn / negatives)
    return float(np.mean(spec)) if spec else math.nan


def _ovr_auc(y: np.ndarray, p: np.ndarray) -> tuple[float, float]:
    """Macro one-vs-rest ROC-AUC and PR-AUC over the classes with positives and negatives."""
    onehot = label_binarize(y, classes=list(range(p.shape[1])))
    pos = onehot.sum(axis=0)
    ok = (pos > 0) & (pos < len(y))
    if not ok.any():
        return math.nan, math.nan
    cols = np.flatnonzero(ok)
    roc = roc_auc_score(onehot[:, cols], p[:, cols], average="macro")
    ap = average_precision_score(onehot[:, cols], p[:, cols], average="macro")
    return float(roc), float(ap)


def classification_metrics(y_true: Any, proba: Any, class_names: Sequence[str] = CLASS_NAMES) -> dict:
    """Window-level metrics of ``CLASSIFICATION_KEYS`` plus ``per_class`` named by ``class_names``
    (K names, label order; see the module docstring)."""
    p = _check_proba(proba, len(class_names))
    y = _check_labels(y_true, p.shape[0], len(class_names))
    y_pred = p.argmax(axis=1)
    LABELS = list(range(len(class_names)))  # noqa: N806  (the labels 0..K-1 of every call below)
    with _quiet_sklearn():
        prec, rec, f1, _ = precision_recall_fscore_support(y, y_pred, labels=LABELS, zero_division=0)
        mprec, mrec, mf1, _ = precision_recall_fscore_support(
            y, y_pred, labels=LABELS, average="macro", zero_division=0
        )
        roc, ap = _ovr_auc(y, p)
        score = 1.0 - p[:, HEALTHY]
        is_fault = y != HEALTHY
        decision = score > THRESHOLD
        out = {
            "accuracy": float(accuracy_score(y, y_pred)),
            "balanced_accuracy": float(balanced_accuracy_score(y, y_pred)),
            "macro_precision": float(mprec),
            "macro_recall": float(mrec),
            "macro_specificity": macro_specificity(y, y_pred, len(class_names)),
            "macro_f1": float(mf1),
            "weighted_f1": float(f1_score(y, y_pred, labels=LABELS, average="weighted", zero_division=0)),
            "mcc": float(matthews_corrcoef(y, y_pred)),
            "roc_auc_ovr": roc,
            "pr_auc_ovr": ap,
            "brier": float(brier_score_loss(y, p, labels=LABELS)),
            "any_fault_f1": float(f1_score(is_fault, decision, zero_division=0)),
            "any_fault_roc_auc": (
                float(roc_auc_score(is_fault, score)) if 0 < is_fault.sum() < len(y) else math.nan
            ),
        }
    out["per_class"] = {
        name: {"precision": float(prec[k]), "recall": float(rec[k]), "f1": float(f1[k])}
        for k, name in enumerate(class_names)
    }
    return out


# ----------------------------------------------------------------------------- detection


def detection_metrics(
    proba: Any,
    traj: Any,
    t_end: Any,
    traj_fault_class: Mapping[int, int] | Sequence[int] | np.ndarray,
    traj_detectable_s: Mapping[int, float] | Sequence[float] | np.ndarray,
) -> dict:
    """Trajectory-level ``mean_detection_delay_s``, ``missed_faults``, ``false_alarm_rate``.

    ``traj_fault_class[i]`` / ``traj_detectable_s[i]`` give the fault class (0 = Healthy) and the
    detectable time (s; NaN for healthy) of trajectory ``i`` -- a dict or an array indexed by the
    values of ``traj``. Only the trajectories that occur in ``traj`` are evaluated. See the module
    docstring for the definitions.
    """
    p = _check_proba(proba)
    n = p.shape[0]
    tr = np.asarray(traj)
    te = np.asarray(t_end, dtype=np.float64)
    if tr.shape != (n,) or te.shape != (n,):
        raise ValueError(f"traj and t_end must have shape ({n},), found {tr.shape} and {te.shape}")
    if tr.dtype.kind not in "iu":
        raise ValueError(f"traj must hold integer trajectory indices, found dtype {tr.dtype}")
    if not np.all(np.isfinite(te)):
        raise ValueError("t_end contains NaN or inf")
    decision = 1.0 - p[:, HEALTHY] > THRESHOLD

    delays: list[float] = []
    missed = 0
    n_healthy = 0
    n_alarmed = 0
    for i in np.unique(tr):
        i = int(i)
        try:
            cls = int(traj_fault_class[i])
            t_det = float(traj_detectable_s[i])
        except (KeyError, IndexError) as e:
            raise ValueError(f"trajectory {i} has no fault class / detectable time in the per-trajectory data") from e
        mine = tr == i
        if cls == HEALTHY:
            n_healthy += 1
            n_alarmed += bool(decision[mine].any())
            continue
        if not 0 <= cls < p.shape[1]:  # a label, and not Healthy (handled above)
            raise ValueError(f"trajectory {i} has fault class {cls}, expected 0..{p.shape[1] - 1}")
        if not math.isfinite(t_det):
            raise ValueError(f"fault trajectory {i} (class {cls}) has no finite detectable time: {t_det}")
        times = te[mine]
        hits = decision[mine] & (times >= t_det - T_TOL_S)
        if hits.any():
            delays.append(max(0.0, float(times[hits].min()) - t_det))
        else:
            missed += 1
    return {
        "mean_detection_delay_s": float(np.mean(delays)) if delays else math.nan,
        "missed_faults": int(missed),
        "false_alarm_rate": n_alarmed / n_healthy if n_healthy else math.nan,
    }


def compute_metrics(
    y_true: Any,
    proba: Any,
    traj: Any,
    t_end: Any,
    fault_class_by_traj: Any,
    detectable_s_by_traj: Any,
    class_names: Sequence[str] = CLASS_NAMES,
) -> dict:
    """All metrics of the ``metrics.json`` contract, keys in ``METRIC_KEYS`` order.

    ``fault_class_by_traj`` and ``detectable_s_by_traj`` are the dataset's per-trajectory arrays
    (length n_traj_total), indexed by ``traj``.
    """
    cls = classification_metrics(y_true, proba, class_names)
    det = detection_metrics(proba, traj, t_end, fault_class_by_traj, detectable_s_by_traj)
    merged = {**cls, **det}
    return {k: merged[k] for k in METRIC_KEYS}


# ----------------------------------------------------------------------------- seeds, JSON


def _num(v: Any) -> float:
    return math.nan if v is None else float(v)


def summarize_seeds(metric_dicts: Sequence[Mapping]) -> dict:
    """Per-seed metric dicts -> one dict of the same keys, each the list of values over the seeds.

    ``per_class`` is nested the same way: class name -> metric -> list. Used for ``seeds.json``.
    """
    if not metric_dicts:
        raise ValueError("summarize_seeds needs at least one metric dict")
    out: dict = {}
    for k in metric_dicts[0]:
        if k == "per_class":
            out[k] = {
                name: {m: [d[k][name][m] for d in metric_dicts] for m in metric_dicts[0][k][name]}
                for name in metric_dicts[0][k]
            }
        else:
            out[k] = [d[k] for d in metric_dicts]
    return out


def _mean_std(values: Sequence, ddof: int) -> dict:
    x = np.array([_num(v) for v in values], dtype=np.float64)
    x = x[np.isfinite(x)]
    mean = float(x.mean()) if len(x) else math.nan
    std = float(x.std(ddof=ddof)) if len(x) > ddof else math.nan
    return {"mean": mean, "std": std, "n": int(len(x))}


def mean_std(summary: Mapping | Sequence[Mapping], ddof: int = 1) -> dict:
    """Mean and standard deviation over seeds for the results table.

    Takes the output of ``summarize_seeds`` (or the list of per-seed dicts) and returns the same
    keys, each ``{"mean", "std", "n"}`` (``per_class`` nested). Undefined values (NaN or None,
    e.g. a seed with no detected fault has no mean delay) are left out and ``n`` counts the values
    used; ``std`` is the sample standard deviation (``ddof=1`` by default), NaN with fewer than
    ddof + 1 values.
    """
    if not isinstance(summary, Mapping):
        summary = summarize_seeds(list(summary))
    out: dict = {}
    for k, v in summary.items():
        if k == "per_class":
            out[k] = {name: {m: _mean_std(vals, ddof) for m, vals in d.items()} for name, d in v.items()}
        else:
            out[k] = _mean_std(v, ddof)
    return out
