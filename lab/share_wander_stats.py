"""How much the four motor commands' shares move within a window: real flights against simulated healthy ones.

    python lab/share_wander_stats.py [--dataset DATASET.npz] [FLIGHT.npz ...]

Share: ``thr_k / mean(thr_1..4)`` per sample. Per 80-sample window (stride 20) where every sample is
airborne with all four commands finite (ingested flights: ``airborne``; dataset flights: collective
above 0.05 and after the first 10 s), the window's own mean is removed from each motor's share;
printed per flight (real) or per mission type over the healthy flights (simulated): the number of
windows, the median and 90th percentile over windows of the within-window standard deviation (mean
of the four motors), and the median over windows of the autocorrelation at lags 1, 5 and 10 samples
(0.04, 0.2, 0.4 s at 25 Hz) of what is left once the four motors' mean is removed too. These are
the figures train/augment.py's amplitude and correlation time were chosen from (docs/training.md,
"Motor-share wander").
"""

from __future__ import annotations

import argparse

import numpy as np

W, STRIDE, LAGS = 80, 20, (1, 5, 10)


def window_stats(thr: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) within-window share std and (n, len(LAGS)) autocorrelations of the usable windows."""
    s = thr / thr.mean(axis=1, keepdims=True)
    sd, ac = [], []
    for a in range(0, len(s) - W + 1, STRIDE):
        if not ok[a:a + W].all():
            continue
        w = s[a:a + W] - s[a:a + W].mean(axis=0)
        sd.append(w.std(axis=0).mean())
        d = w - w.mean(axis=1, keepdims=True)
        v = (d * d).mean()
        ac.append([(d[k:] * d[:W - k]).mean() / v if v > 0 else np.nan for k in LAGS])
    return np.array(sd), np.array(ac).reshape(-1, len(LAGS))


def row(name: str, sd: np.ndarray, ac: np.ndarray) -> str:
    if len(sd) == 0:
        return f"| {name} | 0 | | | |"
    acs = ", ".join(f"{v:.2f}" for v in np.nanmedian(ac, axis=0))
    return f"| {name} | {len(sd)} | {np.median(sd):.3f} | {np.percentile(sd, 90):.3f} | {acs} |"


def real_flight(path: str) -> str:
    d = np.load(path, allow_pickle=True)
    names = [str(n) for n in d["channel_names"]]
    x = d["telemetry"]
    thr = np.stack([x[:, names.index(f"thr{k}")] for k in range(1, 5)], axis=1)
    ok = d["airborne"].astype(bool) & np.isfinite(thr).all(axis=1)
    return row(path, *window_stats(thr, ok))


def dataset_rows(path: str) -> list[str]:
    d = np.load(path, allow_pickle=True)
    names = list(map(str, d["channel_names"]))
    cols = [names.index(f"thr{k}") for k in range(1, 5)]
    first = int(round(10.0 / float(d["time"][1] - d["time"][0])))
    out = []
    for m, mission in enumerate(map(str, d["mission_names"])):
        sds, acs = [], []
        for i in np.flatnonzero((d["fault_class"] == 0) & (d["mission_type"] == m)):
            thr = d["telemetry"][i][:, cols].astype(np.float64)
            ok = (thr.mean(axis=1) > 0.05) & np.isfinite(thr).all(axis=1)
            ok[:first] = False
            sd, ac = window_stats(thr, ok)
            sds.append(sd)
            acs.append(ac)
        if sds:
            out.append(row(f"simulated healthy, {mission} ({len(sds)} flights)", np.concatenate(sds), np.concatenate(acs)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", help="a simulated dataset.npz: its healthy flights by mission type")
    ap.add_argument("flights", nargs="*", help="ingested flight.npz files")
    args = ap.parse_args()
    print(f"| flight | windows | within-window share std, median | p90 | autocorrelation at lag {', '.join(map(str, LAGS))} |")
    print("|---|---|---|---|---|")
    for f in args.flights:
        print(real_flight(f))
    if args.dataset:
        print("\n".join(dataset_rows(args.dataset)))


if __name__ == "__main__":
    main()
