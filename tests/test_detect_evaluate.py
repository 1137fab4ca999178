"""``quadfdi detect`` on a flight of the realistic test set reproduces the
alarms of the evaluation (start, end, class, motor), on the session's tiny flightlog-min export."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from quadfdi.formats.export_folder import Export
from quadfdi.evaluate.alarms import flight_alarms
from quadfdi.evaluate.load import load_run
from tests.conftest import quadfdi


def _key(alarms: list[dict]) -> list[tuple]:
    return [(a["start_s"], a["end_s"], a["class"], a["motor"]) for a in alarms]


@pytest.fixture(scope="module")
def detected(flightlog_export, tmp_path_factory):
    """detect on the test flight whose evaluation alarms are the most (a fault flight on ties)."""
    run = flightlog_export.parent
    sets, infos = load_run(run)
    fl = next(s for s in sets if s.model == "cnode")
    info = infos[fl.dataset]
    pol = Export.open(flightlog_export).policy("cnode")[0]  # detect's default net
    test = np.flatnonzero(fl.split == info.split_names.index("test"))
    row = max(test, key=lambda r: (len(flight_alarms(fl, pol, r)), info.arrays["fault_class"][fl.rows[r]] > 0, -r))
    out = tmp_path_factory.mktemp("detect_eval")
    res = quadfdi("detect", "--model", str(flightlog_export), "--dataset", str(run / "dataset.npz"), "--flight",
                  str(fl.rows[row]), "--out", str(out))
    assert res.returncode == 0, res.stderr
    with np.load(out / "windows.npz") as z:
        win = {k: z[k] for k in z.files}
    return fl, int(row), pol, json.loads((out / "alarms.json").read_text()), win


def test_detect_reproduces_the_evaluations_alarms(detected):
    fl, row, pol, rec, win = detected
    w = int(fl.valid[row].sum())
    assert np.array_equal(win["t_end"], fl.t_end[row, :w])  # the same window grid
    dec = win["decided"]
    # ONNX Runtime fp32 (detect) against PyTorch (the prediction set): the export's own parity bound
    assert np.abs(win["proba"][dec] - fl.proba[row, :w][dec]).max() < 1e-4
    assert np.abs(win["motor_proba"][dec] - fl.motor[row, :w][dec]).max() < 1e-4
    assert _key(flight_alarms(fl, pol, row)) == _key(rec["alarms"])
    assert rec["alarms"], "the chosen flight should have an alarm (otherwise this compares two empty lists)"


def test_evaluations_alarm_code_on_detects_predictions_is_detect(detected):
    fl, row, pol, rec, win = detected
    w, dec = len(win["t_end"]), win["decided"]
    one = fl.subset(np.arange(len(fl.rows)) == row)
    healthy = one.class_names.index("Healthy")
    proba = np.where(dec[:, None], np.nan_to_num(win["proba"].astype(np.float64)), 0.0)
    proba[~dec, healthy] = 1.0
    motor = np.where(dec[:, None], np.nan_to_num(win["motor_proba"].astype(np.float64)), 0.0)
    mine = replace(one, proba=proba[None], motor=motor[None], valid=np.ones((1, w), bool), decided=dec[None],
                   t_end=win["t_end"][None], y_true=one.y_true[:, :w])
    got = flight_alarms(mine, pol, 0)
    assert _key(got) == _key(rec["alarms"])
    # windows.npz holds proba as float32, detect's alarms were computed on its float64 softmax
    assert [a["peak_p_fault"] for a in got] == pytest.approx([a["peak_p_fault"] for a in rec["alarms"]], abs=1e-6)
