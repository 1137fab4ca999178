"""Window-level motor localisation of every indexed prediction set that carries ``motor_proba``.

On the windows of one split whose label is a rotor-side class (models.motor.ROTOR_SIDE_CLASSES,
by name) of a flight with a known motor (dataset ``fault_motor`` >= 0): the share whose argmax
of ``motor_proba`` is that motor, independent of the class decision and of any alarm (the alarm-
level figure is evaluation.md's "motor right"). A network's motor_proba is its motor head's; the
baselines' is the physics rule of train.baselines_jobs.suspected_motor (the rotor with the highest
window-mean command over the mean of the four). Interval: percentile bootstrap over flights
(evaluate.bootstrap.draw_weights, same replicates for every set). Chance is 0.25.

    python -m quadfdi.evaluate.localisation --run RUN [--split test] [--replicates 2000] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from quadfdi.core.alarm import ROTOR_SIDE_CLASSES
from quadfdi.formats.predictions import read_index
from quadfdi.core.tables import md_table
from quadfdi.evaluate.bootstrap import draw_weights

ROTOR_SIDE = ROTOR_SIDE_CLASSES  # models.motor.ROTOR_SIDE_CLASSES (no torch here)


def flight_counts(arrays: dict, fault_motor: np.ndarray, split: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per flight of ``split`` with rotor-side windows: (dataset rows, windows scored, windows right)."""
    names = [str(c) for c in arrays["class_names"]]
    rotor = np.array([n in ROTOR_SIDE for n in names])
    traj = arrays["traj"].astype(np.int64)
    motor = fault_motor[traj].astype(np.int64)
    keep = (arrays["split"] == split) & rotor[arrays["y_true"].astype(np.int64)] & (motor >= 0)
    right = np.argmax(arrays["motor_proba"], axis=1) == motor
    rows = np.unique(traj[keep])
    n = np.array([np.sum(keep & (traj == r)) for r in rows], np.float64)
    ok = np.array([np.sum(keep & right & (traj == r)) for r in rows], np.float64)
    return rows, n, ok


def localisation(run: Path, split: int = 2, replicates: int = 2000, seed: int = 0) -> list[dict]:
    """One record per indexed set with motor_proba: model, flights, windows, accuracy, lo, hi, source."""
    out = []
    cache: dict[str, np.ndarray] = {}
    for e in read_index(run):
        arrays = dict(np.load(run / e["predictions"]))
        if "motor_proba" not in arrays:
            continue
        if e["dataset"] not in cache:
            with np.load(run / e["dataset"]) as ds:
                cache[e["dataset"]] = ds["fault_motor"]
        rows, n, ok = flight_counts(arrays, cache[e["dataset"]], split)
        w = draw_weights([(e["dataset"], int(r)) for r in rows], replicates, seed)
        reps = (w @ ok) / np.maximum(w @ n, 1)
        lo, hi = np.percentile(reps, [2.5, 97.5])
        out.append({"model": e["model"], "sim_seed": e["sim_seed"], "train_seed": e["train_seed"],
                    "flights": int(rows.size), "windows": int(n.sum()), "accuracy": float(ok.sum() / max(n.sum(), 1)),
                    "lo": float(lo), "hi": float(hi),
                    "source": "motor head" if e["model"].split("_")[0] in ("cnode", "gru") else "physics rule"})
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m quadfdi.evaluate.localisation", description=__doc__.splitlines()[0])
    p.add_argument("--run", required=True)
    p.add_argument("--split", type=int, default=2, help="split code (0 train, 1 validation, 2 test, 3.. OOD)")
    p.add_argument("--replicates", type=int, default=2000)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    recs = localisation(Path(a.run), a.split, a.replicates, a.seed)
    rows = [[r["model"], r["source"], r["sim_seed"], r["flights"], r["windows"],
             f"{r['accuracy']:.3f} [{r['lo']:.3f}, {r['hi']:.3f}]"] for r in recs]
    print("\n".join(md_table(["model", "motor from", "sim seed", "flights", "rotor-side windows",
                              "localisation accuracy, 95 % flight bootstrap"], rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
