"""The alarm policy (core.alarm) on hand-built vote sequences: raise, clear, latch, class, motor."""

import numpy as np
import pytest

from quadfdi.core.alarm import AlarmConfig, run_alarm
from quadfdi.core.config import load_config
from quadfdi.core.errors import QuadfdiError


def _proba(p_fault, fault_cls=None, k=5):
    """(1, W, K) probabilities with p(Healthy) = 1 - p_fault, the fault mass on ``fault_cls`` (per window)."""
    p_fault = np.asarray(p_fault, float)
    fault_cls = np.full(p_fault.shape, 1) if fault_cls is None else np.asarray(fault_cls)
    out = np.zeros((1, p_fault.size, k))
    out[0, :, 0] = 1 - p_fault
    out[0, np.arange(p_fault.size), fault_cls] = p_fault
    return out


def _bits(a):
    return "".join("1" if x else "0" for x in np.asarray(a).reshape(-1))


def test_k_of_n_raise_and_m_clear():
    v = [0, 1, 0, 1, 1, 1, 0, 0, 1, 0, 0, 0, 1]
    tr = run_alarm(_proba(np.array(v) * 0.9), threshold=0.5, k=2, n=3, clear_m=3)
    assert _bits(tr.votes) == "0101110010001"
    # window 3: votes at 1 and 3 among 1..3 -> 2 of 3 -> raise; non-votes 6, 7 (run 2), vote 8 resets,
    # 9, 10, 11 -> run reaches 3 at 11: cleared there; window 12 votes but only 1 of 10..12 -> no raise.
    assert _bits(tr.raised) == "0001000000000"
    assert _bits(tr.cleared) == "0000000000010"
    assert _bits(tr.active) == "0001111111100"


def test_threshold_is_inclusive_and_latch_never_clears():
    p = np.array([0.7, 0.69999, 0.7, 0.0, 0.0, 0.0, 0.0])
    tr = run_alarm(_proba(p), threshold=0.7, k=1, n=1, clear_m=2)
    assert _bits(tr.votes) == "1010000"
    assert _bits(tr.active) == "1111000"  # cleared at window 4 (two non-votes: 3, 4)
    assert _bits(run_alarm(_proba(p), threshold=0.7, k=1, n=1, clear_m=2, latch=True).active) == "1111111"


def test_reraise_from_the_unreset_buffer_needs_a_voting_window():
    # k=2, n=4, clear_m=1: votes 0,1 raise at 1; non-vote 2 clears; vote 3 has 1,3 in 0..3 -> re-raise at 3.
    tr = run_alarm(_proba(np.array([1, 1, 0, 1, 0, 0]) * 0.9), threshold=0.5, k=2, n=4, clear_m=1)
    assert _bits(tr.raised) == "010100"
    assert _bits(tr.cleared) == "001010"


def test_class_is_argmax_of_summed_voting_probabilities_ties_to_lowest():
    # Voting windows of the episode: class 3 at 0.6, then class 2 at 0.55 twice: 0.6 < 1.1 -> class 2.
    p = np.array([0.6, 0.55, 0.55])
    tr = run_alarm(_proba(p, [3, 2, 2]), threshold=0.5, k=1, n=1, clear_m=5)
    assert list(tr.cls[0]) == [3, 3, 2]
    # The healthy-mass non-voting window between adds nothing: 0.6 vs 0.6 is a tie -> lowest index (2).
    p = np.array([0.6, 0.1, 0.6])
    tr = run_alarm(_proba(p, [3, 1, 2]), threshold=0.5, k=1, n=1, clear_m=5)
    assert list(tr.cls[0]) == [3, 3, 2]
    # At a k-of-n raise, the voting windows inside the buffer count, the non-voting one does not.
    p = np.array([0.9, 0.2, 0.6])
    tr = run_alarm(_proba(p, [4, 1, 2]), threshold=0.5, k=2, n=3, clear_m=5)
    assert list(tr.cls[0]) == [-1, -1, 4]


