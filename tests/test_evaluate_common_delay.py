"""The delay from onset on the fault flights both models detect (evaluate.common_delay), on hand-built
prediction sets whose answer is worked out below, through evaluate_sets and evaluation.md's table."""

from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.config import load_config
from quadfdi.evaluate.common_delay import common_delay
from quadfdi.evaluate.load import DatasetInfo, Flights
from quadfdi.evaluate.protocol import evaluate_sets
from quadfdi.evaluate.report import markdown
from tests.conftest import ROOT

CLASSES = ("Healthy", "BatteryFault")
ONSET = 2.5  # s; windows end at 1, 2, ..., 10 s (1 s apart): the first window after onset ends at 3 s
# Per model and train seed: the end time of the first alarmed window of each flight (None: no alarm).
# Flights 0-3 are faults with onset 2.5 s, flight 4 is healthy. Policy: vote p >= 0.5, raise 1 of 1.
FIRST_ALARM = {
    ("a", 0): [4, 3, 10, 3, None],
    ("a", 1): [4, 5, 10, None, None],  # flight 3: seed 1 misses it, so "a" does not detect it (every seed must)
    ("b", 0): [6, 7, None, 3, None],
    ("b", 1): [6, 7, None, 3, None],
}
# By hand: common flights = {0, 1} (2 is b's miss, 3 is a's seed-1 miss).
# a on them: flight 0 delay 4 - 2.5 = 1.5; flight 1 the seed mean of 0.5 and 2.5 = 1.5 -> 1.5.
# b on them: 6 - 2.5 = 3.5 and 7 - 2.5 = 4.5 -> 4.0.  Paired a - b = -2.5 (flight diffs -2 and -3).
# Own detections instead (delay_onset_s): a (1.5 + 1.5 + 7.5 + 0.5 * 0.5) / 3.5 = 3.071, b (3.5 + 4.5 + 0.5) / 3
# = 2.833: "a" looks 0.24 s slower only because it also catches flight 2, late.


def _flights(model: str, seed: int) -> Flights:
    f, w = 5, 10
    t = np.tile(np.arange(1.0, w + 1), (f, 1))
    p = np.zeros((f, w))
    for i, first in enumerate(FIRST_ALARM[(model, seed)]):
        if first is not None:
            p[i, t[i] >= first] = 0.9
    proba = np.stack([1 - p, p], axis=2)
    return Flights(model, 0, seed, "d.npz", CLASSES, np.arange(f), proba, None, np.zeros((f, w), np.int64), t,
                   np.ones((f, w), bool), np.full(f, 2), 1.0)


def _info() -> DatasetInfo:
    time = np.arange(0.0, 11.0, 0.5)
    return DatasetInfo(Path("d.npz"), {"fault_class": np.array([1, 1, 1, 1, 0], np.int8),
                                       "onset_s": np.array([ONSET] * 4 + [np.nan]),
                                       "detectable_s": np.full(5, np.nan), "fault_motor": np.full(5, -1, np.int8),
                                       "split": np.full(5, 2, np.int8), "severity": np.zeros((5, time.size)),
                                       "time": time, "severity_threshold": np.array(0.2)},
                       ("train", "validation", "test"))


def _evaluate() -> dict:
    cfg = load_config(ROOT / "configs/paper.toml", ["evaluate.thresholds=[0.5]", "evaluate.kn=['1/1']",
                                                    "evaluate.clear_m=[1]", "evaluate.bootstrap=1000"])
    return evaluate_sets([_flights(m, s) for (m, s) in FIRST_ALARM], {"d.npz": _info()}, cfg)


def test_common_flights_delay_by_hand_through_evaluate():
    ev = _evaluate()
    (pair,) = [p for p in ev["paired"] if p["set"] == "test"]
    c = pair["common_delay_onset"]
    assert (pair["a"], pair["b"], pair["flights"], c["flights"]) == ("a", "b", 5, 2)
    assert c["a"]["value"] == pytest.approx(1.5) and c["b"]["value"] == pytest.approx(4.0)
    assert c["diff"]["diff"] == pytest.approx(-2.5)
    # A resample's common flights are the drawn flights 0 and 1: its difference lies between theirs
    # (-3 and -2), and each alone is drawn in about a quarter of the replicates: the 2.5/97.5 % ends.
    assert (c["diff"]["lo"], c["diff"]["hi"]) == pytest.approx((-3.0, -2.0))
    assert (c["a"]["lo"], c["a"]["hi"]) == pytest.approx((1.5, 1.5))
    assert (c["b"]["lo"], c["b"]["hi"]) == pytest.approx((3.5, 4.5))
    # The own-detection figure points the other way: the reason for the common-flight one.
    assert pair["diff"]["delay_onset_s"]["diff"] == pytest.approx((1.5 + 1.5 + 7.5 + 0.25) / 3.5 - 8.5 / 3)
    ev.update(command="test", git_commit="0" * 40, git_dirty=False,
              protocol={"ci": 0.95, "bootstrap": 1000, "seed": 0, "target_fa_per_h": 1.0})
    row = next(line for line in markdown(ev).splitlines() if line.startswith("| a − b | test |"))
    assert "| 2 | 1.50 [1.50, 1.50] | 4.00 [3.50, 4.50] | -2.50 [-3.00, -2.00] |" in row


def test_each_replicate_recomputes_the_common_set():
    stats = {}
    for m in ("a", "b"):
        fl = [_flights(m, s) for s in (0, 1)]
        from quadfdi.evaluate.outcomes import flight_outcomes

        outs = [flight_outcomes(f, _info(), {"threshold": 0.5, "k": 1, "n": 1, "clear_m": 1, "latch": False})
                for f in fl]
        stats[m] = {k: np.mean([o[k] for o in outs], axis=0) for k in outs[0]}
    only_1 = np.tile([0.0, 2, 0, 0, 3], (4, 1))  # flight 1 alone among the common ones
    c = common_delay(stats["a"], stats["b"], only_1, 0.95)
    assert (c["a"]["lo"], c["b"]["lo"], c["diff"]["lo"], c["diff"]["hi"]) == pytest.approx((1.5, 4.5, -3.0, -3.0))
    mixed = np.tile([2.0, 1, 0, 0, 2], (4, 1))  # flight 0 twice, flight 1 once: b (7 + 4.5) / 3
    c = common_delay(stats["a"], stats["b"], mixed, 0.95)
    assert c["b"]["lo"] == pytest.approx(11.5 / 3) and c["diff"]["hi"] == pytest.approx(1.5 - 11.5 / 3)
    none = np.tile([0.0, 0, 3, 1, 1], (4, 1))  # no common flight drawn: undefined, no interval
    c = common_delay(stats["a"], stats["b"], none, 0.95)
    assert c["flights"] == 2 and c["diff"]["lo"] is None and c["a"]["lo"] is None
