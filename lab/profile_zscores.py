"""A real flight's profile inputs against a simulated suite's training flights: z-scores per channel.

    python lab/profile_zscores.py PROFILE DATASET.npz LOG [LOG ...]

For each log (ingested on the fly, as `quadfdi detect` does), the mean of each profile channel over
its decided samples (after the hover freeze, every channel backed) against the training split of
DATASET (the same profile applied by models.inputs, samples after each flight's freeze): z over
all training flights and over the healthy ones, and the ratio of the log's within-flight standard
deviation to the healthy flights' median within-flight standard deviation. Prints a markdown table.
"""

from __future__ import annotations

import sys

import numpy as np

from quadfdi.detect.inputs import flight_inputs, read_flight
from quadfdi.formats.dataset import load_dataset
from quadfdi.models.inputs import profiled_dataset


def train_samples(dataset: str, profile: str) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    ds = profiled_dataset(load_dataset(dataset), profile)
    x, split, cls, freeze = ds["telemetry"], ds["split"], ds["fault_class"], ds["hover_freeze"]
    keep = np.flatnonzero(split == 0)
    after = np.arange(x.shape[1])[None, :] >= freeze[keep][:, None]
    return list(map(str, ds["channel_names"])), x[keep], after, cls[keep] == 0


def main(argv: list[str]) -> int:
    if len(argv) < 3:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    profile, dataset, logs = argv[0], argv[1], argv[2:]
    names, x, after, healthy = train_samples(dataset, profile)
    flat_all = x[after]
    flat_h = x[after & healthy[:, None]]
    std_h = np.median([np.nanstd(f[a], axis=0) for f, a, h in zip(x, after, healthy) if h and a.any()], axis=0)
    for log in logs:
        fi = flight_inputs(read_flight(log), profile, 80, 20)
        s = fi.x[fi.used & (np.arange(len(fi.x)) >= fi.hover.freeze)]
        print(f"\n{fi.name}: {len(s)} samples after the hover freeze\n")
        print("| channel | flight mean | training mean ± std (all) | z all | z healthy | std ratio (healthy) |")
        print("|---|---|---|---|---|---|")
        for j, n in enumerate(names):
            m, sd = np.nanmean(s[:, j]), np.nanstd(s[:, j])
            za = (m - np.nanmean(flat_all[:, j])) / np.nanstd(flat_all[:, j])
            zh = (m - np.nanmean(flat_h[:, j])) / np.nanstd(flat_h[:, j])
            print(f"| `{n}` | {m:.3f} | {np.nanmean(flat_all[:, j]):.3f} ± {np.nanstd(flat_all[:, j]):.3f} | "
                  f"{za:+.1f} | {zh:+.1f} | {sd / std_h[j]:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
