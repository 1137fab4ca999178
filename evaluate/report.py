"""evaluation.md from evaluation.json, and the run report's section and headline (files only).

``report_section(run_root)`` and ``headline(run_root)`` read ``<run>/evaluation/evaluation.json``
and nothing else (no torch, no datasets), like every stage's report module.
"""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.reportmd import demote, not_run, optional_json
from quadfdi.core.rundir import EVALUATION_JSON
from quadfdi.core.tables import md_table
from quadfdi.evaluate import deployment
from quadfdi.evaluate.figures import SWEEP_PNG
from quadfdi.evaluate.protocol import OOD_ALL

JSON_NAME = Path(EVALUATION_JSON)
MD_NAME = Path("evaluation") / "evaluation.md"
HEADING = "## Evaluation (validation-chosen alarm policy, flight bootstrap)"


def _v(x, nd=3) -> str:
    return "—" if x is None else f"{x:.{nd}f}"


def _ci(m: dict, nd=3, scale=1.0) -> str:
    if m.get("value") is None:
        return "—"
    s = f"{m['value'] * scale:.{nd}f}"
    return s if m.get("lo") is None else f"{s} [{m['lo'] * scale:.{nd}f}, {m['hi'] * scale:.{nd}f}]"


def _policy(p: dict) -> str:
    return f"p≥{p['threshold']:g}, {p['k']}/{p['n']}, clear {p['clear_m']}" + (", latch" if p["latch"] else "")


def _motor(ev: dict, r: dict) -> str:
    """The localisation cell, tagged with where the motor comes from: a network's motor head, or a
    baseline's physics rule (train.baselines_jobs.suspected_motor)."""
    cell = _ci(r["metrics"]["motor_acc"])
    if cell == "—":
        return cell
    return f"{cell} ({'head' if ev['models'].get(r['model'], {}).get('network') else 'rule'})"


def _set_table(ev: dict, name: str) -> list[str]:
    rows = []
    for r in (r for r in ev["results"] if r["set"] == name):
        m = r["metrics"]
        rows.append([r["model"], r["flights"], _ci(m["macro_f1"]), _ci(m["accuracy"]), _ci(m["detection_rate"]),
                     _ci(m["delay_onset_s"], 2), _ci(m["delay_thr_s"], 2), _ci(m["class_acc"]), _motor(ev, r)])
    c = ev["ceiling"].get(name)
    if c:
        rows.append([f"*label-noise ceiling* ({c['ambiguous_windows']}/{c['windows']} windows ambiguous)", "",
                     _v(c["macro_f1"]), _v(c["accuracy"]), "", "", "", "", ""])
    return [f"### {name}", ""] + md_table(
        ["model", "flights", "macro F1", "accuracy", "detected", "delay from onset s", "delay from threshold s",
         "alarm class right", "motor right (head / physics rule)"], rows)


def _fa_table(ev: dict) -> list[str]:
    rows = []
    for r in ev["results"]:
        fa = r["false_alarms"]
        rate = "—" if fa["rate_per_h"] is None else f"{fa['rate_per_h']:.2f} [{fa['poisson_lo']:.2f}, {fa['poisson_hi']:.2f}]"
        rows.append([r["model"], r["set"], fa["count"], fa["runs"], fa["healthy_flights"], f"{fa['exposure_h']:.2f}",
                     rate, _ci(r["metrics"]["fa_per_h"], 2), f"{r['early_alarms']:.1f}", f"{r['pre_onset_alarms']:.1f}",
                     f"{r['missed_faults']:.1f}"])
    return md_table(["model", "set", "false alarms", "runs", "healthy flights (all runs)", "exposure h (all runs)",
                     "per h, Garwood 95 %", "per h, bootstrap", "early alarms", "of which before onset",
                     "missed faults"], rows)


def _paired_table(ev: dict) -> list[str]:
    nets = {m for m, d in ev["models"].items() if d["network"]}
    rows = []
    for p in ev["paired"]:
        d = p["diff"]
        fmt = lambda k, nd=3: "—" if d[k]["diff"] is None else (  # noqa: E731
            f"{d[k]['diff']:+.{nd}f}" + ("" if d[k]["lo"] is None else f" [{d[k]['lo']:+.{nd}f}, {d[k]['hi']:+.{nd}f}]"))
        tag = " (best baseline)" if ev["best_baseline"] in (p["a"], p["b"]) and ({p["a"], p["b"]} & nets) else ""
        rows.append([f"{p['a']} − {p['b']}{tag}", p["set"], p["flights"], fmt("macro_f1"), fmt("detection_rate"),
                     fmt("fa_per_h", 2), fmt("delay_onset_s", 2), *_common_cells(p.get("common_delay_onset"))])
    return md_table(["pair (a − b)", "set", "flights", "Δ macro F1", "Δ detected", "Δ false alarms / h",
                     "Δ delay from onset s", "faults both detect", "delay on them s: a", "b",
                     "Δ delay on them s"], rows)


