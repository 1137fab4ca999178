"""train.metrics: equal to scikit-learn where it defines the metric; hand-made detection cases."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
from sklearn import metrics as skm  # the independent reference every metric is checked against

from quadfdi.core.contracts import CLASS_LABELS, CLASS_NAMES
from quadfdi.core.jsonio import to_jsonable
from quadfdi.train.metrics import (
    METRIC_KEYS,
    classification_metrics,
    compute_metrics,
    detection_metrics,
    macro_specificity,
    mean_std,
    summarize_seeds,
)

LABELS = list(CLASS_LABELS)

# the scikit-learn reference calls below warn on the degenerate cases; train.metrics does not
pytestmark = pytest.mark.filterwarnings("ignore:y_pred contains classes not in y_true:UserWarning")


def as_f64(p):
    """The float64 probabilities the metrics see (float32 rows renormalised to sum to 1)."""
    pd = np.asarray(p, dtype=np.float64)
    return pd / pd.sum(axis=1, keepdims=True)


def random_case(seed: int, n: int = 300, classes=(0, 1, 2, 3)):
    rng = np.random.default_rng(seed)
    y = rng.choice(np.asarray(classes), size=n)
    logits = rng.normal(size=(n, 4)).astype(np.float32)
    logits[np.arange(n), y] += rng.uniform(0.0, 2.5, size=n).astype(np.float32)  # informative, imperfect
    p = np.exp(logits - logits.max(axis=1, keepdims=True))
    p = (p / p.sum(axis=1, keepdims=True)).astype(np.float32)
    return y, p


def hand_specificity(y, y_pred):
    cm = skm.confusion_matrix(y, y_pred, labels=LABELS)
    vals = []
    for k in LABELS:
        tp = cm[k, k]
        fn = cm[k, :].sum() - tp
        fp = cm[:, k].sum() - tp
        tn = cm.sum() - tp - fn - fp
        if tn + fp > 0:
            vals.append(tn / (tn + fp))
    return float(np.mean(vals)) if vals else math.nan


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_classification_equals_sklearn_all_classes(seed):
    y, p = random_case(seed)
    m = classification_metrics(y, p)
    pd = as_f64(p)
    yp = pd.argmax(axis=1)
    prec, rec, f1, _ = skm.precision_recall_fscore_support(y, yp, labels=LABELS, zero_division=0)
    assert m["accuracy"] == pytest.approx(skm.accuracy_score(y, yp), abs=1e-12)
    assert m["balanced_accuracy"] == pytest.approx(skm.balanced_accuracy_score(y, yp), abs=1e-12)
    assert m["macro_precision"] == pytest.approx(prec.mean(), abs=1e-12)
    assert m["macro_recall"] == pytest.approx(rec.mean(), abs=1e-12)
    assert m["macro_f1"] == pytest.approx(skm.f1_score(y, yp, average="macro"), abs=1e-12)
    assert m["weighted_f1"] == pytest.approx(skm.f1_score(y, yp, average="weighted"), abs=1e-12)
    assert m["mcc"] == pytest.approx(skm.matthews_corrcoef(y, yp), abs=1e-12)
    assert m["macro_specificity"] == pytest.approx(hand_specificity(y, yp), abs=1e-12)
    # the one-call multiclass forms of scikit-learn
    assert m["roc_auc_ovr"] == pytest.approx(skm.roc_auc_score(y, pd, multi_class="ovr", average="macro"), abs=1e-12)
    assert m["pr_auc_ovr"] == pytest.approx(skm.average_precision_score(y, pd, average="macro"), abs=1e-12)
    assert m["brier"] == pytest.approx(skm.brier_score_loss(y, pd, labels=LABELS), abs=1e-12)
    score = 1.0 - pd[:, 0]
    assert m["any_fault_f1"] == pytest.approx(skm.f1_score(y != 0, score > 0.5), abs=1e-12)
    assert m["any_fault_roc_auc"] == pytest.approx(skm.roc_auc_score(y != 0, score), abs=1e-12)
    for k, name in enumerate(CLASS_NAMES):
        assert m["per_class"][name] == pytest.approx({"precision": prec[k], "recall": rec[k], "f1": f1[k]}, abs=1e-12)
    assert all(math.isfinite(v) for k, v in m.items() if k != "per_class")


def test_brier_is_sum_of_per_class_eq13():
    """brier = sklearn multiclass Brier = sum over classes of Eq. 13's Brier_k (one-vs-rest)."""
    for seed in range(3):
        y, p = random_case(seed)
        pd = as_f64(p)
        per_class = [skm.brier_score_loss(y == k, pd[:, k]) for k in LABELS]
        by_hand = np.mean(np.sum((pd - np.eye(4)[y]) ** 2, axis=1))
        m = classification_metrics(y, p)
        assert m["brier"] == pytest.approx(sum(per_class), abs=1e-12)
        assert m["brier"] == pytest.approx(by_hand, abs=1e-12)
    # perfect and uniform predictions
    y = np.array([0, 1, 2, 3])
    assert classification_metrics(y, np.eye(4))["brier"] == 0.0
    assert classification_metrics(y, np.full((4, 4), 0.25))["brier"] == pytest.approx(0.75)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("absent", [0, 2])
