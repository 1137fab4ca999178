"""The alarm-policy sweep of an evaluation as markdown (docs/detect.md "The alarm policy for the
profiled models"): per model the validation Pareto front (false alarms per flight-hour against mean
delay from onset; no other grid policy has both lower), the policy chosen on validation by
evaluate.policy's rule, and that policy's test figures with their intervals; first, the healthy
exposure behind them, of distinct flights and pooled over the runs.

    PYTHONPATH=. python scripts/policy_sweep_table.py RUN [SET]     (SET: test by default)
"""

from __future__ import annotations

import sys
from pathlib import Path

from quadfdi.core.jsonio import read_json
from quadfdi.core.tables import md_table


def _pol(r: dict) -> str:
    return f"p >= {r['threshold']:g}, {r['k']}/{r['n']}, clear {r['clear_m']}"


def _ci(m: dict, nd: int = 2) -> str:
    if m is None or m.get("value") is None:
        return "—"
    lo, hi = m.get("lo"), m.get("hi")
    return f"{m['value']:.{nd}f}" + (f" [{lo:.{nd}f}, {hi:.{nd}f}]" if lo is not None and hi is not None else "")


def exposure_rows(ev: dict, sets: tuple[str, ...]) -> list[list[str]]:
    """Per model and set: the healthy flights and decided healthy hours of DISTINCT flights (each
    (sim seed, dataset) counted once: a flight seen by several train seeds is one flight), per sim
    seed and summed, and the exposure pooled over every (sim seed, train seed) run, which the sweep uses."""
    rows = []
    for name in sorted(ev["models"]):
        for test in sets:
            runs = [r for r in ev["per_seed"] if r["model"] == name and r["set"] == test]
            if not runs:
                continue
            by_sim: dict[tuple, dict] = {}
            for r in runs:  # the train seeds of one dataset see the same flights and decided windows
                by_sim.setdefault((r["sim_seed"], r["dataset"]), r)
            parts = ", ".join(f"sim {k[0]}: {r['healthy']:.0f} flights, {r['exposure_h']:.2f} h"
                              for k, r in sorted(by_sim.items()))
            rows.append([name, test, parts, f"{sum(r['healthy'] for r in by_sim.values()):.0f}",
                         f"{sum(r['exposure_h'] for r in by_sim.values()):.2f}",
                         f"{len(runs)}", f"{sum(r['exposure_h'] for r in runs):.2f}"])
    return rows


def main(argv: list[str]) -> int:
    ev = read_json(Path(argv[0]) / "evaluation" / "evaluation.json")
    test = argv[1] if len(argv) > 1 else "test"
    print("\n".join(md_table(["model", "set", "distinct healthy flights per sim seed (decided hours)",
                              "distinct healthy flights", "distinct healthy h", "runs (sim x train seeds)",
                              "pooled exposure h"], exposure_rows(ev, ("validation", test)))))
    rows = []
    for name, m in sorted(ev["models"].items()):
        sw = [r for r in m["sweep"] if r["fa_per_h"] is not None and r["delay_onset_s"] is not None]
        front = [r for r in sw if not any(o["fa_per_h"] <= r["fa_per_h"] and o["delay_onset_s"] <= r["delay_onset_s"]
                                          and (o["fa_per_h"], o["delay_onset_s"]) != (r["fa_per_h"], r["delay_onset_s"])
                                          for o in sw)]
        c = m["policy"]
        for r in sorted(front, key=lambda r: r["delay_onset_s"]):
            chosen = all(r[k] == c[k] for k in c)
            rows.append([name, _pol(r) + (" **(chosen)**" if chosen else ""), f"{r['fa']:.0f} / {r['exposure_h']:.2f} h",
                         f"{r['fa_per_h']:.2f}", f"{r['detection_rate']:.3f}", f"{r['delay_onset_s']:.2f}"])
        pick = next(r for r in m["sweep"] if all(r[k] == c[k] for k in c))
        if not any(all(pick[k] == c[k] for k in c) for pick in front):
            rows.append([name, _pol(pick) + " **(chosen)**", f"{pick['fa']:.0f} / {pick['exposure_h']:.2f} h",
                         f"{pick['fa_per_h']:.2f}" if pick["fa_per_h"] is not None else "—",
                         f"{pick['detection_rate']:.3f}", f"{pick['delay_onset_s']:.2f}"])
    print("\n".join(md_table(["model", "policy (validation Pareto front)", "val false alarms / healthy exposure",
                              "val FA/h", "val detected", "val mean delay (s)"], rows)))
    trows = []
    for r in ev["results"]:
        if r["set"] != test or r["model"] not in ev["models"]:
            continue
        fa, mt = r["false_alarms"], r["metrics"]
        trows.append([r["model"], _pol(ev["models"][r["model"]]["policy"]), f"{fa['count']:.0f} / {fa['exposure_h']:.2f} h",
                      f"{fa['rate_per_h']:.2f} [{fa['poisson_lo']:.2f}, {fa['poisson_hi']:.2f}]",
                      _ci(mt.get("detection_rate"), 3), _ci(mt.get("delay_onset_s")), _ci(mt.get("motor_acc"), 3)])
    print("\n".join(md_table(["model", "chosen policy", f"{test} false alarms / exposure", f"{test} FA/h (Garwood)",
                              f"{test} detected", f"{test} mean delay (s)", f"{test} motor right"], trows)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
