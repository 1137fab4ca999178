"""The alarms of a prediction set under a policy: the one place evaluate runs core.alarm.

``set_trace(fl, policy, reps, classes)`` is the AlarmTrace every outcome of evaluate.outcomes (and
so the validation sweep and the test report) is computed from: ``fl.proba`` / ``fl.motor`` with
``fl.voting()`` (padding and the windows before the hover freeze never vote, as in detect).
``flight_alarms(fl, policy, row)`` lists one flight's alarms in detect's alarms.json format
(core.alarm.alarm_records: start, end, class, motor, peak), the motor reported by core.alarm's
rule 5: what ``quadfdi detect`` on the same flight must give (tests/test_detect_evaluate.py).
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.alarm import AlarmTrace, alarm_records, rotor_columns, run_alarm
from quadfdi.evaluate.load import Flights


def set_trace(fl: Flights, policy: dict, reps: int = 1, classes: bool = True) -> AlarmTrace:
    """core.alarm on ``reps`` stacked copies of the set's flights (policy values scalars or (reps * F,))."""
    tile = (lambda x: np.concatenate([x] * reps)) if reps > 1 else (lambda x: x)
    return run_alarm(tile(fl.proba), policy["threshold"], policy["k"], policy["n"], policy["clear_m"],
                     policy.get("latch", False), healthy=fl.class_names.index("Healthy"), valid=tile(fl.voting()),
                     motor_proba=None if fl.motor is None else tile(fl.motor), classes=classes)


def flight_alarms(fl: Flights, policy: dict, row: int) -> list[dict]:
    """The alarms of flight ``row`` of the set (row of ``fl.rows``, not the dataset row)."""
    one = fl.subset(np.arange(len(fl.rows)) == row)
    tr = set_trace(one, policy)
    w = int(one.valid[0].sum())  # padding is at the end
    return alarm_records(tr, one.t_end[:, :w], one.proba[:, :w], one.class_names,
                         rotor=rotor_columns(one.class_names) if one.motor is not None else None)
