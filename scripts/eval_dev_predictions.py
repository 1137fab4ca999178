"""Development prediction sets for ``quadfdi evaluate`` before the real producers land (NOT a baseline).

A multinomial logistic regression on per-window mean / slope / std (train/baseline.py's features)
of a realistic dataset, fitted on half of the training windows (the half drawn by the train seed),
at C = 1 (``dev_logreg``) and C = 5e-4 (``dev_logreg_weak``); ``motor_proba`` = softmax(60 x each
motor command over the four's mean, last 20 samples of the window). Written with formats.predictions.

    PYTHONPATH=. python scripts/eval_dev_predictions.py RUN 0=dataset.npz [1=sim1/dataset.npz ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from quadfdi.core.npzio import write_npz
from quadfdi.formats.predictions import add_entries, prediction_path
from quadfdi.formats.dataset import class_names, load_dataset, make_windows, split_names
from quadfdi.train.baseline import window_features

MODELS = {"dev_logreg": 1.0, "dev_logreg_weak": 5e-4}


def _motor(x: np.ndarray, cols: list[int]) -> np.ndarray:
    thr = x[:, -20:, cols].mean(axis=1).astype(np.float64)
    z = 60.0 * (thr - thr.mean(axis=1, keepdims=True))
    z = np.exp(z - z.max(axis=1, keepdims=True))
    return (z / z.sum(axis=1, keepdims=True)).astype(np.float32)


def sets_of(ds) -> list[tuple]:
    names = split_names(ds.arrays)
    cols = [ds.channel_names.index(f"thr{i}") for i in range(1, 5)]
    out = []
    for s in names[1:]:
        if (ds["split"] == names.index(s)).any():
            w = make_windows(ds, s)
            out.append((w, window_features(w.x.astype(np.float64)), _motor(w.x, cols)))
    return out


def main(run: Path, items: list[str]) -> None:
    entries = []
    for item in items:
        seed, rel = item.split("=")
        ds = load_dataset(run / rel)
        tr = make_windows(ds, "train")
        xtr = window_features(tr.x.astype(np.float64))
        evals = sets_of(ds)
        for model, c in MODELS.items():
            for ts in (0, 1):
                sub = np.random.default_rng(ts).choice(len(tr.y), size=len(tr.y) // 2, replace=False)
                clf = make_pipeline(StandardScaler(), LogisticRegression(C=c, max_iter=500, class_weight="balanced"))
                clf.fit(xtr[sub], tr.y[sub])
                k = len(class_names(ds.arrays))
                parts = []
                for w, x, m in evals:
                    p = np.zeros((len(w.y), k), np.float32)
                    p[:, clf.classes_] = clf.predict_proba(x)
                    parts.append({"proba": p, "y_true": w.y, "traj": w.traj, "t_end": w.t_end,
                                  "split": ds["split"][w.traj].astype(np.int8), "motor_proba": m})
                arr = {key: np.concatenate([pp[key] for pp in parts]) for key in parts[0]}
                arr["class_names"] = np.array(class_names(ds.arrays))
                path = prediction_path(run, model, int(seed), ts)
                path.parent.mkdir(parents=True, exist_ok=True)
                write_npz(path, arr)
                entries.append({"model": model, "sim_seed": int(seed), "train_seed": ts, "dataset": rel,
                                "predictions": str(path.relative_to(run))})
                print(f"{model} sim {seed} train {ts}: {path}", flush=True)
    add_entries(run, entries)


if __name__ == "__main__":
    main(Path(sys.argv[1]), sys.argv[2:])
