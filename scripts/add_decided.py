"""Add ``decided`` to prediction sets written before train/predsets.py wrote it (the same rule,
models.inputs.decided): PYTHONPATH=. python scripts/add_decided.py RUN PROFILE"""
import sys
from pathlib import Path

import numpy as np

from quadfdi.formats.predictions import read_index
from quadfdi.formats.dataset import load_dataset
from quadfdi.train.predsets import write_prediction_set
from quadfdi.models.inputs import decided, profiled_dataset

run = Path(sys.argv[1]); profile = sys.argv[2]
ds = profiled_dataset(load_dataset(run / "dataset.npz"), profile)
dt, w = float(ds.config.sim.sample_dt_s), int(ds.config.sim.window)
for e in read_index(run):
    p = run / e["predictions"]
    with np.load(p) as z:
        a = {k: z[k] for k in z.files}
    if "decided" in a or e["model"] not in ("cnode", "gru"):
        continue
    start = np.rint(a["t_end"] / dt).astype(np.int64) - w + 1
    a["decided"] = decided(ds, a["traj"], start)
    write_prediction_set(p, a)
    print(p, int((~a["decided"]).sum()), "of", len(start), "windows before the freeze")
