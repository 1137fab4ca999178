"""The evaluation's pieces on hand-built flights: delays, early and pre-onset alarms, class and motor,
false alarms and exposure; the ceiling's ambiguous windows; Garwood; the bootstrap's pairing."""

from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from quadfdi.evaluate.bootstrap import draw_weights, intervals, paired, point_and_replicates
from quadfdi.evaluate.ceiling import expected_confusion
from quadfdi.evaluate.load import DatasetInfo, Flights
from quadfdi.evaluate.metrics import garwood, macro_f1_accuracy
from quadfdi.evaluate.outcomes import flight_outcomes

CLASSES = ("Healthy", "BatteryFault", "MotorFault")
STRIDE = 1.0  # s between window ends
POLICY = {"threshold": 0.5, "k": 2, "n": 3, "clear_m": 2, "latch": False}


def _flights(p_fault, fault_cls, motor=None):
    """Two-or-more flights, 10 windows ending at 1..10 s; p_fault (F, 10); fault mass on column fault_cls (F,)."""
    p_fault = np.asarray(p_fault, float)
    f, w = p_fault.shape
    proba = np.zeros((f, w, 3))
    proba[:, :, 0] = 1 - p_fault
    for i, c in enumerate(fault_cls):
        proba[i, :, max(c, 1)] = p_fault[i]
    t = np.tile(np.arange(1.0, w + 1), (f, 1))
    return Flights("m", 0, 0, "d.npz", CLASSES, np.arange(f), proba, motor, np.zeros((f, w), np.int64), t,
                   np.ones((f, w), bool), np.full(f, 2), STRIDE)


def _info(fault_class, onset, detectable, motor, severity=None, time=None):
    f = len(fault_class)
    time = np.arange(0.0, 11.0, 0.5) if time is None else time
    sev = np.zeros((f, time.size)) if severity is None else severity
    return DatasetInfo(Path("d.npz"), {"fault_class": np.array(fault_class, np.int8), "onset_s": np.array(onset, float),
                                       "detectable_s": np.array(detectable, float),
                                       "fault_motor": np.array(motor, np.int8), "split": np.full(f, 2, np.int8),
                                       "severity": sev, "time": time, "severity_threshold": np.array(0.2)},
                       ("train", "validation", "test"))


def test_healthy_flight_false_alarms_and_exposure():
    fl = _flights([[0, .9, .9, 0, 0, 0, .9, .9, 0, 0]], [0])
    out = flight_outcomes(fl, _info([0], [np.nan], [np.nan], [-1]), POLICY)
    assert out["fa"][0] == 2 and out["healthy"][0] == 1 and out["fault"][0] == 0
    assert out["exposure_h"][0] == pytest.approx(10 * STRIDE / 3600)
    assert out["detected"][0] == 0


def test_fault_flight_delays_class_and_motor():
    # Motor fault, onset 3.5 s, threshold crossed at 5.5 s: votes from window 5 (t=6) -> raise at t=7.
    p = [[0, 0, 0, 0, 0, .9, .9, .9, .9, .9]]
    motor = np.zeros((1, 10, 4))
    motor[0, :, 3] = 1.0
    fl = _flights(p, [2], motor)
    out = flight_outcomes(fl, _info([2], [3.5], [5.5], [3]), POLICY)
    assert out["detected"][0] == 1 and out["delay_onset"][0] == pytest.approx(7 - 3.5)
    assert out["delay_thr"][0] == pytest.approx(7 - 5.5)
    assert out["early"][0] == 0 and out["pre_onset"][0] == 0
    assert out["class_ok"][0] == 1 and out["motor_n"][0] == 1 and out["motor_ok"][0] == 1
    # The same alarm, but the flight is a battery fault: the class is wrong; no motor is scored.
    out = flight_outcomes(fl, _info([1], [3.5], [5.5], [-1]), POLICY)
    assert out["class_ok"][0] == 0 and out["motor_n"][0] == 0


def test_early_and_pre_onset_alarms_and_a_held_alarm_detects():
    # Alarm raised at t=2 (votes at 1, 2) and never cleared: onset 4.5, threshold 8.5.
    fl = _flights([[.9, .9, .9, .9, .9, .9, .9, .9, .9, .9]], [1])
    out = flight_outcomes(fl, _info([1], [4.5], [8.5], [-1]), POLICY)
    assert out["pre_onset"][0] == 1 and out["early"][0] == 1
    assert out["detected"][0] == 1 and out["delay_onset"][0] == pytest.approx(5 - 4.5)
    assert out["delay_thr"][0] == pytest.approx(9 - 8.5)
    # Never crossing the threshold (incipient): not a threshold flight, no early count, still detectable.
    out = flight_outcomes(fl, _info([1], [4.5], [np.nan], [-1]), POLICY)
    assert out["thr"][0] == 0 and out["early"][0] == 0 and out["detected"][0] == 1
    # Cleared before onset and never raised again: missed.
    fl = _flights([[.9, .9, 0, 0, 0, 0, 0, 0, 0, 0]], [1])
    out = flight_outcomes(fl, _info([1], [4.5], [8.5], [-1]), POLICY)
    assert out["detected"][0] == 0 and out["pre_onset"][0] == 1


