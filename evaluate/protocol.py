"""The protocol: per model x test set x sim seed x train seed, pooled with intervals, paired differences.

Test sets: ``validation``, ``test`` and each out-of-distribution split by its name (codes >= 3 of
the dataset's split_names), plus ``test_ood_all`` pooling the out-of-distribution splits. Pooling:
the per-flight counts of one model's train seeds on one dataset are AVERAGED flight by flight
(a flight is one resampling unit however many train seeds saw it), then the flights of every
dataset (simulator seed) are concatenated: they are all units of one bootstrap pool.
"""

from __future__ import annotations

import itertools

import numpy as np

from quadfdi.core.config import Config
from quadfdi.core.errors import QuadfdiError
from quadfdi.evaluate import policy as pol
from quadfdi.evaluate.bootstrap import draw_weights, intervals, paired, point_and_replicates
from quadfdi.evaluate.ceiling import expected_confusion
from quadfdi.evaluate.common_delay import common_delay
from quadfdi.evaluate.load import DatasetInfo, Flights
from quadfdi.evaluate.metrics import COUNTS, garwood, macro_f1_accuracy, metrics_from_sums, sum_flights
from quadfdi.evaluate.outcomes import flight_outcomes

OOD_ALL = "test_ood_all"
GOAL_POINTS = 0.03  # the goal: a network beats the best baseline by >= 3 points of macro F1 on OOD sets
PAIRED_METRICS = ("macro_f1", "accuracy", "detection_rate", "fa_per_h", "delay_onset_s")


def test_sets(infos: dict[str, DatasetInfo]) -> dict[str, set[tuple[str, int]]]:
    """Set name -> {(dataset, split code)} (codes 1.. by name; test_ood_all = every code >= 3)."""
    out: dict[str, set] = {}
    for rel, info in infos.items():
        for code, name in enumerate(info.split_names):
            if code >= 1:
                out.setdefault(name, set()).add((rel, code))
            if code >= 3:
                out.setdefault(OOD_ALL, set()).add((rel, code))
    return out


def is_network(model: str, prefixes: tuple[str, ...]) -> bool:
    return any(model == p or model.startswith(p + "_") or model.startswith(p + "-") for p in prefixes)


def _pick(stats: dict[str, np.ndarray], keep: np.ndarray) -> dict[str, np.ndarray]:
    return {k: v[keep] for k, v in stats.items()}


