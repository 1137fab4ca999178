"""The two alarm-motor rules on validation (docs/detect.md "Which motor"):
A = core.alarm (summed motor_proba over the alarm's voting windows, rotor-side alarm class only),
B = the alternative (mean motor_proba over the alarm's active windows whose own fault class is
rotor-side, rotor-side alarm class only). Both read at the window evaluate scores (the first active
window at or after onset) for detected rotor-side fault flights with a known motor.

Usage: python lab/motor_rules.py RUN [SPLIT]   (SPLIT defaults to validation)"""
import sys
from pathlib import Path

import numpy as np

from quadfdi.core.alarm import AlarmConfig, reported_motor, rotor_columns
from quadfdi.evaluate.alarms import set_trace
from quadfdi.evaluate.load import load_run

run, split = Path(sys.argv[1]), sys.argv[2] if len(sys.argv) > 2 else "validation"
pol = dict(AlarmConfig().__dict__)
sets, infos = load_run(run)
for fl in sets:
    if fl.motor is None:
        continue
    info = infos[fl.dataset]
    fl = fl.subset(fl.split == info.split_names.index(split))
    rotor = rotor_columns(fl.class_names)
    healthy = fl.class_names.index("Healthy")
    tr = set_trace(fl, pol)
    onset = np.nan_to_num(info.arrays["onset_s"][fl.rows], nan=np.inf)
    motor = info.arrays["fault_motor"][fl.rows].astype(int)
    a_ok = b_ok = n = 0
    for f in range(len(fl.rows)):
        hit = np.flatnonzero(tr.active[f] & (np.nan_to_num(fl.t_end[f], nan=-np.inf) >= onset[f]))
        if motor[f] < 0 or hit.size == 0:
            continue
        i = hit[0]
        n += 1
        a_ok += int(reported_motor(tr.cls[f, i], tr.motor[f, i], rotor) == motor[f])
        start = np.flatnonzero(tr.raised[f, :i + 1])[-1]
        p = np.where(np.isfinite(fl.proba[f]), fl.proba[f], -np.inf).copy(); p[:, healthy] = -np.inf
        wcls = p.argmax(axis=1)
        keep = tr.active[f, start:i + 1] & rotor[wcls[start:i + 1]]
        b = int(np.argmax(fl.motor[f, start:i + 1][keep].mean(axis=0))) if keep.any() and rotor[tr.cls[f, i]] else -1
        b_ok += int(b == motor[f])
    print(f"{fl.model} train seed {fl.train_seed} ({split}): {n} detected rotor-side flights; motor right: "
          f"core.alarm sum {a_ok} ({a_ok / max(n, 1):.3f}), mean over rotor-side windows {b_ok} ({b_ok / max(n, 1):.3f})")
