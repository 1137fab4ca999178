"""The hover estimate without a pitch channel (core.hover, docs/profiles.md "The masked profile"): a
log that lacks pitch enters the steady test with pitch 0 (level). How much that changes the frozen
estimate: each flight's estimate with its logged pitch against the same with pitch set to 0.

    python lab/hover_without_pitch.py DATASET.npz [LOG ...]

DATASET.npz: a realistic-suite dataset (its first 8 flights: simulated, airborne throughout); LOG:
real flights (.ulg, .BIN or flight.npz; ingested on the fly). One line per flight: freeze sample and
cmd with pitch, without, and the relative change of cmd.
"""

from __future__ import annotations

import sys

import numpy as np

from quadfdi.core import hover
from quadfdi.formats.dataset import load_dataset

FLIGHTS = 8


def compare(name: str, cols: np.ndarray, airborne: np.ndarray | None) -> bool:
    """One line; True when the estimate and its freeze sample are identical without pitch."""
    level = cols.copy()
    level[:, hover.INPUTS.index("pitch")] = 0.0
    a, b = hover.estimate(cols, airborne), hover.estimate(level, airborne)
    rel = float(abs(b.cmd - a.cmd) / a.cmd) if a.ok and b.ok else float("nan")
    same = a.freeze == b.freeze and a.cmd == b.cmd
    print(f"{name}: freeze {a.freeze} -> {b.freeze}, cmd {a.cmd:.6f} -> {b.cmd:.6f} ({100 * rel:.2f} %)"
          f"{'  identical' if same else ''}")
    return same


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 1
    ds = load_dataset(argv[0])
    names = ds.channel_names
    same = []
    for i in range(FLIGHTS):
        cols = ds["telemetry"][i][:, [names.index(c) for c in hover.INPUTS]]
        same.append(compare(f"{argv[0]}#{i}", cols, None))
    from quadfdi.detect.inputs import read_flight

    for log in argv[1:]:
        a = read_flight(log)
        flight = [str(n) for n in a["channel_names"]]
        cols = np.stack([a["telemetry"][:, flight.index(c)] for c in hover.INPUTS], axis=1).astype(np.float32)
        same.append(compare(log, cols, np.asarray(a["airborne"], bool)))
    print(f"identical on {sum(same)} of {len(same)} flights")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
