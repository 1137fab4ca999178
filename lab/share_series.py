"""What lab/forward_flight_shares.py and lab/yaw_trim_shares.py share: the 1 s mean of a
per-sample series over the usable samples, and their command line (ingested flights and simulated
datasets in, one markdown table out). Imported as a sibling module (``python lab/X.py`` puts
lab/ on the path)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np

SMOOTH = 25  # samples: 1 s at 25 Hz


def smooth(v: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """The mean of ``v`` over the usable samples ``ok`` in a centred 1 s box (NaN-free where any is)."""
    k = np.ones(SMOOTH) / SMOOTH
    num = np.convolve(np.where(ok, v, 0.0), k, mode="same")
    den = np.convolve(ok.astype(float), k, mode="same")
    return num / np.maximum(den, 1e-9)


def table_cli(doc: str, header: str, real_row: Callable[[str], str], dataset_row: Callable[[str], str]) -> None:
    """Parse ``[--dataset D ...] [FLIGHT.npz ...]`` and print the header (its column count sets the
    separator), one row per flight, then one per dataset."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--dataset", action="append", default=[], help="a simulated dataset.npz (repeatable)")
    ap.add_argument("flights", nargs="*", help="ingested flight.npz files")
    args = ap.parse_args()
    print(header)
    print("|" + "---|" * (header.count("|") - 1))
    for f in args.flights:
        print(real_row(f))
    for f in args.dataset:
        print(dataset_row(f))
