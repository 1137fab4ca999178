"""Mean fault probability 1 - p(Healthy) of a run's prediction sets on windows labelled Healthy.

    PYTHONPATH=. python scripts/healthy_pfault.py RUN [--split validation]

For each prediction set of RUN/predictions/index.json: its decided windows labelled Healthy in the
split (the dataset's split names: train, validation, test, ...), their count, and the mean and
median of 1 - p(Healthy). What a real healthy flight's p(fault) (scripts/real_occlusion.py, row
"none") is compared with in docs/detect.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from quadfdi.formats.predictions import read_index
from quadfdi.formats.dataset import load_dataset, split_names


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--split", default="validation")
    args = ap.parse_args()
    print("| model | sim seed | train seed | healthy windows | mean p(fault) | median |")
    print("|---|---|---|---|---|---|")
    for e in read_index(args.run):
        names = split_names(load_dataset(args.run / e["dataset"]).arrays)
        if args.split not in names:
            raise SystemExit(f"{e['dataset']}: no split {args.split!r} ({', '.join(names)})")
        d = np.load(args.run / e["predictions"], allow_pickle=False)
        h = [str(c) for c in d["class_names"]].index("Healthy")
        sel = (d["y_true"] == h) & d["decided"] & (d["split"] == names.index(args.split))
        pf = 1.0 - d["proba"][sel, h]
        print(f"| {e['model']} | {e['sim_seed']} | {e['train_seed']} | {int(sel.sum())} | {pf.mean():.2f} | {np.median(pf):.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
