"""``quadfdi sweep --dataset-from RUN``: the points train on RUN's published dataset, simulate nothing."""

from __future__ import annotations

import json

from tests.conftest import ROOT, SMALL_SIM, quadfdi

TINY_TRAIN = ["--set", "train.epochs=1", "--set", "train.latent=4", "--set", "train.hidden=8", "--set",
              "train.gru_hidden=8", "--set", "train.steps=2"]


def _sweep(small_run, out, *extra: str):
    return quadfdi("sweep", "--config", str(ROOT / "configs/paper.toml"), *SMALL_SIM, *TINY_TRAIN,
                   "--grid", "train.dropout_latent=0.3", "--metrics", "history.cnode.val_macro_f1,history.gru.best_epoch",
                   "--workers", "1", "--out", str(out), *extra)


def test_points_reuse_the_runs_dataset(small_run, tmp_path):
    out = tmp_path / "sweep"
    res = _sweep(small_run, out, "--stages", "train", "--dataset-from", str(small_run))
    assert res.returncode == 0, res.stderr
    row, = json.loads((out / "sweep.json").read_text())["rows"]
    assert row["status"] == "done" and 0.0 <= row["metrics"]["history.cnode.val_macro_f1"] <= 1.0
    assert row["metrics"]["history.gru.best_epoch"] == 0  # one epoch: the only one
    point = out / "points" / row["point"]
    assert (point / "dataset.npz").stat().st_ino == (small_run / "dataset.npz").stat().st_ino  # a hard link
    assert (point / "metrics.json").is_file() and not (out / "cache" / "sim").exists()


def test_refusals_are_one_line(small_run, tmp_path):
    res = _sweep(small_run, tmp_path / "a", "--stages", "train")
    assert res.returncode == 2 and "--dataset-from RUN" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    res = _sweep(small_run, tmp_path / "b", "--stages", "train", "--dataset-from", str(small_run), "--set", "sim.seed=7")
    assert res.returncode == 2 and "was simulated with sim.seed=0" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_another_windowing_gets_one_rewindowed_copy(small_run, tmp_path):
    out = tmp_path / "sweep"
    res = quadfdi("sweep", "--config", str(ROOT / "configs/paper.toml"), *SMALL_SIM, *TINY_TRAIN,
                  "--set", "train.model=cnode", "--set", "train.outputs=fit", "--grid", "sim.window=40,80",
                  "--grid", "train.seed=0,1", "--metrics", "history.cnode.val_macro_f1", "--workers", "1",
                  "--out", str(out), "--stages", "train", "--dataset-from", str(small_run))
    assert res.returncode == 0, res.stderr
    rows = json.loads((out / "sweep.json").read_text())["rows"]
    assert len(rows) == 4 and all(r["status"] == "done" for r in rows)
    copies = list((out / "datasets").glob("*/dataset.npz"))
    assert [c.parent.name for c in copies] == ["window40_stride10"]  # 80: the run's own windowing, linked
    import numpy as np

    from quadfdi.formats.dataset import load_dataset

    ds, src = load_dataset(copies[0]), load_dataset(small_run / "dataset.npz")
    assert ds.config.sim.window == 40 and src.config.sim.window == 80
    assert np.array_equal(ds["telemetry"], src["telemetry"])
    for r in rows:  # every point trained on windows of its own length; "fit": no prediction sets
        point = out / "points" / r["point"]
        assert load_dataset(point / "dataset.npz").config.sim.window == int(r["values"]["sim.window"])
        assert not list(point.glob("predictions/*.npz"))
