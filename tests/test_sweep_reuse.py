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