def test_class_absent_from_y_true(seed, absent):
    classes = tuple(c for c in LABELS if c != absent)
    y, p = random_case(seed, classes=classes)
    m = classification_metrics(y, p)
    pd = as_f64(p)
    yp = pd.argmax(axis=1)
    assert (yp == absent).any()  # the absent class is still predicted sometimes
    present = list(classes)
    roc = np.mean([skm.roc_auc_score(y == k, pd[:, k]) for k in present])
    ap = np.mean([skm.average_precision_score(y == k, pd[:, k]) for k in present])
    assert m["roc_auc_ovr"] == pytest.approx(roc, abs=1e-12)
    assert m["pr_auc_ovr"] == pytest.approx(ap, abs=1e-12)
    prec, rec, f1, _ = skm.precision_recall_fscore_support(y, yp, labels=LABELS, zero_division=0)
    assert m["macro_recall"] == pytest.approx(rec.mean(), abs=1e-12)
    assert m["per_class"][CLASS_NAMES[absent]]["recall"] == 0.0
    assert m["macro_f1"] == pytest.approx(f1.mean(), abs=1e-12)
    assert m["balanced_accuracy"] == pytest.approx(skm.balanced_accuracy_score(y, yp), abs=1e-12)
    assert m["mcc"] == pytest.approx(skm.matthews_corrcoef(y, yp), abs=1e-12)
    assert m["macro_specificity"] == pytest.approx(hand_specificity(y, yp), abs=1e-12)
    assert m["brier"] == pytest.approx(skm.brier_score_loss(y, pd, labels=LABELS), abs=1e-12)
    if absent == 0:  # all windows faulty: any-fault ROC-AUC undefined, any-fault F1 defined
        assert math.isnan(m["any_fault_roc_auc"])
        assert m["any_fault_f1"] == pytest.approx(skm.f1_score(y != 0, 1 - pd[:, 0] > 0.5), abs=1e-12)
    else:
        assert m["any_fault_roc_auc"] == pytest.approx(skm.roc_auc_score(y != 0, 1 - pd[:, 0]), abs=1e-12)
    assert all(math.isfinite(v) for k, v in m.items() if k not in ("per_class", "any_fault_roc_auc"))


