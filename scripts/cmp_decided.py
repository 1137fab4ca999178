"""Alarms of every evaluation flight with and without the prediction set's ``decided`` (docs/detect.md):
    PYTHONPATH=. python scripts/cmp_decided.py RUN   (RUN/export/manifest.json gives the policy)"""
import sys
from dataclasses import replace
from pathlib import Path

from quadfdi.formats.export_folder import Export
from quadfdi.evaluate.alarms import flight_alarms
from quadfdi.evaluate.load import load_run

run = Path(sys.argv[1])
pol = Export.open(run / "export").policy("cnode")[0]
sets, infos = load_run(run)
for fl in sets:
    if fl.decided is None: continue
    nod = replace(fl, decided=None)
    diff = sum(flight_alarms(fl, pol, r) != flight_alarms(nod, pol, r) for r in range(len(fl.rows)))
    print(fl.model, fl.train_seed, "flights", len(fl.rows), "whose alarms change when pre-freeze windows vote:", diff)
