"""Validation macro F1 of streaming networks (the streaming GRU ``sgru_train<T>.pt``, the streaming CNODE
``scnode_train<T>.pt``) at the validation windows' ends (what training selects on) and at every sample
(the stream's decision at each 25 Hz sample), each stream started from zero at take-off on every
validation flight, the streaming CNODE on its checkpoint's profile (each flight under its own mask
pattern for a masked profile).

    python lab/stream_val_f1.py RUN/sgru_train0.pt RUN/scnode_train0.pt ...   (dataset.npz beside each)
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from sklearn.metrics import f1_score

from quadfdi.core.contracts import SPLIT_VALIDATION
from quadfdi.formats.dataset import load_dataset
from quadfdi.models.inputs import profile_of, profiled_dataset
from quadfdi.train.stream_gru_fit import step_labels, window_end_index


def scores(ckpt: Path) -> dict:
    if ckpt.name.startswith("scnode"):
        from quadfdi.train.stream_cnode_fit import stream_logits
        from quadfdi.train.stream_cnode_run import load_checkpoint
    else:
        from quadfdi.train.stream_gru_fit import stream_logits
        from quadfdi.train.stream_gru_run import load_stream_checkpoint as load_checkpoint
    model, blob = load_checkpoint(ckpt)
    ds = profiled_dataset(load_dataset(ckpt.parent / "dataset.npz"), profile_of(blob), patterns=True)
    rows = np.flatnonzero(np.asarray(ds["split"]) == SPLIT_VALIDATION)
    logits, y = stream_logits(model, ds["telemetry"][rows]), step_labels(ds, rows)
    ends, labels = window_end_index(ds), list(range(logits.shape[-1]))
    f1 = {name: float(f1_score(y[:, sel].ravel(), logits[:, sel].argmax(-1).ravel(), labels=labels, average="macro",
                               zero_division=0)) for name, sel in (("window_ends", ends), ("every_sample", slice(None)))}
    return {"checkpoint": str(ckpt), "profile": profile_of(blob), "flights": len(rows), "best_epoch":
            blob["history"]["best_epoch"] + 1, "val_macro_f1": {k: round(v, 4) for k, v in f1.items()}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("checkpoints", nargs="+", type=Path)
    for ckpt in ap.parse_args().checkpoints:
        print(json.dumps(scores(ckpt)))


if __name__ == "__main__":
    main()