@pytest.mark.parametrize("only", [0, 1, 3])
def test_single_class_y_true(only):
    _, p = random_case(7, n=50)
    y = np.full(50, only)
    m = classification_metrics(y, p)
    pd = as_f64(p)
    yp = pd.argmax(axis=1)
    # undefined: no class has both positives and negatives; any-fault has a single class
    assert math.isnan(m["roc_auc_ovr"]) and math.isnan(m["pr_auc_ovr"])
    assert math.isnan(m["any_fault_roc_auc"])
    # defined: finite and equal to scikit-learn
    assert m["accuracy"] == pytest.approx(skm.accuracy_score(y, yp))
    assert m["balanced_accuracy"] == pytest.approx(skm.balanced_accuracy_score(y, yp))
    assert m["mcc"] == pytest.approx(skm.matthews_corrcoef(y, yp))
    assert m["brier"] == pytest.approx(skm.brier_score_loss(y, pd, labels=LABELS))
    assert m["macro_f1"] == pytest.approx(skm.f1_score(y, yp, labels=LABELS, average="macro", zero_division=0))
    assert m["any_fault_f1"] == pytest.approx(skm.f1_score(y != 0, 1 - pd[:, 0] > 0.5, zero_division=0))
    assert m["macro_specificity"] == pytest.approx(hand_specificity(y, yp))
    assert math.isfinite(m["macro_specificity"])
    json.dumps(to_jsonable(m), allow_nan=False)


def test_degenerate_cases_raise_no_warning():
    _, p = random_case(3, n=40)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        classification_metrics(np.zeros(40, dtype=int), p)
        classification_metrics(np.full(40, 2), p)
        classification_metrics(np.arange(40) % 2 + 1, p.astype(np.float32))


def test_macro_specificity_by_hand():
    # confusion matrix (rows true, cols predicted):
    #   H: 3 0 1 0 | B: 1 2 0 0 | M: 0 0 2 0 | O: 0 1 0 0
    y = np.array([0, 0, 0, 0, 1, 1, 1, 2, 2, 3])
    yp = np.array([0, 0, 0, 2, 0, 1, 1, 2, 2, 1])
    # H: neg=6, FP=1 -> 5/6; B: neg=7, FP=1 -> 6/7; M: neg=8, FP=1 -> 7/8; O: neg=9, FP=0 -> 1
    expected = (5 / 6 + 6 / 7 + 7 / 8 + 1.0) / 4
    assert macro_specificity(y, yp) == pytest.approx(expected, abs=1e-15)
    p = np.eye(4)[yp]
    assert classification_metrics(y, p)["macro_specificity"] == pytest.approx(expected, abs=1e-15)
    # a class with no negatives is skipped (0/0), the rest averaged
    y1 = np.zeros(4, dtype=int)
    yp1 = np.array([0, 0, 1, 2])
    assert macro_specificity(y1, yp1) == pytest.approx((3 / 4 + 3 / 4 + 1.0) / 3)


def test_any_fault_uses_sum_of_fault_probabilities():
    # argmax Healthy (0.4) but 1 - p(H) = 0.6 > 0.5: any-fault decision positive
    p = np.array([[0.4, 0.2, 0.2, 0.2], [0.6, 0.4, 0.0, 0.0], [0.5, 0.5, 0.0, 0.0]])
    y = np.array([1, 0, 0])
    m = classification_metrics(y, p)
    assert m["any_fault_f1"] == pytest.approx(1.0)  # 0.5 exactly is not > 0.5
    assert m["any_fault_roc_auc"] == pytest.approx(1.0)


def test_bad_inputs_raise():
    y, p = random_case(0, n=10)
    with pytest.raises(ValueError, match="shape"):
        classification_metrics(y, p[:, :3])
    with pytest.raises(ValueError, match="sum to 1"):
        classification_metrics(y, p * 0.5)
    with pytest.raises(ValueError, match="labels"):
        classification_metrics(y + 4, p)


# ----------------------------------------------------------------------------- detection


