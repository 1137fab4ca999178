"""Prediction sets scored under alarm policies fixed beforehand: the protocol (evaluate.protocol)
without its policy sweep.

``quadfdi evaluate`` chooses each model's policy on that model's own validation flights. A variant of
a model -- the masked model with every test window under one mask pattern -- must be scored under
the policy its model was chosen with (every channel), not one re-tuned to the variant: that would
flatter it with a choice a deployed model cannot make. Everything else is the protocol's: the
flights of one test set (``evaluate.protocol.test_sets``), train seeds averaged per flight and sim
seeds pooled, flight-bootstrap intervals, the Garwood interval on false alarms per healthy
flight-hour, and paired differences on the flights two models share under the same replicates. A
model scored here under the policy ``quadfdi evaluate`` chose for it gives evaluation.json's row.
"""

from __future__ import annotations

from quadfdi.core.errors import QuadfdiError
from quadfdi.evaluate.bootstrap import draw_weights, intervals, paired, point_and_replicates
from quadfdi.evaluate.load import DatasetInfo, Flights
from quadfdi.evaluate.outcomes import flight_outcomes
from quadfdi.evaluate.protocol import PAIRED_METRICS, _false_alarms, _pick, _pool, test_sets


def score_fixed(sets: dict[str, list[Flights]], policies: dict[str, dict], infos: dict[str, DatasetInfo],
                set_name: str, cfg) -> tuple[dict[str, dict], dict[str, tuple]]:
    """Each label's row on the test set ``set_name`` under ``policies[label]`` (the protocol's result
    row: flights, metrics with intervals, false_alarms, missed_faults), and what ``paired_fixed`` needs."""
    ev = cfg.evaluate
    members = test_sets(infos).get(set_name)
    if members is None:
        raise QuadfdiError(f"no test set {set_name!r} in the datasets ({', '.join(sorted(test_sets(infos)))})")
    rows, pooled = {}, {}
    for label, fls in sets.items():
        outs = [(fl, flight_outcomes(fl, infos[fl.dataset], policies[label])) for fl in fls]
        units, stats, seeds = _pool(outs, members)
        if not units:
            raise QuadfdiError(f"{label}: its prediction sets hold no flight of the {set_name} set")
        pooled[label] = (units, stats)
        rows[label] = {"flights": len(units), "policy": policies[label],
                       "metrics": intervals(stats, draw_weights(units, ev.bootstrap, ev.seed), ev.ci),
                       "false_alarms": _false_alarms(seeds, ev.ci),
                       "faults": float(stats["fault"].sum()), "detected": float(stats["detected"].sum()),
                       "missed_faults": float(stats["fault"].sum() - stats["detected"].sum())}
    return rows, pooled


def paired_fixed(pooled: dict[str, tuple], a: str, b: str, cfg) -> dict:
    """``a`` minus ``b`` (labels of ``score_fixed``) on the flights both hold, under the same bootstrap
    replicates: {"flights", "diff": {metric: {"diff", "lo", "hi"}}}."""
    ev = cfg.evaluate
    (ua, sa), (ub, sb) = pooled[a], pooled[b]
    common = sorted(set(ua) & set(ub))
    if not common:
        raise QuadfdiError(f"{a} and {b} share no flight")
    w = draw_weights(common, ev.bootstrap, ev.seed)
    ia, ib = {u: i for i, u in enumerate(ua)}, {u: i for i, u in enumerate(ub)}
    ra = point_and_replicates(_pick(sa, [ia[u] for u in common]), w)
    rb = point_and_replicates(_pick(sb, [ib[u] for u in common]), w)
    return {"flights": len(common), "diff": paired(ra, rb, ev.ci, PAIRED_METRICS)}