def test_ceiling_marks_windows_within_one_stride_of_the_crossing():
    time = np.arange(0.0, 11.0, 0.5)  # stride 1 s = 2 samples
    sev = np.where(time >= 5.0, 0.5, 0.0)[None, :]  # crossing at 5.0 s
    fl = _flights([[0.0] * 10], [1])
    conf, amb = expected_confusion(fl, _info([1], [4.0], [5.0], [-1], sev, time))
    # Window ends 1..10 s: labels flip between 4 and 5; ends 4 (5 would be fault) and 5 (4 would be healthy) are ambiguous.
    assert amb[0] == 2
    assert conf[0, 0, 0] == 3.5 and conf[0, 0, 1] == 0.5 and conf[0, 1, 1] == 5.5 and conf[0, 1, 0] == 0.5
    f1, acc = macro_f1_accuracy(conf.sum(0))
    assert acc == pytest.approx(0.9) and f1 < 1


def test_garwood_matches_the_chi2_formula():
    lo, hi = garwood(0, 2.0)
    assert lo == 0 and hi == pytest.approx(chi2.ppf(0.975, 2) / 2 / 2.0)  # 3.689 / 2 h
    lo, hi = garwood(10, 1.0)
    assert (lo, hi) == pytest.approx((4.7954, 18.3904), abs=1e-3)


def test_paired_bootstrap_cancels_shared_flight_variation():
    rng = np.random.default_rng(1)
    f = 200
    units = [("d", i) for i in range(f)]
    w = draw_weights(units, 1000, 0)
    assert w.shape == (1000, f) and np.all(w.sum(1) == f)
    assert np.array_equal(w, draw_weights(units, 1000, 0))
    # Flight difficulty varies a lot; model b is model a plus one extra correct window on every flight.
    hard = rng.integers(0, 10, f)
    conf_a = np.zeros((f, 2, 2))
    conf_a[:, 0, 0], conf_a[:, 0, 1], conf_a[:, 1, 1] = 10 - hard, hard, 10
    conf_b = conf_a.copy()
    conf_b[:, 0, 0] += np.minimum(1, hard)
    conf_b[:, 0, 1] -= np.minimum(1, hard)
    zeros = {k: np.zeros(f) for k in ("fa", "exposure_h", "detected", "fault", "delay_onset", "delay_thr",
                                       "detected_thr", "early", "thr", "class_ok", "motor_ok", "motor_n")}
    sa, sb = dict(zeros, conf=conf_a), dict(zeros, conf=conf_b)
    d = paired(point_and_replicates(sb, w), point_and_replicates(sa, w), 0.95, ("accuracy",))["accuracy"]
    single = intervals(sa, w, 0.95)["accuracy"]
    assert d["diff"] > 0 and d["lo"] > 0  # the difference is resolved ...
    assert d["hi"] - d["lo"] < 0.5 * (single["hi"] - single["lo"])  # ... far tighter than either model's interval


def test_undecided_windows_never_vote_and_leave_the_exposure():
    """A prediction set's ``decided`` (before the hover freeze: False) as detect treats it."""
    from dataclasses import replace

    from quadfdi.evaluate.alarms import flight_alarms

    fl = _flights([[.9, .9, .9, 0, 0, 0, 0, 0, 0, 0]], [0])
    info = _info([0], [np.nan], [np.nan], [-1])
    assert flight_outcomes(fl, info, POLICY)["fa"][0] == 1
    assert flight_alarms(fl, POLICY, 0)[0]["start_s"] == 2.0
    pre = replace(fl, decided=np.arange(10)[None, :] >= 2)  # the first two windows undecided
    out = flight_outcomes(pre, info, POLICY)
    assert out["fa"][0] == 0 and out["exposure_h"][0] == pytest.approx(8 * STRIDE / 3600)  # 1 vote of 3: no raise
    assert flight_alarms(pre, POLICY, 0) == []


def test_a_battery_alarm_on_a_rotor_fault_names_no_motor():
    motor = np.zeros((1, 10, 4))
    motor[0, :, 3] = 1.0
    fl = _flights([[0, 0, 0, 0, 0, .9, .9, .9, .9, .9]], [1], motor)  # the model says BatteryFault
    out = flight_outcomes(fl, _info([2], [3.5], [5.5], [3]), POLICY)
    assert out["motor_n"][0] == 1 and out["motor_ok"][0] == 0  # core.alarm rule 5: no motor, counted wrong