def test_motor_and_per_row_policies_and_padding():
    proba = np.concatenate([_proba([0.9, 0.9, 0.9, 0.9]), _proba([0.9, 0.9, 0.9, 0.9])])
    motor = np.zeros((2, 4, 4))
    motor[:, :, 2] = 0.6
    motor[:, :, 1] = 0.4
    motor[1, 3] = [0, 1, 0, 0]
    valid = np.array([[1, 1, 1, 1], [1, 1, 1, 0]], bool)
    tr = run_alarm(proba, threshold=np.array([0.5, 0.95]), k=np.array([3, 1]), n=3, clear_m=1, valid=valid,
                   motor_proba=motor)
    assert _bits(tr.raised[0]) == "0010" and not tr.raised[1].any()  # row 1's threshold is above 0.9
    assert list(tr.motor[0]) == [-1, -1, 2, 2]
    tr = run_alarm(proba, threshold=0.5, k=1, n=1, clear_m=1, valid=valid, motor_proba=motor)
    assert list(tr.motor[1]) == [2, 2, 2, 2]  # the padded window (0, 1, 0, 0) is ignored
    assert _bits(tr.votes[1]) == "1110"


def test_config_section_validates():
    assert load_config(None).alarm == AlarmConfig()
    with pytest.raises(QuadfdiError, match="1 <= k <= n"):
        load_config(None, ["alarm.k=4"])
    with pytest.raises(QuadfdiError, match="threshold must be in"):
        load_config(None, ["alarm.threshold=0"])
    with pytest.raises(QuadfdiError, match="evaluate grid"):
        load_config(None, ["evaluate.kn=['5/3']"])
    with pytest.raises(QuadfdiError, match="'k/n'"):
        load_config(None, ["evaluate.kn=['2-3']"])


def test_episodes_start_end_class_and_peak():
    from quadfdi.core.alarm import alarm_episodes

    p = np.array([0, .9, .8, 0, 0, 0, .95, .6, .7])
    proba = _proba(p, [1, 1, 2, 1, 1, 1, 2, 2, 2])
    tr = run_alarm(proba, threshold=0.5, k=2, n=2, clear_m=2)
    t = np.arange(1.0, 10.0)[None, :]
    eps = alarm_episodes(tr, t, proba)
    # Raised at window 2 (t=3), cleared at window 4 (t=5); raised again at 7 (t=8), active at the end.
    assert [(e["start_s"], e["end_s"]) for e in eps] == [(3.0, 5.0), (8.0, None)]
    assert eps[0]["cls"] == 1 and eps[0]["peak_p_fault"] == pytest.approx(0.8)  # 0.9 (cls 1) > 0.8 (cls 2)
    assert eps[1]["cls"] == 2 and eps[1]["peak_p_fault"] == pytest.approx(0.7) and eps[1]["motor"] == -1


def test_reach_says_exactly_when_a_certain_fault_can_raise():
    """core.alarm.reach against the policy itself: with every decided window voting p_fault = 1, the
    policy raises somewhere iff reach calls the flight possible (random masks, k, n)."""
    from quadfdi.core.alarm import reach

    rng = np.random.default_rng(7)
    seen = set()
    for _ in range(400):
        w, n = int(rng.integers(1, 30)), int(rng.integers(1, 13))
        k = int(rng.integers(1, n + 1))
        valid = rng.random(w) < rng.uniform(0.2, 0.9)
        tr = run_alarm(_proba(np.ones(w)), threshold=0.99, k=k, n=n, clear_m=3, valid=valid[None])
        r = reach(valid, k, n, window=120, stride=20, dt=0.04)
        assert r["possible"] == bool(tr.raised.any()), (valid, k, n, r)
        seen.add(r["possible"])
    assert seen == {True, False}  # both outcomes drawn
    assert reach(np.ones(5, bool), 2, 3, window=120, stride=20, dt=0.04)["needs_s"] == pytest.approx(5.6)


def test_reach_note_is_one_line_only_when_no_alarm_was_possible():
    from quadfdi.core.alarm import reach, reach_note

    short = reach(np.array([True, False, False, True]), 3, 4, window=120, stride=20, dt=0.04)
    assert reach_note(short) == ("no alarm was possible: the policy needs 3 votes among 4 windows (6.4 s of decided "
                                 "flight in a row) and this flight has at most 2 decided windows among 4")
    assert reach_note(reach(np.ones(4, bool), 3, 4, window=120, stride=20, dt=0.04)) is None
    assert reach_note(None) is None  # a record written before reach was computed
