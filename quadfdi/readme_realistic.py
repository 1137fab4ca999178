"""The README's realistic-suite block (``quadfdi readme --run R --block realistic``), from a run's files.

Rewrites ``<!-- realistic:start -->`` ... ``<!-- realistic:end -->`` from ``evaluation/evaluation.json``
(``quadfdi evaluate``) and, when present, ``realism/realism.json`` (``quadfdi realism``): macro F1
with its flight-bootstrap interval for every model on every test set, false alarms with their
exposure and Poisson interval, detection delays, each network against the best baseline (paired
bootstrap), and the realism ratios. Nothing is typed in by hand.
"""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json
from quadfdi.core.rundir import RunDir
from quadfdi.core.tables import md_table
from quadfdi.evaluate.report import (  # one formatting of an interval and of a policy
    _ci,
    _policy,
)

SETS = ("test", "test_ood_mission", "test_ood_vehicle", "test_ood_wind", "test_incipient", "test_ood_all")


def _models(ev: dict) -> list[str]:
    """Networks first, then baselines, each alphabetical."""
    return sorted(ev["models"], key=lambda m: (not ev["models"][m]["network"], m))


def f1_table(ev: dict) -> list[str]:
    sets = [s for s in SETS if any(r["set"] == s for r in ev["results"])]
    by = {(r["model"], r["set"]): r for r in ev["results"]}
    rows = [[m] + [_ci(by[(m, s)]["metrics"]["macro_f1"]) if (m, s) in by else "—" for s in sets] for m in _models(ev)]
    ceil = ev.get("ceiling", {})
    rows.append(["*label-noise ceiling*"] + [f"{ceil[s]['macro_f1']:.3f}" if s in ceil else "—" for s in sets])
    flights = [str(next((r["flights"] for r in ev["results"] if r["set"] == s), "?")) for s in sets]
    return md_table(["window macro F1 [95 %] (flights)"] + [f"{s} ({n})" for s, n in zip(sets, flights)], rows)


def alarm_table(ev: dict, set_name: str = "test") -> list[str]:
    rows = []
    for m in _models(ev):
        r = next((r for r in ev["results"] if r["model"] == m and r["set"] == set_name), None)
        if r is None:
            continue
        fa, mt, p = r["false_alarms"], r["metrics"], ev["models"][m]["policy"]
        rate = "—" if fa["rate_per_h"] is None else f"{fa['rate_per_h']:.2f} [{fa['poisson_lo']:.2f}, {fa['poisson_hi']:.2f}]"
        rows.append([m, _policy(p), fa["count"],
                     f"{fa['exposure_h']:.2f}", rate, _ci(mt["detection_rate"]), _ci(mt["delay_onset_s"], 2),
                     _ci(mt["delay_thr_s"], 2), f"{r['missed_faults']:.1f}", _ci(mt["motor_acc"])])
    return md_table(["model", "alarm policy (chosen on validation)", "false alarms", "healthy exposure h (all runs)",
                     "false alarms / h, Garwood 95 %", "faults detected", "delay from onset s",
                     "delay from threshold s", "missed faults (all sim seeds, train-seed mean)", "motor right"], rows)


def goal_table(ev: dict) -> list[str]:
    rows = [[g["network"], g["baseline"], g["set"], g["flights"],
             "—" if g["macro_f1_diff"] is None else f"{100 * g['macro_f1_diff']:+.1f}",
             "—" if g["lo"] is None else f"[{100 * g['lo']:+.1f}, {100 * g['hi']:+.1f}]",
             "yes" if g["goal_met"] else "no"] for g in ev.get("vs_best_baseline", []) if g["set"] in SETS]
    return md_table(["network", "best baseline (validation)", "set", "flights", "Δ macro F1 (points)",
                     "paired 95 % interval", "goal met (≥ 3 points, interval above 0)"], rows)


def realism_lines(root: Path) -> list[str]:
    path = root / "realism" / "realism.json"
    if not path.is_file():
        return ["Realism: not run (`quadfdi realism`).", ""]
    rows = read_json(path, "realism.json")["table"]
    ok = [r["channel"] for r in rows if r.get("noise_ratio") and 0.5 <= r["noise_ratio"] <= 2.0]
    off = [f"{r['channel']} {r['noise_ratio']:.2g}x" for r in rows
           if r.get("noise_ratio") and not 0.5 <= r["noise_ratio"] <= 2.0]
    return [f"**Realism** (`realism/realism.md`, simulated / real noise on steady segments): within a factor 2 "
            f"for {len(ok)} of {len(ok) + len(off)} channels ({', '.join(ok) or 'none'}); outside: "
            f"{', '.join(off) or 'none'}.", ""]


def realistic_block(root: Path) -> str:
    path = RunDir(root).evaluation
    if not path.is_file():
        raise QuadfdiError(f"{path} is missing: run `quadfdi evaluate --run {root}` first")
    ev = read_json(path, "evaluation.json")
    models = ev["models"]
    seeds = sorted({s for d in models.values() for s in d["sim_seeds"]})
    tseeds = sorted({s for d in models.values() if d["network"] for s in d["train_seeds"]})
    lines = [f"Made by `quadfdi readme --run {root} --block realistic` from `{ev['command']}` (code "
             f"`{(ev['git_commit'] or '?')[:10]}`{', with uncommitted changes' if ev['git_dirty'] else ''}); "
             f"simulator seeds {seeds}, network training seeds {tseeds} (averaged per flight), baselines one seed; "
             "intervals: flight bootstrap (docs/evaluation.md).", "",
             "**Window macro F1 per test set** (in distribution, then the out-of-distribution sets):", "",
             *f1_table(ev), "**Alarms on the in-distribution test flights** (policy per model chosen on validation):",
             "", *alarm_table(ev), "**Each network against the best baseline** (paired flight bootstrap):", "",
             *goal_table(ev), *realism_lines(root)]
    return "\n".join(lines)