def _num(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def _pool(outs: list[tuple[Flights, dict]], members: set) -> tuple[list, dict[str, np.ndarray], list[dict]]:
    """Units, train-seed-averaged per-flight stats, and per-seed point rows of one model on one set."""
    by_ds: dict[str, list] = {}
    seeds = []
    for fl, st in outs:
        keep = np.array([(fl.dataset, int(c)) in members for c in fl.split], bool)
        if keep.any():
            by_ds.setdefault(fl.dataset, []).append((fl, _pick(st, keep)))
            sums = sum_flights(_pick(st, keep))
            m = metrics_from_sums(sums)
            seeds.append({"sim_seed": fl.sim_seed, "train_seed": fl.train_seed, "dataset": fl.dataset,
                          "flights": int(keep.sum()), **{k: _num(v) for k, v in m.items()},
                          **{k: float(sums[k]) for k in COUNTS}})
    units, parts = [], []
    for rel in sorted(by_ds):
        group = by_ds[rel]
        rows = group[0][0].rows[np.array([(rel, int(c)) in members for c in group[0][0].split])]
        if any(not np.array_equal(fl.rows, group[0][0].rows) for fl, _ in group):
            raise QuadfdiError(f"model {group[0][0].model}: its train seeds' prediction sets on {rel} cover different "
                               "flights; every set of one model on one dataset must hold the same windows")
        keys = group[0][1].keys()
        parts.append({k: np.mean([st[k] for _, st in group], axis=0) for k in keys})
        units += [(rel, int(r)) for r in rows]
    stats = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if parts else {}
    return units, stats, seeds


def _false_alarms(seeds: list[dict], ci: float) -> dict:
    """Raw alarms summed over every (sim seed, train seed) run, over their summed exposure."""
    count = sum(s["fa"] for s in seeds)
    exposure = sum(s["exposure_h"] for s in seeds)
    lo, hi = garwood(count, exposure, ci)
    return {"count": int(round(count)), "exposure_h": exposure, "runs": len(seeds),
            "healthy_flights": int(round(sum(s["healthy"] for s in seeds))),
            "rate_per_h": count / exposure if exposure > 0 else None, "poisson_lo": lo, "poisson_hi": hi}


def _ceiling(sets_by_model: dict[str, list[Flights]], infos: dict[str, DatasetInfo], members: set) -> dict | None:
    first = {}
    for fls in sets_by_model.values():
        for fl in fls:
            first.setdefault(fl.dataset, fl)
    confs, amb, windows = [], 0, 0
    for rel, fl in sorted(first.items()):
        keep = np.array([(rel, int(c)) in members for c in fl.split], bool)
        if keep.any():
            conf, a = expected_confusion(fl.subset(keep), infos[rel])
            confs.append(conf.sum(axis=0))
            amb += int(a.sum())
            windows += int(fl.valid[keep].sum())
    if not confs:
        return None
    f1, acc = macro_f1_accuracy(np.sum(confs, axis=0))
    return {"macro_f1": _num(f1), "accuracy": _num(acc), "ambiguous_windows": amb, "windows": windows}


def evaluate_sets(sets: list[Flights], infos: dict[str, DatasetInfo], cfg: Config) -> dict:
    """Everything evaluation.json holds but its provenance (see docs/evaluation.md)."""
    ev = cfg.evaluate
    models = sorted({s.model for s in sets})
    by_model = {m: [s for s in sets if s.model == m] for m in models}
    grid = pol.grid(ev, cfg.alarm)
    chosen, sweeps = {}, {}
    for m in models:
        sweeps[m] = pol.sweep(by_model[m], infos, grid)
        chosen[m] = grid[pol.choose(sweeps[m], ev.target_fa_per_h)]
    outs = {m: [(fl, flight_outcomes(fl, infos[fl.dataset], chosen[m])) for fl in by_model[m]] for m in models}
    results, per_seed, pooled = [], [], {}
    for name, members in sorted(test_sets(infos).items()):
        for m in models:
            units, stats, seeds = _pool(outs[m], members)
            if not units:
                continue
            pooled[(m, name)] = (units, stats)
            w = draw_weights(units, ev.bootstrap, ev.seed)
            results.append({"model": m, "set": name, "flights": len(units), "metrics": intervals(stats, w, ev.ci),
                            "false_alarms": _false_alarms(seeds, ev.ci),
                            "missed_faults": float(stats["fault"].sum() - stats["detected"].sum()),
                            "early_alarms": float(stats["early"].sum()), "pre_onset_alarms": float(stats["pre_onset"].sum())})
            per_seed += [dict(s, model=m, set=name) for s in seeds]
    val = {m: r["metrics"]["macro_f1"]["value"] for r in results if r["set"] == pol.VALIDATION for m in [r["model"]]}
    baselines = [m for m in models if not is_network(m, ev.networks) and val.get(m) is not None]
    best = max(baselines, key=lambda m: (val[m], m)) if baselines else None
    return {"models": {m: {"network": is_network(m, ev.networks), "policy": chosen[m], "sweep": sweeps[m],
                           "sim_seeds": sorted({s.sim_seed for s in by_model[m]}),
                           "train_seeds": sorted({s.train_seed for s in by_model[m]})} for m in models},
            "best_baseline": best, "results": results, "per_seed": per_seed,
            "paired": (pairs := _paired(pooled, models, ev)), "vs_best_baseline": versus_best(pairs, best, models, ev),
            "ceiling": {name: _ceiling(by_model, infos, mem) for name, mem in sorted(test_sets(infos).items())}}


def _paired(pooled: dict, models: list[str], ev) -> list[dict]:
    """Every pair of models on every set, on the flights both were evaluated on (replicate metrics of a
    model on a flight list are computed once and shared by all its pairs), with the delay from onset
    on the fault flights both detect (evaluate.common_delay) under the same replicates."""
    weights: dict[tuple, np.ndarray] = {}
    subs: dict[tuple, dict] = {}
    reps: dict[tuple, tuple] = {}

    def rep(model: str, name: str, common: list) -> tuple:
        key = (model, name, tuple(common))
        if key not in reps:
            units, stats = pooled[(model, name)]
            index = {u: i for i, u in enumerate(units)}
            if tuple(common) not in weights:
                weights[tuple(common)] = draw_weights(common, ev.bootstrap, ev.seed)
            subs[key] = _pick(stats, np.array([index[u] for u in common]))
            reps[key] = point_and_replicates(subs[key], weights[tuple(common)])
        return reps[key]

    out = []
    for (a, b) in itertools.combinations(models, 2):
        for name in sorted({s for (_, s) in pooled}):
            if (a, name) not in pooled or (b, name) not in pooled:
                continue
            common = sorted(set(pooled[(a, name)][0]) & set(pooled[(b, name)][0]))
            if common:
                diff = paired(rep(a, name, common), rep(b, name, common), ev.ci, PAIRED_METRICS)
                key = tuple(common)
                both = common_delay(subs[(a, name, key)], subs[(b, name, key)], weights[key], ev.ci)
                out.append({"a": a, "b": b, "set": name, "flights": len(common), "diff": diff,
                            "common_delay_onset": both})
    return out


def versus_best(pairs: list[dict], best: str | None, models: list[str], ev) -> list[dict]:
    """Each network minus the best baseline, macro F1 on every set (the goal: at least
    GOAL_POINTS with the interval of the difference above 0 on the out-of-distribution sets)."""
    out = []
    for net in (m for m in models if is_network(m, ev.networks) and best is not None):
        for p in pairs:
            if {p["a"], p["b"]} == {net, best}:
                d = p["diff"]["macro_f1"]
                sign = 1.0 if p["a"] == net else -1.0
                diff = None if d["diff"] is None else sign * d["diff"]
                lo, hi = (None, None) if d["lo"] is None else sorted((sign * d["lo"], sign * d["hi"]))
                out.append({"network": net, "baseline": best, "set": p["set"], "flights": p["flights"],
                            "macro_f1_diff": diff, "lo": lo, "hi": hi,
                            "goal_met": diff is not None and lo is not None and diff >= GOAL_POINTS and lo > 0})
    return out
