"""Epoch time per network on a dataset, one thread: `python lab/train_epoch_time.py <dataset.npz> <n_train_windows> [cnode,gru]`
(docs/training.md, "The realistic suite")."""
import sys, time
import numpy as np, torch
from quadfdi.core.config import replace_section
from quadfdi.formats.dataset import load_dataset, class_names, make_windows
from quadfdi.train.data import capped_train_windows, class_weights, fit_normalisation
from quadfdi.train.loop import train_model, predict_proba
from quadfdi.models.networks import build_model

ds = load_dataset(sys.argv[1]); n = int(sys.argv[2]); kinds = sys.argv[3].split(",") if len(sys.argv) > 3 else ["cnode", "gru"]
cfg = ds.config
torch.set_num_threads(1)
tcfg = replace_section(cfg, "train", epochs=1).train
K = len(class_names(ds.arrays))
t0 = time.perf_counter(); tr = capped_train_windows(ds, n, 0); val = make_windows(ds, "validation")
print(f"windows: train {len(tr)} (cap {n}), validation {len(val)}; gather {time.perf_counter()-t0:.1f} s; K={K}", flush=True)
mean, std = fit_normalisation(ds)
for kind in kinds:
    torch.manual_seed(0)
    m = build_model(kind, ds.n_channels, tcfg, window=cfg.sim.window, n_classes=K); m.set_normalisation(mean, std)
    h = train_model(m, tr, val, tcfg, class_weights(tr.y, K), log=lambda s: None)
    t1 = time.perf_counter(); predict_proba(m, val.x); pv = time.perf_counter() - t1
    print(f"{kind}: epoch (train part) {h.epoch_s[0]:.1f} s for {len(tr)} windows = {1e3*h.epoch_s[0]/len(tr):.2f} ms/window; "
          f"validation predict {pv:.1f} s for {len(val)} windows = {1e3*pv/len(val):.2f} ms/window", flush=True)
