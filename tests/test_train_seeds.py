"""``quadfdi train --seed S`` adds seed S's prediction sets to predictions/ and keeps the other
seeds' (their index entries too); a re-run of one seed replaces its own sets; other seeds' sets made
with another [train] are dropped, not pooled with the new ones (train.run.keep_other_seeds).

Training is replaced by untrained models and seeded random prediction sets (``_fake_train_all``):
what is tested is the stage's publish, and a real training costs seconds per call."""

from __future__ import annotations

import numpy as np
import pytest

from quadfdi.formats.predictions import read_index
from quadfdi.core.records import load_record
from tests.conftest import copy_run

TINY = ["train.latent=4", "train.hidden=8", "train.gru_hidden=4"]


def _fake_train_all(ds, cfg, kinds, log=print, predsets=True):
    """train.run.train_all's result, untrained: one window per evaluation flight, probabilities drawn
    from (train seed, lr) so that another seed or [train] gives other sets."""
    from types import SimpleNamespace

    from quadfdi.formats.dataset import class_names
    from quadfdi.train.data import evaluation_rows
    from quadfdi.train.loop import History
    from quadfdi.models.networks import build_model

    names = class_names(ds.arrays)
    rows = evaluation_rows(ds)
    rng = np.random.default_rng([cfg.train.seed, int(cfg.train.lr * 1000)])
    test = SimpleNamespace(y=np.zeros(len(rows), np.int64), traj=rows.astype(np.int64), t_end=np.full(len(rows), 5.0))
    out = {"models": {}, "history": {}, "proba": {}, "metrics": {}, "predsets": {}, "ds": ds,
           "splits": SimpleNamespace(test=test)}
    for kind in kinds:
        model = build_model(kind, ds.n_channels, cfg.train, window=cfg.sim.window, n_classes=len(names))
        model.set_normalisation(np.zeros(ds.n_channels), np.ones(ds.n_channels))
        proba = rng.dirichlet(np.ones(len(names)), len(rows)).astype(np.float32)
        out["models"][kind], out["history"][kind], out["proba"][kind] = model, History(), proba
        out["metrics"][kind] = {"accuracy": 0.0}
        out["predsets"][kind] = {"proba": proba, "y_true": test.y, "traj": test.traj, "t_end": test.t_end,
                                 "split": np.asarray(ds["split"])[rows].astype(np.int8), "class_names": np.array(names)}
    return out


def _train(run_dir, seed, extra=(), model="both"):
    from quadfdi.core.rundir import open_run
    from quadfdi.train.run import train_run

    run, cfg = open_run(run_dir, TINY + list(extra))
    train_run(run, cfg, model, seed, log=lambda s: None)


def _sets(run_dir):
    return {(e["model"], e["train_seed"]): e["predictions"] for e in read_index(run_dir)}


@pytest.fixture()
def seeded_run(small_run, tmp_path, monkeypatch):
    from quadfdi.train import figures as train_figures
    from quadfdi.train import run as train_run_module

    monkeypatch.setattr(train_figures, "draw_all", lambda run, ds, result: [])  # figures are not the subject
    monkeypatch.setattr(train_run_module, "train_all", _fake_train_all)
    return copy_run(small_run, tmp_path / "run")


def test_another_seed_keeps_the_first_seeds_sets(seeded_run):
    _train(seeded_run, 0)
    first = {p: (seeded_run / p).read_bytes() for p in _sets(seeded_run).values()}
    _train(seeded_run, 1)
    sets = _sets(seeded_run)
    assert set(sets) == {(k, s) for k in ("cnode", "gru") for s in (0, 1)}
    for p, data in first.items():  # seed 0's sets untouched, still published by the train stage
        assert (seeded_run / p).read_bytes() == data
    outputs = {e["path"] for e in load_record(seeded_run, "train")["outputs"]}
    assert set(sets.values()) <= outputs
    # a re-run of seed 1 with other data in its sets replaces seed 1's, keeps seed 0's
    before = np.load(seeded_run / sets[("cnode", 1)])["proba"]
    _train(seeded_run, 1, ["train.lr=0.05"])  # another [train]: seed 0's sets no longer pool with it
    after = _sets(seeded_run)
    assert set(after) == {("cnode", 1), ("gru", 1)}
    assert not (seeded_run / sets[("cnode", 0)]).exists()
    assert not np.array_equal(before, np.load(seeded_run / after[("cnode", 1)])["proba"])


def test_one_model_with_another_train_config_drops_the_other_seeds_sets(seeded_run):
    _train(seeded_run, 0)
    _train(seeded_run, 1, ["train.lr=0.05"], model="cnode")  # carries gru.pt, but not seed 0's sets
    assert set(_sets(seeded_run)) == {("cnode", 1)}
    outputs = {e["path"] for e in load_record(seeded_run, "train")["outputs"]}
    assert "gru.pt" in outputs and not any("_train0" in p for p in outputs)
