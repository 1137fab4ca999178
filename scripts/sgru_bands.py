"""Where in the flight and on which class the streaming GRU trails the windowed one (docs/training.md
"10 s segments"): window-argmax macro F1 per band of window-end time and F1 per class, on one split of a
pooled run folder (scripts/pool_predictions.py), train seeds averaged per window.

    python scripts/sgru_bands.py /tmp/sgru6/pool --models gru,sgru,cnode [--split 1] [--band 15]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from sklearn.metrics import f1_score


def _averaged(pred_dir: Path, model: str, sim: int, split: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    sets = sorted(pred_dir.glob(f"{model}_sim{sim}_train*.npz"))
    if not sets:
        return None
    zs = [np.load(p) for p in sets]
    sel = zs[0]["split"] == split
    proba = np.mean([z["proba"][sel] for z in zs], axis=0)
    return zs[0]["y_true"][sel], proba.argmax(1), zs[0]["t_end"][sel]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--models", default="gru,sgru")
    ap.add_argument("--split", type=int, default=1, help="split code (1 = validation)")
    ap.add_argument("--band", type=float, default=15.0, help="band width, s of window-end time")
    args = ap.parse_args(argv)
    for model in args.models.split(","):
        for sim in (0, 1):
            got = _averaged(args.run / "predictions", model, sim, args.split)
            if got is None:
                continue
            y, yp, t = got
            k = list(range(int(max(y.max(), yp.max())) + 1))
            edges = np.arange(0.0, float(t.max()) + args.band, args.band)
            bands = [f1_score(y[b], yp[b], labels=k, average="macro", zero_division=0)
                     for b in ((t >= lo) & (t < lo + args.band) for lo in edges[:-1]) if b.any()]
            per_class = f1_score(y, yp, labels=k, average=None, zero_division=0)
            print(f"{model:14s} sim {sim}  macro F1 by {args.band:g} s band: " + " ".join(f"{f:.3f}" for f in bands)
                  + "  | per class: " + " ".join(f"{f:.3f}" for f in per_class))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
