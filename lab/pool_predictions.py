"""Assemble an evaluation run folder from prediction sets of several runs, so that ``quadfdi evaluate``
pools simulator seeds and compares models trained in different folders (e.g. streaming GRUs
trained in their own folders beside the windowed networks of runs/realistic).

    python lab/pool_predictions.py OUT --config CONFIG.toml \
        --dataset 0=runs/realistic/dataset.npz --dataset 1=runs/realistic/sims/seed1/dataset.npz \
        --set gru:0:0=runs/realistic/predictions/gru_sim0_train0.npz ... [--set MODEL:SIM:TRAIN=PATH ...]

OUT gets ``config.toml`` (a copy of CONFIG), the datasets as symbolic links (the first sim seed at
``dataset.npz``, the others at ``sims/seed<S>/dataset.npz``, as ``quadfdi study`` lays them out), every
prediction set copied to ``predictions/<model>_sim<S>_train<T>.npz`` (a MODEL may be a new name, e.g.
``sgru_onset``, to evaluate a variant beside the default) and its index entry. The sets are checked
against the datasets by ``quadfdi evaluate`` itself. OUT must not exist.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.predictions import add_entries, check_prediction_set
from quadfdi.train.predsets import index_entry, relative_prediction_path


def _parse_set(spec: str) -> tuple[str, int, int, Path]:
    try:
        key, path = spec.split("=", 1)
        model, sim, train = key.split(":")
        return model, int(sim), int(train), Path(path)
    except ValueError:
        raise QuadfdiError(f"--set {spec!r}: expected MODEL:SIM:TRAIN=PATH") from None


def pool(out: Path, config: Path, datasets: dict[int, Path], sets: list[tuple[str, int, int, Path]]) -> Path:
    """Write the folder of the module docstring; returns the index path."""
    import numpy as np

    if out.exists():
        raise QuadfdiError(f"{out} exists: pool into a new folder")
    first = min(datasets)
    rel = {s: "dataset.npz" if s == first else f"sims/seed{s}/dataset.npz" for s in datasets}
    out.mkdir(parents=True)
    shutil.copyfile(config, out / "config.toml")
    for s, path in datasets.items():
        (out / rel[s]).parent.mkdir(parents=True, exist_ok=True)
        (out / rel[s]).symlink_to(path.resolve())
    entries = []
    for model, sim, train, path in sets:
        if sim not in datasets:
            raise QuadfdiError(f"--set {model}:{sim}:{train}: no --dataset {sim}=PATH given")
        with np.load(path, allow_pickle=False) as z:
            check_prediction_set({k: z[k] for k in z.files}, str(path))
        dst = out / relative_prediction_path(model, sim, train)
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, dst)
        entries.append(index_entry(model, sim, train, dataset=rel[sim]))
    return add_entries(out, entries)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--config", type=Path, required=True)
    ap.add_argument("--dataset", action="append", default=[], help="SIM=PATH, one per simulator seed")
    ap.add_argument("--set", action="append", default=[], help="MODEL:SIM:TRAIN=PATH, one per prediction set")
    args = ap.parse_args(argv)
    datasets = {int(k): Path(v) for k, v in (d.split("=", 1) for d in args.dataset)}
    print(f"wrote {pool(args.out, args.config, datasets, [_parse_set(s) for s in args.set])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