def det_case():
    """Hand-made windows of six trajectories (dataset indices 10..15), t_det for faults."""
    fault_class = {10: 1, 11: 2, 12: 3, 13: 0, 14: 0, 15: 0}
    t_det = {10: 5.0, 11: 6.0, 12: 4.4, 13: math.nan, 14: math.nan, 15: math.nan}
    times = np.array([3.6, 4.0, 4.4, 4.8, 5.2, 5.6, 6.0, 6.4, 6.8])
    alarms = {
        10: [1, 1, 0, 0, 0, 0, 1, 1, 1],  # alarms before t_det ignored; first at/after 5.0 -> 6.0: delay 1.0
        11: [1, 1, 1, 1, 1, 1, 0, 0, 0],  # alarms only before t_det=6.0 -> missed
        12: [0, 0, 1, 1, 1, 1, 1, 1, 1],  # detected at exactly t_det -> delay 0
        13: [0, 0, 0, 0, 0, 0, 0, 0, 0],  # healthy, quiet
        14: [0, 0, 0, 0, 1, 0, 0, 0, 0],  # healthy, one false alarm
        15: [0, 0, 0, 0, 0, 0, 0, 0, 0],  # healthy, quiet
    }
    traj, t_end, proba = [], [], []
    for i, a in alarms.items():
        for t, on in zip(times, a):
            traj.append(i)
            t_end.append(t)
            proba.append([0.1, 0.9, 0.0, 0.0] if on else [0.9, 0.0, 0.05, 0.05])
    return np.array(proba), np.array(traj), np.array(t_end), fault_class, t_det


def test_detection_hand_cases():
    proba, traj, t_end, fc, td = det_case()
    d = detection_metrics(proba, traj, t_end, fc, td)
    assert d["missed_faults"] == 1
    assert isinstance(d["missed_faults"], int)
    assert d["mean_detection_delay_s"] == pytest.approx((1.0 + 0.0) / 2)
    assert d["false_alarm_rate"] == pytest.approx(1 / 3)


def test_detection_with_arrays_shuffled_and_float_rounding():
    proba, traj, t_end, fc, td = det_case()
    # per-trajectory arrays of the whole dataset (n_traj_total = 16)
    fc_arr = np.zeros(16, dtype=int)
    td_arr = np.full(16, np.nan)
    for i in fc:
        fc_arr[i] = fc[i]
        td_arr[i] = td[i]
    td_arr[12] = 4.4 + 1e-12  # t_det computed another way than t_end: still "at t_det"
    order = np.random.default_rng(0).permutation(len(traj))
    d = detection_metrics(proba[order], traj[order], t_end[order], fc_arr, td_arr)
    assert d["missed_faults"] == 1
    assert d["mean_detection_delay_s"] == pytest.approx(0.5)
    assert d["false_alarm_rate"] == pytest.approx(1 / 3)


def test_always_alarm_and_never_alarm():
    proba, traj, t_end, fc, td = det_case()
    always = np.tile([0.0, 0.0, 1.0, 0.0], (len(traj), 1))
    d = detection_metrics(always, traj, t_end, fc, td)
    assert d["false_alarm_rate"] == 1.0
    assert d["missed_faults"] == 0
    # first window at/after t_det: 10 -> 5.2 (0.2), 11 -> 6.0 (0), 12 -> 4.4 (0)
    assert d["mean_detection_delay_s"] == pytest.approx(0.2 / 3)
    never = np.tile([1.0, 0.0, 0.0, 0.0], (len(traj), 1))
    d = detection_metrics(never, traj, t_end, fc, td)
    assert d["false_alarm_rate"] == 0.0
    assert d["missed_faults"] == 3
    assert math.isnan(d["mean_detection_delay_s"])


def test_detection_no_healthy_or_no_fault_trajectory():
    proba, traj, t_end, fc, td = det_case()
    faults = np.isin(traj, [10, 11, 12])
    d = detection_metrics(proba[faults], traj[faults], t_end[faults], fc, td)
    assert math.isnan(d["false_alarm_rate"])
    d = detection_metrics(proba[~faults], traj[~faults], t_end[~faults], fc, td)
    assert d["missed_faults"] == 0 and math.isnan(d["mean_detection_delay_s"])


def test_fault_trajectory_without_detectable_time_raises():
    proba, traj, t_end, fc, td = det_case()
    td = dict(td)
    td[10] = math.nan
    with pytest.raises(ValueError, match="detectable"):
        detection_metrics(proba, traj, t_end, fc, td)