def _common_cells(c: dict | None) -> list[str]:
    """The delay from onset on the fault flights both models detect (evaluate.common_delay): the
    number of such flights, each model's mean delay on them and the paired difference a - b."""
    if c is None:
        return ["—"] * 4
    d = c["diff"]
    diff = "—" if d["diff"] is None else (
        f"{d['diff']:+.2f}" + ("" if d["lo"] is None else f" [{d['lo']:+.2f}, {d['hi']:+.2f}]"))
    return [str(c["flights"]), _ci(c["a"], 2), _ci(c["b"], 2), diff]


def _goal_table(ev: dict) -> list[str]:
    rows = [[g["network"], g["baseline"], g["set"], g["flights"],
             "—" if g["macro_f1_diff"] is None else f"{100 * g['macro_f1_diff']:+.1f}",
             "—" if g["lo"] is None else f"[{100 * g['lo']:+.1f}, {100 * g['hi']:+.1f}]",
             "yes" if g["goal_met"] else "no"] for g in ev.get("vs_best_baseline", [])]
    if not rows:
        return ["No network and baseline pair to compare.", ""]
    return md_table(["network", "best baseline", "set", "flights", "Δ macro F1 (points)", "95 % interval",
                     "≥ 3 points, interval above 0"], rows)


def markdown(ev: dict) -> str:
    """The whole evaluation.md."""
    p = ev["protocol"]
    lines = ["# Evaluation", "", f"Command: `{ev['command']}`  ", f"Code: commit `{ev['git_commit']}`"
             + (" (with uncommitted changes)" if ev["git_dirty"] else "") + "  ",
             f"Intervals: {int(p['ci'] * 100)} % percentile bootstrap by flight ({p['bootstrap']} replicates, seed "
             f"{p['seed']}); train seeds averaged per flight before resampling; the flights of every simulator seed "
             "are units of one pool; false-alarm rates also with an exact Poisson (Garwood) interval over all runs. "
             "Definitions: docs/evaluation.md.", "", "## Alarm policy (chosen on validation flights only)", "",
             f"Rule: validation false alarms per flight-hour ≤ {p['target_fa_per_h']:g}, then most faults detected, "
             "then shortest delay from onset, then grid order.", ""]
    rows = []
    for m, d in sorted(ev["models"].items()):
        c = d["policy"]
        row = next(r for r in d["sweep"] if all(r[k] == c[k] for k in c))
        rows.append([m, "network" if d["network"] else "baseline", _policy(c), _v(row["fa_per_h"], 2),
                     _v(row["detection_rate"]), _v(row["delay_onset_s"], 2), ",".join(map(str, d["sim_seeds"])),
                     ",".join(map(str, d["train_seeds"]))])
    lines += md_table(["model", "kind", "chosen policy", "val FA/h", "val detected", "val delay s", "sim seeds",
                       "train seeds"], rows)
    lines += [f"![alarm sweep]({SWEEP_PNG})", "", f"Best baseline (validation macro F1): {ev['best_baseline'] or '—'}", ""]
    lines += deployment.markdown(ev) + ["## Window and flight metrics per test set", ""]
    for name in _set_order(ev):
        lines += _set_table(ev, name)
    lines += ["## False alarms, early alarms, missed faults", ""] + _fa_table(ev)
    lines += ["## Networks against the best baseline (macro F1, paired)", ""] + _goal_table(ev)
    lines += ["## Paired differences (same resampled flights)", ""] + _paired_table(ev)
    return "\n".join(lines)


def _set_order(ev: dict) -> list[str]:
    names = sorted({r["set"] for r in ev["results"]})
    first = [n for n in ("validation", "test") if n in names]
    return first + [n for n in names if n not in first and n != OOD_ALL] + ([OOD_ALL] if OOD_ALL in names else [])


def report_section(root: Path) -> list[str]:
    ev = optional_json(Path(root) / JSON_NAME, "evaluation.json")
    if ev is None:
        return not_run(HEADING, "no evaluation/evaluation.json (quadfdi evaluate --run RUN)")
    text = markdown(ev).replace(f"]({SWEEP_PNG})", f"](evaluation/{SWEEP_PNG})")
    return [HEADING, ""] + demote("\n".join(text.splitlines()[2:]), 1)


def headline(root: Path) -> list[str]:
    ev = optional_json(Path(root) / JSON_NAME, "evaluation.json")
    if ev is None:
        return []
    out = []
    for name in ("test", OOD_ALL):
        rows = [r for r in ev["results"] if r["set"] == name and r["metrics"]["macro_f1"]["value"] is not None]
        if rows:
            best = max(rows, key=lambda r: r["metrics"]["macro_f1"]["value"])
            out.append(f"- Evaluation, {name}: best macro F1 {_ci(best['metrics']['macro_f1'])} ({best['model']}, "
                       f"{best['flights']} flights); ceiling {_v((ev['ceiling'].get(name) or {}).get('macro_f1'))}.")
    return out
