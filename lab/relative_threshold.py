"""Would a threshold relative to the vehicle's own healthy flights help? For one model of a fleet run, the
alarm policy chosen on the VALIDATION flights (evaluate/policy.py's rule: validation false alarms per
flight-hour <= 1, then most faulty flights detected) from three grids: the absolute thresholds of
[evaluate] ("abs"); a per-vehicle threshold = a quantile (0.5, 0.9 or 1.0) of p(fault) over the decided
windows of that vehicle's reference flights, plus a margin, capped at 1 ("rel"); both ("all"). Each
choice is then shown on the test and the pooled out-of-distribution flights. Prints, before the choices,
the median over validation flights of their vehicle's reference quantiles (how far from 0 a healthy flight sits).

    python lab/relative_threshold.py RUN MODEL       # e.g. a fleet run and gru
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np

from quadfdi.evaluate.load import load_dataset_info, to_flights
from quadfdi.evaluate.metrics import metrics_from_sums
from quadfdi.evaluate.outcomes import SCALAR_KEYS, alarm_outcomes
from quadfdi.formats.predictions import check_prediction_set, read_index

QUANTILES = (0.5, 0.9, 1.0)
MARGINS = (0.0, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3)
THRESHOLDS = (0.5, 0.7, 0.9, 0.97, 0.99)
KN = ("1/1", "2/2", "2/3", "3/3", "2/4", "3/4", "4/4", "3/5", "5/8", "8/12")
CLEAR_M = (3, 8)
TARGET_FA_PER_H = 1.0


def load(run: Path, model: str) -> list[tuple]:
    """(flights without the reference ones, (F, len(QUANTILES)) reference quantiles, info) per prediction set."""
    out, infos = [], {}
    for e in (e for e in read_index(run) if e["model"] == model):
        if e["dataset"] not in infos:
            infos[e["dataset"]] = load_dataset_info(run / e["dataset"])
            with np.load(run / e["dataset"]) as z:
                infos[e["dataset"]].arrays["vehicle_id"] = z["vehicle_id"]
        info = infos[e["dataset"]]
        with np.load(run / e["predictions"]) as z:
            arrays = {k: z[k] for k in z.files}
        check_prediction_set(arrays, e["predictions"])
        fl = to_flights(e, arrays, info)
        vid, ref = info.arrays["vehicle_id"][fl.rows], info.arrays["reference_flight"][fl.rows].astype(bool)
        pf, vote = 1.0 - fl.proba[:, :, fl.class_names.index("Healthy")], fl.voting()
        stat = np.full((fl.rows.size, len(QUANTILES)), np.nan)
        for v in np.unique(vid):
            vals = pf[(vid == v) & ref][vote[(vid == v) & ref]]
            if vals.size:
                stat[vid == v] = np.quantile(vals, QUANTILES)
        out.append((fl.subset(~ref), stat[~ref], info))
    if not out:
        sys.exit(f"{run}: no prediction set of model {model!r}")
    return out


def policies() -> list[dict]:
    out = []
    for t, kn, m in itertools.product(THRESHOLDS, KN, CLEAR_M):
        k, n = map(int, kn.split("/"))
        out.append({"threshold": t, "k": k, "n": n, "clear_m": m, "relative": None})
    for q, mg, kn, m in itertools.product(range(len(QUANTILES)), MARGINS, KN, CLEAR_M):
        k, n = map(int, kn.split("/"))
        out.append({"threshold": None, "k": k, "n": n, "clear_m": m, "relative": (q, mg)})
    return out


def score(sets: list[tuple], pol: dict, pick) -> dict:
    sums = {k: 0.0 for k in SCALAR_KEYS}
    for fl, stat, info in sets:
        keep = pick(fl.split)
        sub = fl.subset(keep)
        if pol["relative"] is None:
            thr = pol["threshold"]
        else:
            q, mg = pol["relative"]
            thr = np.minimum(np.nan_to_num(stat[keep, q], nan=1.0) + mg, 1.0)
        o = alarm_outcomes(sub, info, dict(pol, threshold=thr, latch=False), classes=False)
        for k in SCALAR_KEYS:
            sums[k] += float(o[k].sum())
    m = metrics_from_sums(dict(sums, conf=np.zeros((1, 1))))
    return {"fa_per_h": float(m["fa_per_h"]), "detected": float(np.nan_to_num(m["detection_rate"], nan=0.0)),
            "fa": sums["fa"], "exposure_h": sums["exposure_h"]}


def main(run: str, model: str) -> None:
    sets = load(Path(run), model)
    val_stat = np.concatenate([s[fl.split == 1] for fl, s, _ in sets])
    print(f"{model}: reference p(fault) over validation flights, median over flights of their vehicle's quantiles "
          + ", ".join(f"q{q:g} {v:.3f}" for q, v in zip(QUANTILES, np.nanmedian(val_stat, axis=0))))
    pols = policies()
    val = [score(sets, p, lambda s: s == 1) for p in pols]
    for family, member in (("abs", lambda p: p["relative"] is None), ("rel", lambda p: p["relative"] is not None),
                           ("all", lambda p: True)):
        ok = [i for i, p in enumerate(pols) if member(p) and val[i]["fa_per_h"] <= TARGET_FA_PER_H]
        if not ok:
            print(f"{family}: no policy meets {TARGET_FA_PER_H} false alarm per validation hour")
            continue
        i = max(ok, key=lambda j: (val[j]["detected"], -j))
        p = pols[i]
        what = (f"p >= {p['threshold']}" if p["relative"] is None else
                f"p >= min(1, q{QUANTILES[p['relative'][0]]:g} of the reference + {p['relative'][1]})")
        print(f"{family}: {what}, {p['k']} of {p['n']}, clear {p['clear_m']}: validation "
              f"{val[i]['detected']:.1%} detected at {val[i]['fa_per_h']:.2f} FA/h")
        for name, pick in (("test", lambda s: s == 2), ("ood", lambda s: s >= 3)):
            r = score(sets, p, pick)
            print(f"    {name}: {r['detected']:.1%} detected at {r['fa_per_h']:.2f} FA/h "
                  f"({r['fa']:.0f} alarms in {r['exposure_h']:.1f} h)")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