# ----------------------------------------------------------------------------- contract, JSON, seeds


def full_case():
    proba, traj, t_end, fc, td = det_case()
    fc_arr = np.array([fc.get(i, 0) for i in range(16)])
    td_arr = np.array([td.get(i, math.nan) for i in range(16)])
    # window labels as the dataset assigns them: Healthy before t_det
    y = np.array([fc_arr[i] if t >= td_arr[i] else 0 for i, t in zip(traj, t_end)])
    return y, proba, traj, t_end, fc_arr, td_arr


def test_compute_metrics_keys_and_strict_json():
    y, proba, traj, t_end, fc, td = full_case()
    m = compute_metrics(y, proba, traj, t_end, fc, td)
    assert tuple(m) == METRIC_KEYS
    assert set(m) == {
        "accuracy", "balanced_accuracy", "macro_precision", "macro_recall", "macro_specificity",
        "macro_f1", "weighted_f1", "mcc", "roc_auc_ovr", "pr_auc_ovr", "brier", "any_fault_f1",
        "any_fault_roc_auc", "mean_detection_delay_s", "missed_faults", "false_alarm_rate", "per_class",
    }  # fmt: skip
    assert set(m["per_class"]) == set(CLASS_NAMES)
    assert all(set(v) == {"precision", "recall", "f1"} for v in m["per_class"].values())
    # a single-class case has NaNs: they must serialise as null in strict JSON
    m1 = compute_metrics(np.zeros_like(y), proba, traj, t_end, fc, td)
    assert math.isnan(m1["roc_auc_ovr"])
    text = json.dumps(to_jsonable(m1), allow_nan=False)
    back = json.loads(text)
    assert back["roc_auc_ovr"] is None and back["any_fault_roc_auc"] is None
    assert back["missed_faults"] == m1["missed_faults"]
    with pytest.raises(ValueError):
        json.dumps(m1, allow_nan=False)  # the raw dict is not strict JSON


def test_to_jsonable_types():
    obj = {
        "a": np.float32(0.5), "b": np.int64(3), "c": np.array([1.0, np.nan, np.inf]),
        "d": (np.bool_(True), None, "x"), 4: float("-inf"),
    }  # fmt: skip
    out = to_jsonable(obj)
    assert out == {"a": 0.5, "b": 3, "c": [1.0, None, None], "d": [True, None, "x"], "4": None}
    json.dumps(out, allow_nan=False)


def test_summarize_seeds_and_mean_std():
    y, proba, traj, t_end, fc, td = full_case()
    runs = []
    for s in range(3):
        rng = np.random.default_rng(s)
        p = 0.7 * proba + 0.3 * rng.dirichlet(np.ones(4), size=len(y))
        runs.append(compute_metrics(y, p, traj, t_end, fc, td))
    summary = summarize_seeds(runs)
    assert tuple(summary) == METRIC_KEYS
    assert summary["accuracy"] == [r["accuracy"] for r in runs]
    assert summary["per_class"]["MotorFault"]["f1"] == [r["per_class"]["MotorFault"]["f1"] for r in runs]
    json.dumps(to_jsonable(summary), allow_nan=False)
    ms = mean_std(summary)
    acc = np.array(summary["accuracy"])
    assert ms["accuracy"]["mean"] == pytest.approx(acc.mean())
    assert ms["accuracy"]["std"] == pytest.approx(acc.std(ddof=1))
    assert ms["accuracy"]["n"] == 3
    assert mean_std(runs)["macro_f1"] == ms["macro_f1"]
    assert ms["per_class"]["Healthy"]["recall"]["mean"] == pytest.approx(
        np.mean(summary["per_class"]["Healthy"]["recall"])
    )
    # undefined values (NaN, or None after a JSON round trip) are left out
    loaded = json.loads(json.dumps(to_jsonable({"x": [1.0, float("nan"), 3.0]})))
    assert mean_std(loaded)["x"] == {"mean": 2.0, "std": pytest.approx(math.sqrt(2.0)), "n": 2}
