"""Networks on the realistic suite: five classes from the data through training, the prediction
sets of every evaluation window, export and the C++ reference; the training-window cap; the seed
study over simulator seeds x training seeds (reuse of the train stage, index entries)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from quadfdi.core.config import load_config
from quadfdi.core.contracts import CLASS_NAMES
from quadfdi.formats.predictions import check_prediction_set, read_index
from quadfdi.formats.dataset import class_names, load_dataset, make_windows, split_names
from tests.conftest import ROOT, copy_run, quadfdi, trained_export_run
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)
from quadfdi.train.data import capped_train_windows, evaluation_rows

# A tiny suite, simulated in this process's order (--workers 1): every split code 0..6 present.
TINY = ["sim.n_traj=20", "sim.ood_traj=2", "sim.duration_s=12.0", "sim.chunk=14", "sim.window=40"]
TRAIN = ["train.epochs=1", "train.latent=8", "train.hidden=16", "train.gru_hidden=16", "train.max_train_windows=60"]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("realistic") / "tiny"
    res = quadfdi("sim", "--config", str(ROOT / "configs/realistic.toml"), "--out", str(out), "--workers", "1",
                  *[a for v in TINY for a in ("--set", v)])
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def exported(tiny, tmp_path_factory) -> Path:
    return trained_export_run(tiny, tmp_path_factory.mktemp("realistic_train") / "run", *TRAIN)


def test_five_classes_train_export_and_the_cpp_reference_reads_them(exported, host_build):  # noqa: F811
    names = list(class_names(load_dataset(exported / "dataset.npz").arrays))
    assert len(names) == 5 and names[0] == "Healthy" and names != list(CLASS_NAMES)
    for kind in ("cnode", "gru"):
        blob = torch.load(exported / f"{kind}.pt", weights_only=True)
        assert blob["class_names"] == names and blob["architecture"]["n_classes"] == 5
    metrics = json.loads((exported / "metrics.json").read_text())
    for model in ("cnode", "gru", "baseline"):
        assert list(metrics[model]["per_class"]) == names
    assert np.load(exported / "predictions_cnode.npz")["proba"].shape[1] == 5
    assert (exported / "figures" / "detection_propeller_traj{}.png".format(
        next(r for r in np.unique(make_windows(load_dataset(exported / "dataset.npz"), "test").traj)
             if load_dataset(exported / "dataset.npz")["fault_class"][r] == 4))).is_file()
    manifest = json.loads((exported / "export" / "manifest.json").read_text())
    assert manifest["class_names"] == names and manifest["io"]["outputs"][0]["shape"] == ["batch", 5]
    export = exported / "export"
    res = subprocess.run([str(host_build / "fwref_parity"), "--weights", str(export / "weights.bin"),
                          "--reference", str(export / "reference.bin")], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "all 18 tensors OK" in res.stdout


def test_prediction_sets_cover_every_evaluation_window(exported):
    ds = load_dataset(exported / "dataset.npz")
    entries = read_index(exported)
    assert {(e["model"], e["sim_seed"], e["train_seed"], e["dataset"]) for e in entries} == \
        {("cnode", 0, 0, "dataset.npz"), ("gru", 0, 0, "dataset.npz")}
    rows = evaluation_rows(ds)
    assert set(ds["split"][rows]) == set(range(1, len(split_names(ds.arrays))))  # validation, test, 4 OOD sets
    expect = [make_windows(ds, code) for code in range(1, len(split_names(ds.arrays)))]
    for e in entries:
        with np.load(exported / e["predictions"]) as z:
            pred = dict(z)
        check_prediction_set(pred, e["predictions"])
        assert pred["proba"].dtype == np.float32 and list(pred["class_names"]) == list(class_names(ds.arrays))
        # every evaluation window once, flight by flight in dataset order: the splits' windows, merged by row
        order = np.argsort(np.concatenate([w.traj for w in expect]), kind="stable")
        for key, attr in (("traj", "traj"), ("y_true", "y"), ("t_end", "t_end")):
            assert np.array_equal(pred[key], np.concatenate([getattr(w, attr) for w in expect])[order])
        assert np.array_equal(pred["split"], ds["split"][pred["traj"]])
        test = np.load(exported / f"predictions_{e['model']}.npz")  # the test split's, as before
        assert np.allclose(pred["proba"][pred["split"] == 2], test["proba"], atol=1e-6)


def test_the_cap_is_a_seeded_subsample_of_the_training_windows(tiny):
    ds = load_dataset(tiny / "dataset.npz")
    full = make_windows(ds, "train")
    assert len(capped_train_windows(ds, 0, 0)) == len(full)  # 0: every window
    assert len(capped_train_windows(ds, 10 ** 9, 0)) == len(full)
    a, b, c = (capped_train_windows(ds, 50, s) for s in (0, 0, 1))
    assert len(a) == 50 and np.array_equal(a.traj, b.traj) and np.array_equal(a.start, b.start)
    assert not (np.array_equal(a.traj, c.traj) and np.array_equal(a.start, c.start))
    keys = set(zip(full.traj.tolist(), full.start.tolist()))
    assert set(zip(a.traj.tolist(), a.start.tolist())) <= keys
    assert np.all(np.diff(a.traj * 10 ** 6 + a.start) > 0)  # dataset order, no repeats
    i = np.flatnonzero(full.traj == a.traj[0])[0] + np.flatnonzero(full.start[full.traj == a.traj[0]] == a.start[0])[0]
    assert np.array_equal(a.x[0], full.x[i]) and a.y[0] == full.y[i]


def test_realistic_config_fits_the_budget_settings():
    cfg = load_config(ROOT / "configs/realistic.toml")
    assert cfg.train.max_train_windows > 0 and load_config(ROOT / "configs/paper.toml").train.max_train_windows == 0


def test_study_over_sim_seeds_reuses_the_train_stage(exported, tmp_path):
    run = copy_run(exported, tmp_path / "run", names=("config.toml", "dataset.npz", ".stages/sim.json",
                                                      ".stages/train.json", "cnode.pt", "gru.pt", "metrics.json",
                                                      "history.json", "predictions/cnode_sim0_train0.npz",
                                                      "predictions/gru_sim0_train0.npz", "predictions_cnode.npz",
                                                      "predictions_gru.npz", "predictions/index.json"))
    for f in json.loads((exported / ".stages/train.json").read_text())["outputs"]:  # the figures too
        copy_run(exported, run, names=(f["path"],))
    res = quadfdi("train", "study", "--run", str(run), "--seeds", "0", "--sim-seeds", "0,1", "--workers", "1",
                  *[a for v in TRAIN for a in ("--set", v)])
    assert res.returncode == 0, res.stderr
    assert len(list((run / "cache" / "study").glob("*.npz"))) == 2  # sim seed 1 only: sim 0 came from train
    entries = {(e["model"], e["sim_seed"], e["train_seed"]): e for e in read_index(run)}
    assert set(entries) == {(m, s, 0) for m in ("cnode", "gru") for s in (0, 1)}
    assert entries[("gru", 1, 0)]["dataset"] == "sims/seed1/dataset.npz"
    ds1 = load_dataset(run / "sims/seed1/dataset.npz")
    assert ds1.config.sim.seed == 1 and len(class_names(ds1.arrays)) == 5
    with np.load(run / entries[("gru", 1, 0)]["predictions"]) as z:
        assert np.array_equal(z["traj"], np.concatenate([make_windows(ds1, int(c)).traj for c in (1, 2, 3, 4, 5, 6)])[
            np.argsort(np.concatenate([make_windows(ds1, int(c)).traj for c in (1, 2, 3, 4, 5, 6)]), kind="stable")])
    seeds = json.loads((run / "seeds.json").read_text())
    assert seeds["sim_seeds"] == [0, 1] and len(seeds["cnode"]["macro_f1"]) == 2
    check = quadfdi("check", "--run", str(run))
    assert check.returncode == 0, check.stderr


def test_index_entries_of_unpublished_sets_are_dropped(tmp_path):
    from quadfdi.formats.predictions import add_entries
    from quadfdi.train.predsets import drop_missing_entries, index_entry

    kept, gone = index_entry("cnode", 0, 1), index_entry("cnode", 0, 0)
    (tmp_path / kept["predictions"]).parent.mkdir(parents=True)
    (tmp_path / kept["predictions"]).write_bytes(b"")
    add_entries(tmp_path, [kept, gone])
    assert drop_missing_entries(tmp_path) == 1 and read_index(tmp_path) == [kept]
    assert drop_missing_entries(tmp_path) == 0 and read_index(tmp_path) == [kept]
