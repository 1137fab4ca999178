"""Training is a function of (dataset, config, seed): the same seed gives the same checkpoint bytes.

Three one-epoch trainings of both models on copies of the small run, in this process (the
figures are skipped: they are not what is compared, and they cost most of the time).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import copy_run

from quadfdi.core.rundir import open_run

KINDS = ("cnode", "gru")


def _train(small_run: Path, out: Path, seed: int, monkeypatch: pytest.MonkeyPatch) -> Path:
    from quadfdi.train import figures as train_figures
    from quadfdi.train.run import train_run

    copy_run(small_run, out)
    monkeypatch.setattr(train_figures, "draw_all", lambda run, ds, result: [])
    run, cfg = open_run(out, ["train.epochs=1", "train.batch_size=48"], need=("dataset",))
    train_run(run, cfg, "both", seed, log=lambda s: None)
    return out


@pytest.fixture(scope="module")
def three_runs(small_run, tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("determinism")
    with pytest.MonkeyPatch.context() as mp:
        return {name: _train(small_run, root / name, seed, mp)
                for name, seed in (("a", 0), ("b", 0), ("other", 1))}


@pytest.mark.parametrize("kind", KINDS)
def test_same_seed_gives_the_same_checkpoint_bytes(three_runs, kind):
    a = (three_runs["a"] / f"{kind}.pt").read_bytes()
    b = (three_runs["b"] / f"{kind}.pt").read_bytes()
    assert a == b
    assert (three_runs["a"] / f"predictions_{kind}.npz").read_bytes() == \
        (three_runs["b"] / f"predictions_{kind}.npz").read_bytes()
    assert (three_runs["a"] / "metrics.json").read_bytes() == (three_runs["b"] / "metrics.json").read_bytes()


@pytest.mark.parametrize("kind", KINDS)
def test_another_seed_gives_other_bytes(three_runs, kind):
    assert (three_runs["a"] / f"{kind}.pt").read_bytes() != (three_runs["other"] / f"{kind}.pt").read_bytes()
    assert (three_runs["a"] / f"predictions_{kind}.npz").read_bytes() != \
        (three_runs["other"] / f"predictions_{kind}.npz").read_bytes()


def test_checkpoint_history_has_no_wall_clock_times(three_runs):
    import json

    import torch

    blob = torch.load(three_runs["a"] / "cnode.pt", weights_only=True)
    assert "epoch_s" not in blob["history"] and blob["history"]["best_epoch"] == 0
    history = json.loads((three_runs["a"] / "history.json").read_text())
    assert len(history["cnode"]["epoch_s"]) == 1  # history.json keeps the times
