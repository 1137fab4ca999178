"""The prediction-set index (formats.predictions): entries replace by key, bad sets are refused."""

import numpy as np
import pytest

from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.predictions import add_entries, check_prediction_set, prediction_path, read_index


def _set(n=3, k=5, split=1):
    p = np.full((n, k), 1.0 / k, np.float32)
    return {"proba": p, "y_true": np.zeros(n, np.int64), "traj": np.arange(n), "t_end": np.arange(n, dtype=float),
            "split": np.full(n, split, np.int8), "class_names": np.array([f"c{i}" for i in range(k)])}


def test_entries_replace_by_key(tmp_path):
    assert read_index(tmp_path) == []
    e = {"model": "cnode", "sim_seed": 0, "train_seed": 1, "dataset": "dataset.npz", "predictions": "p/a.npz"}
    add_entries(tmp_path, [e, dict(e, model="gru")])
    add_entries(tmp_path, [dict(e, predictions="p/b.npz")])
    got = read_index(tmp_path)
    assert [(x["model"], x["predictions"]) for x in got] == [("cnode", "p/b.npz"), ("gru", "p/a.npz")]
    assert prediction_path(tmp_path, "gru", 1, 2).name == "gru_sim1_train2.npz"
    with pytest.raises(ValueError):
        add_entries(tmp_path, [dict(e, dataset=str(tmp_path / "x.npz"))])


def test_check_prediction_set():
    check_prediction_set(_set(), "ok")
    bad = _set()
    bad["proba"] = bad["proba"][:, :4]
    with pytest.raises(QuadfdiError, match="expected \\(n, 5\\)"):
        check_prediction_set(bad, "x")
    with pytest.raises(QuadfdiError, match="training windows"):
        check_prediction_set(_set(split=0), "x")
    with pytest.raises(QuadfdiError, match="lacks split"):
        check_prediction_set({k: v for k, v in _set().items() if k != "split"}, "x")
