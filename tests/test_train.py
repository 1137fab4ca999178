"""Training: the loss falls, the artifacts follow their contracts, bad inputs fail clearly."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from quadfdi.core.config import load_config, replace_section
from quadfdi.core.contracts import CLASS_NAMES, N_CLASSES, SPLIT_TEST, SPLIT_TRAIN
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import load_dataset
from tests.conftest import quadfdi
from quadfdi.models.checkpoint import check_dataset_matches, load_checkpoint, save_checkpoint
from quadfdi.train.data import batch_order, class_weights, fit_normalisation, split_windows
from quadfdi.train.loop import weighted_cross_entropy
from quadfdi.models.networks import build_model

METRIC_KEYS = {"accuracy", "balanced_accuracy", "macro_precision", "macro_recall", "macro_specificity", "macro_f1",
               "weighted_f1", "mcc", "roc_auc_ovr", "pr_auc_ovr", "brier", "any_fault_f1", "any_fault_roc_auc",
               "mean_detection_delay_s", "missed_faults", "false_alarm_rate", "per_class"}


def test_weighted_cross_entropy_is_eq12():
    logits = torch.tensor([[2.0, 0.0, -1.0, 0.5], [0.1, 0.2, 0.3, 0.4], [0.0, 0.0, 0.0, 3.0]])
    y = torch.tensor([0, 2, 3])
    w = torch.tensor([0.5, 1.0, 2.0, 4.0])
    p = torch.softmax(logits, 1).numpy()
    expect = -np.mean([w[y[b]].item() * np.log(p[b, y[b]] + 1e-8) for b in range(3)])
    assert weighted_cross_entropy(logits, y, w, 1e-8).item() == pytest.approx(expect, rel=1e-6)


def test_class_weights_inverse_frequency():
    y = np.array([0] * 6 + [1] * 3 + [2] * 2 + [3])
    w = class_weights(y)
    assert np.allclose(w * np.bincount(y), len(y) / 4)  # every class weighs the same in total


def test_same_batches_for_both_models():
    a = batch_order(500, 96, seed=3, epoch=2)
    b = batch_order(500, 96, seed=3, epoch=2)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert sorted(np.concatenate(a).tolist()) == list(range(500))
    assert not np.array_equal(a[0], batch_order(500, 96, seed=3, epoch=3)[0])


def test_normalisation_from_training_split_only(small_run):
    ds = load_dataset(small_run / "dataset.npz")
    mean, _ = fit_normalisation(ds)
    train_tel = ds["telemetry"][ds["split"] == SPLIT_TRAIN]
    assert np.allclose(mean, train_tel.reshape(-1, train_tel.shape[-1]).mean(0), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("kind", ["cnode", "gru"])
def test_one_epoch_lowers_loss(small_run, kind):
    from quadfdi.train.loop import train_model

    ds = load_dataset(small_run / "dataset.npz")
    cfg = replace_section(load_config(None), "train", epochs=1, batch_size=32)
    sp = split_windows(ds)
    torch.manual_seed(0)
    model = build_model(kind, ds.n_channels, cfg.train)
    model.set_normalisation(*fit_normalisation(ds))
    w = torch.as_tensor(class_weights(sp.train.y))
    x, y = torch.from_numpy(sp.train.x), torch.from_numpy(sp.train.y)
    with torch.no_grad():
        before = weighted_cross_entropy(model(x), y, w, 1e-8).item()
    train_model(model, sp.train, sp.validation, cfg.train, w.numpy(), log=lambda s: None)
    with torch.no_grad():
        after = weighted_cross_entropy(model(x), y, w, 1e-8).item()
    assert after < before


@pytest.fixture(scope="module")
def trained_run(small_run, tmp_path_factory):
    import shutil

    run = tmp_path_factory.mktemp("trained") / "run"
    shutil.copytree(small_run, run)
    res = quadfdi("train", "--run", str(run), "--set", "train.epochs=2", "--set", "train.batch_size=48")
    assert res.returncode == 0, res.stderr
    return run


def test_train_artifacts(trained_run):
    metrics = json.loads((trained_run / "metrics.json").read_text())
    assert set(metrics) == {"cnode", "gru", "baseline"}
    for m in metrics.values():
        assert set(m) == METRIC_KEYS
        assert set(m["per_class"]) == set(CLASS_NAMES)
    ds = load_dataset(trained_run / "dataset.npz")
    for kind in ("cnode", "gru"):
        with np.load(trained_run / f"predictions_{kind}.npz", allow_pickle=False) as z:
            assert set(z.files) == {"y_true", "proba", "traj", "t_end"}
            assert z["proba"].shape == (len(z["y_true"]), N_CLASSES) and np.allclose(z["proba"].sum(1), 1.0)
            assert set(ds["split"][z["traj"]]) == {SPLIT_TEST}
        blob = torch.load(trained_run / f"{kind}.pt", weights_only=True)  # no pickled classes
        assert blob["architecture"]["kind"] == kind
    for fig in ("train_curves.png", "confusion_cnode.png", "confusion_gru.png", "per_class_f1.png", "any_fault_roc.png"):
        assert (trained_run / "figures" / fig).is_file()
    assert len(list((trained_run / "figures").glob("detection_*.png"))) == 3


def test_checkpoint_round_trip_and_errors(trained_run, tmp_path):
    model, blob = load_checkpoint(trained_run / "cnode.pt", "cnode")
    x = torch.randn(3, 80, len(blob["channel_names"])) * 0.1 + torch.tensor(blob["normalisation"]["mean"])
    path = tmp_path / "again.pt"
    save_checkpoint(path, model, blob["config"], blob["channel_names"])
    again, _ = load_checkpoint(path)
    with torch.no_grad():
        assert torch.equal(model(x), again(x))
    with pytest.raises(QuadfdiError, match="holds a 'gru' model, expected 'cnode'"):
        load_checkpoint(trained_run / "gru.pt", "cnode")
    bad = tmp_path / "bad.pt"
    bad.write_bytes((trained_run / "cnode.pt").read_bytes()[:300])
    with pytest.raises(QuadfdiError, match="cannot be read"):
        load_checkpoint(bad)
    with pytest.raises(QuadfdiError, match="the model expects 23 channels, the dataset has 22"):
        check_dataset_matches(blob, blob["channel_names"][:-1], "dataset.npz")


def test_train_rejects_missing_dataset(tmp_path):
    res = quadfdi("train", "--run", str(tmp_path / "nowhere"))
    assert res.returncode == 2 and "does not exist" in res.stderr and len(res.stderr.strip().splitlines()) == 1
