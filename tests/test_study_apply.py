"""``quadfdi train apply``: the train stage's networks predict on another simulator seed's flights
without retraining; the sets are published by the stage ``apply`` and indexed under that seed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.predictions import read_index
from tests.conftest import copy_run, random_weight_run


@pytest.fixture()
def applied_run(small_run, tmp_path):
    """A run with random-weight checkpoints recorded as trained with its config (train seed 0), and a
    second dataset under sims/seed1/ (the same flights, its sim record saying seed 1: the test is of
    the plumbing, not of the simulator)."""
    from quadfdi.core.config import load_config

    cfg = load_config(small_run / "config.toml").to_dict()
    run_dir = random_weight_run(small_run, tmp_path / "run", config=cfg)
    sub = copy_run(small_run, run_dir / "sims" / "seed1")
    rec = json.loads((sub / ".stages/sim.json").read_text())
    rec["config"]["sim"]["seed"] = 1
    (sub / ".stages/sim.json").write_text(json.dumps(rec))
    return run_dir


def test_apply_predicts_the_stage_networks_on_another_sim_seed(applied_run):
    from quadfdi.core.executor import SERIAL
    from quadfdi.core.rundir import open_run
    from quadfdi.evaluate.load import load_run
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.train.predsets import prediction_set
    from quadfdi.train.study_apply import SUMMARY, run_apply

    run, cfg = open_run(applied_run)
    summary = run_apply(run, cfg, [0], [1], SERIAL, log=lambda s: None)
    assert [(s["model"], s["network"]) for s in summary["sets"]] == [("cnode", "train stage"), ("gru", "train stage")]
    entries = {(e["model"], e["sim_seed"], e["train_seed"]): e for e in read_index(applied_run)}
    assert set(entries) == {("cnode", 1, 0), ("gru", 1, 0)}
    assert entries[("gru", 1, 0)]["dataset"] == "sims/seed1/dataset.npz"
    model, _ = load_checkpoint(applied_run / "gru.pt", "gru")
    want = prediction_set(model, load_dataset(applied_run / "sims/seed1/dataset.npz"))
    got = np.load(applied_run / entries[("gru", 1, 0)]["predictions"])
    assert np.array_equal(got["proba"], want["proba"]) and np.array_equal(got["traj"], want["traj"])
    assert (applied_run / SUMMARY).is_file()
    sets, infos = load_run(applied_run)  # evaluate reads them, with sim seed 1's dataset
    assert {s.sim_seed for s in sets} == {1} and set(infos) == {"sims/seed1/dataset.npz"}
    with pytest.raises(QuadfdiError, match="only the run's own simulator seed"):
        run_apply(run, cfg, [0], [cfg.sim.seed], SERIAL, log=lambda s: None)


def test_apply_uses_the_stage_networks_train_settings_and_refuses_another_network(small_run, tmp_path):
    """`quadfdi train --set train.X=...` is not stored in config.toml: apply takes [train] from the
    stage's networks (seed aside, its own --set train.* kept), so it applies THEM instead of silently
    retraining with config.toml's [train]; a network that does not reproduce the run's indexed set
    (another network than the one evaluated) is refused."""
    from quadfdi.core.config import load_config, replace_section
    from quadfdi.core.executor import SERIAL
    from quadfdi.formats.predictions import add_entries
    from quadfdi.core.rundir import open_run
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.train.predsets import index_entry, prediction_set, write_prediction_set
    from quadfdi.train.study_apply import run_apply, with_stage_train

    base = load_config(small_run / "config.toml")
    trained = replace_section(base, "train", epochs=base.train.epochs + 5)  # as `quadfdi train --set train.epochs=...`
    run_dir = random_weight_run(small_run, tmp_path / "run", config=trained.to_dict())
    sub = copy_run(small_run, run_dir / "sims" / "seed1")
    rec = json.loads((sub / ".stages/sim.json").read_text())
    rec["config"]["sim"]["seed"] = 1
    (sub / ".stages/sim.json").write_text(json.dumps(rec))
    run, cfg = open_run(run_dir)
    assert cfg.train.epochs == base.train.epochs
    assert with_stage_train(run, cfg, {"epochs"}, log=lambda s: None) == cfg  # the command's own --set wins
    adopted = with_stage_train(run, cfg, log=lambda s: None)
    assert adopted.train.epochs == trained.train.epochs and adopted.train.seed == cfg.train.seed
    summary = run_apply(run, adopted, [0], [1], SERIAL, log=lambda s: None)
    assert {s["network"] for s in summary["sets"]} == {"train stage"}
    model, _ = load_checkpoint(run_dir / "cnode.pt", "cnode")  # an indexed set this network does not give
    other = prediction_set(model, load_dataset(run_dir / "dataset.npz"))
    other["proba"] = np.roll(other["proba"], 1, axis=1)
    entry = index_entry("cnode", cfg.sim.seed, 0)
    write_prediction_set(run_dir / entry["predictions"], other)
    add_entries(run_dir, [entry])
    with pytest.raises(QuadfdiError, match="does not reproduce the run's indexed cnode prediction set"):
        run_apply(run, adopted, [0], [1], SERIAL, log=lambda s: None)
