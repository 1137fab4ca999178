"""Why the streaming GRU alarms later or earlier than the windowed GRU after a fault's onset
(issue 16, third "Done when" bullet): per test set, per fault class and fault mode.

    python scripts/sgru_onset.py RUN [--a gru] [--b sgru] [--sets test,test_ood_mission,...]

RUN is a run folder already evaluated (``quadfdi evaluate``): the alarm policy of each model is the
one ``RUN/evaluation/evaluation.json`` chose on validation; the prediction sets are those its index
lists (every sim seed and train seed). Per flight, train seeds averaged (as evaluate does):

- ``det``: share of train seeds whose alarm is active at a window ending at or after onset;
- ``delay``: that first window's end minus onset, averaged over the seeds that detected;
- ``t50`` / ``t99``: the first window ending at or after onset whose fault probability
  1 - p(Healthy) (what the policy votes on) reaches 0.5 / the policy threshold, minus onset,
  averaged over the seeds that reach it (and the share that do: ``r50`` / ``r99``);
- ``pf[a, b)``: the mean fault probability over the windows ending in [onset + a, onset + b) s.

Printed (markdown): per set x class x mode the flight count, detections and mean delays of both
models; the mean delay on the flights BOTH detect (every seed of each) with the paired difference
a - b and its flight-bootstrap interval, computed by ``evaluate.common_delay`` (the definition
``quadfdi evaluate`` reports per pair and set, docs/evaluation.md "Delay on common flights"; here
resampling the group's fault flights, with evaluation.json's bootstrap settings), and below each
table the set's figure as evaluation.json holds it; the rise of the fault probability after onset.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from quadfdi.core.tables import md_table
from quadfdi.evaluate.bootstrap import draw_weights
from quadfdi.evaluate.common_delay import common_delay
from quadfdi.evaluate.load import Flights, load_run
from quadfdi.evaluate.outcomes import alarm_outcomes

BINS = ((-10.0, 0.0), (0.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 40.0))
DEFAULT_SETS = "test,test_ood_mission,test_ood_vehicle,test_ood_wind,validation"


def _first_after(mask: np.ndarray, t_end: np.ndarray, onset: np.ndarray) -> np.ndarray:
    """(F,) end time of the first window in ``mask`` ending at or after onset, minus onset (NaN: none)."""
    te = np.nan_to_num(t_end, nan=-np.inf)
    m = mask & (te >= onset[:, None])
    i = m.argmax(axis=1)
    return np.where(m.any(axis=1), t_end[np.arange(len(i)), i] - onset, np.nan)


def per_flight(fl: Flights, info, policy: dict) -> dict[str, np.ndarray]:
    """The per-flight quantities of the module docstring for one prediction set (one train seed)."""
    a = info.arrays
    onset = np.nan_to_num(a["onset_s"][fl.rows], nan=np.inf)
    out = alarm_outcomes(fl, info, policy, classes=False)
    pf = 1.0 - fl.proba[:, :, fl.class_names.index("Healthy")]
    vote = fl.voting()
    res = {"det": out["detected"], "delay": np.where(out["detected"] > 0, out["delay_onset"], np.nan),
           "t50": _first_after((pf >= 0.5) & vote, fl.t_end, onset),
           "t99": _first_after((pf >= policy["threshold"]) & vote, fl.t_end, onset)}
    since = fl.t_end - onset[:, None]
    for lo, hi in BINS:
        w = vote & (since >= lo) & (since < hi)
        res[f"pf{lo:g}_{hi:g}"] = np.where(w.any(axis=1), (pf * w).sum(axis=1) / np.maximum(w.sum(axis=1), 1), np.nan)
    return res


def model_table(sets: list[Flights], infos: dict, policy: dict) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """(dataset, row) -> per-seed values (S,) of every key of ``per_flight``."""
    acc: dict[tuple[str, int], dict[str, list]] = {}
    for fl in sets:
        res = per_flight(fl, infos[fl.dataset], policy)
        for j, r in enumerate(fl.rows):
            d = acc.setdefault((fl.dataset, int(r)), {})
            for k, v in res.items():
                d.setdefault(k, []).append(float(v[j]))
    return {u: {k: np.asarray(v) for k, v in d.items()} for u, d in acc.items()}


def _nanmean(x: np.ndarray) -> float:
    return float(np.nanmean(x)) if np.isfinite(x).any() else float("nan")


def _fmt(x: float, nd: int = 2) -> str:
    return "—" if not np.isfinite(x) else f"{x:.{nd}f}"


def _stats(t: dict, us: list) -> dict[str, np.ndarray]:
    """The per-flight counts evaluate pools (train seeds averaged) that evaluate.common_delay reads."""
    det = np.array([t[u]["det"].mean() for u in us])
    delay = np.array([np.where(t[u]["det"] > 0, np.nan_to_num(t[u]["delay"]), 0.0).mean() for u in us])
    return {"fault": np.ones(len(us)), "detected": det, "delay_onset": delay}


def _ci(m: dict, key: str = "value") -> str:
    f = "+.2f" if key == "diff" else ".2f"
    v = "—" if m[key] is None else format(m[key], f)
    return v if m["lo"] is None else f"{v} [{format(m['lo'], f)}, {format(m['hi'], f)}]"


def _units(infos: dict, tab_a: dict, set_name: str) -> list[tuple[str, int]]:
    """Fault flights of a set (by split name; test_ood_all = every split code >= 3) both models saw."""
    out = []
    for (rel, row) in sorted(tab_a):
        a = infos[rel].arrays
        name = infos[rel].split_names[int(a["split"][row])]
        ok = name == set_name or (set_name == "test_ood_all" and int(a["split"][row]) >= 3)
        if ok and int(a["fault_class"][row]) != 0:
            out.append((rel, row))
    return out


GROUP_KEYS = ("class_names", "fault_mode", "fault_mode_names")


def add_group_arrays(run: Path, infos: dict) -> None:
    """The class and fault-mode arrays evaluate does not load (the telemetry is still not read)."""
    for rel, info in infos.items():
        with np.load(run / rel, allow_pickle=False) as z:
            info.arrays.update({k: z[k] for k in GROUP_KEYS if k in z.files})


def _group(infos: dict, u: tuple[str, int]) -> str:
    a = infos[u[0]].arrays
    cls = str(a["class_names"][int(a["fault_class"][u[1]])]) if "class_names" in a else str(int(a["fault_class"][u[1]]))
    mode = str(a["fault_mode_names"][int(a["fault_mode"][u[1]])]) if "fault_mode_names" in a else "?"
    return f"{cls.replace('Fault', '')} / {mode}"


def set_report(name: str, units: list, infos: dict, ta: dict, tb: dict, a: str, b: str, ev: dict) -> list[str]:
    """The per-set lines: groups, common-detection paired delay, rise of the fault probability."""
    groups = sorted({_group(infos, u) for u in units}) + ["all"]
    proto = ev["protocol"]
    rows = []
    for g in groups:
        us = [u for u in units if g == "all" or _group(infos, u) == g]
        sa, sb = _stats(ta, us), _stats(tb, us)
        det_a, det_b = sa["detected"], sb["detected"]
        own_a = sa["delay_onset"].sum() / det_a.sum() if det_a.sum() else float("nan")
        own_b = sb["delay_onset"].sum() / det_b.sum() if det_b.sum() else float("nan")
        c = common_delay(sa, sb, draw_weights(us, proto["bootstrap"], proto["seed"]), proto["ci"])
        rows.append([g, len(us), _fmt(det_a.sum(), 1), _fmt(det_b.sum(), 1), _fmt(own_a), _fmt(own_b), c["flights"],
                     _ci(c["a"]), _ci(c["b"]), _ci(c["diff"], "diff")])
    lines = [f"### {name}", ""]
    lines += md_table(["class / mode", "fault flights", f"det {a}", f"det {b}", f"delay {a} (own)", f"delay {b} (own)",
                       "both detect", f"delay {a} (both)", f"delay {b} (both)", f"Δ {a} − {b} (both) [95 %]"], rows)
    pair = next((p for p in ev.get("paired", []) if p["set"] == name and {p["a"], p["b"]} == {a, b}), None)
    if pair is not None and "common_delay_onset" in pair:
        c = pair["common_delay_onset"]
        sign = "" if pair["a"] == a else f" (as {pair['a']} − {pair['b']})"
        lines += [f"evaluation.json, {name}: {c['flights']} fault flights both detect; delay {pair['a']} "
                  f"{_ci(c['a'])}, {pair['b']} {_ci(c['b'])}, Δ {_ci(c['diff'], 'diff')}{sign}", ""]
    rise = []
    for m, t in ((a, ta), (b, tb)):
        vals = {k: np.array([_nanmean(t[u][k]) for u in units]) for k in t[units[0]] if k.startswith("pf")}
        r50 = np.mean([np.isfinite(t[u]["t50"]).mean() for u in units])
        r99 = np.mean([np.isfinite(t[u]["t99"]).mean() for u in units])
        t50 = np.nanmedian([_nanmean(t[u]["t50"]) for u in units])
        t99 = np.nanmedian([_nanmean(t[u]["t99"]) for u in units])
        rise.append([m, _fmt(r50), _fmt(t50), _fmt(r99), _fmt(t99), *(_fmt(_nanmean(v), 3) for v in vals.values())])
    lines += md_table(["model", "reach 0.5", "median t 0.5 s", "reach thr", "median t thr s",
                       *(f"mean p_fault [{lo:g}, {hi:g}) s" for lo, hi in BINS)], rise)
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--a", default="gru")
    ap.add_argument("--b", default="sgru")
    ap.add_argument("--sets", default=DEFAULT_SETS)
    args = ap.parse_args(argv)
    ev = json.loads((args.run / "evaluation" / "evaluation.json").read_text())
    sets, infos = load_run(args.run)
    add_group_arrays(args.run, infos)
    tabs = {m: model_table([s for s in sets if s.model == m], infos, ev["models"][m]["policy"]) for m in (args.a, args.b)}
    print(f"# Onset analysis: {args.a} against {args.b}, run {args.run}\n")
    print(f"policies: {args.a} {ev['models'][args.a]['policy']}; {args.b} {ev['models'][args.b]['policy']}\n")
    for name in args.sets.split(","):
        units = [u for u in _units(infos, tabs[args.a], name) if u in tabs[args.b]]
        if units:
            print("\n".join(set_report(name, units, infos, tabs[args.a], tabs[args.b], args.a, args.b, ev)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
